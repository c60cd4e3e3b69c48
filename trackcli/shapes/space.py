"""The shape-space value: a linear family of curves ``Q = W X + Q0`` (AC ch 4 and §8.4, SPEC §2).

Symbols
-------
``Q``  (2 Nq,)   stacked control vector ``(Qx; Qy)`` of a spline curve.
``X``  (Nx,)     shape vector; ``W`` (2 Nq, Nx) the shape-matrix, ``Q0`` (2 Nq,) the template.
``𝒰``  (2 Nq, 2 Nq)  the spline metric (:attr:`trackcli.shapes.spline.SplineBasis.U`).
``H``  (Nx, Nx)  ``Wᵀ 𝒰 W`` (AC eq 8.6): ``Xᵀ H X`` is the mean-square displacement along
the curve produced by ``X``.

A :class:`ShapeSpace` maps shape vectors to curves and back (L2 projection), gives the
metric ``H``, the curve points, normals and measurement vectors, the pose of a curve, the
projectors onto subspaces, and its own (de)serialisation.  The ways of making one are in
:mod:`trackcli.shapes.shape_space`.

Constructive spaces
-------------------
The deformation columns of the translation, similarity and affine spaces
(:func:`constructive_columns`) are built from the template's control points taken
*relative to an anchor* ``origin`` — by default the area centroid of the template curve (the
parameter-mean for an open curve, see :func:`trackcli.shapes.spline.curve_centre`).
Rotation and scale therefore act about the object, and ``(tx, ty)`` is exactly the
displacement of the anchor.  ``Q0`` stays in image coordinates, so ``X = 0`` is the template
where it was drawn.  With ``Q0' = Q0 − origin`` per coordinate and ``1`` the vector of ones:

- ``translation``: ``W = [[1, 0], [0, 1]]``, ``X = (tx, ty)``;
- ``similarity``: ``W = [[1, 0, Q0x', −Q0y'], [0, 1, Q0y', Q0x']]``,
  ``X = (tx, ty, s cosθ − 1, s sinθ)``;
- ``affine``: ``W = [[1, 0, Q0x', 0, 0, Q0y'], [0, 1, 0, Q0y', Q0x', 0]]``,
  ``X = (tx, ty, a11 − 1, a22 − 1, a21, a12)``, the curve being ``r ↦ A (r − o) + o + t``.

Angles run from +x towards +y: clockwise on the screen, where ``y`` points down.  The first
columns of a space extended with key-frames or PCA modes are those of its base, so
:meth:`ShapeSpace.pose` still reads them directly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from trackcli.errors import ConfigError, DataError, ModelError, TrackcliError
from trackcli.shapes.spline import CurveSampler, SplineBasis

__all__ = ["POSE_KINDS", "ShapeSpace", "constructive_columns"]


#: the constructive kinds: their columns (:func:`constructive_columns`) are read by :meth:`ShapeSpace.pose`
POSE_KINDS = ("translation", "similarity", "affine")


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class ShapeSpace:
    """A shape-space ``S = L(W, Q0)`` over one spline basis.

    Parameters
    ----------
    W : array_like of shape (2 Nq, Nx)
        Shape-matrix; its columns must be linearly independent.
    Q0 : array_like of shape (2 Nq,)
        Template control vector, image coordinates.
    basis : SplineBasis
    kind : str
        How the space was made (see the module docstring).
    names : tuple of str, length Nx
        Parameter names, used for CSV headers.
    origin : array_like of shape (2,)
        Anchor point about which the constructive deformation columns were built.
    """

    W: np.ndarray
    Q0: np.ndarray
    basis: SplineBasis
    kind: str
    names: tuple[str, ...]
    origin: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.basis, SplineBasis):
            raise ConfigError(
                f"shape-space basis must be a SplineBasis, got {type(self.basis).__name__}"
            )
        if not isinstance(self.kind, str) or not self.kind:
            raise ConfigError(f"shape-space kind must be a non-empty string, got {self.kind!r}")
        n2 = 2 * self.basis.n_ctrl
        W = np.array(self.W, dtype=float)
        if W.ndim != 2 or W.shape[0] != n2 or W.shape[1] < 1:
            raise DataError(
                f"shape-matrix W must have shape (2*Nq, Nx) = ({n2}, Nx >= 1), got {W.shape}"
            )
        Q0 = np.array(self.Q0, dtype=float)
        if Q0.shape != (n2,):
            raise DataError(f"template Q0 must have shape ({n2},), got {Q0.shape}")
        origin = np.array(self.origin, dtype=float)
        if origin.shape != (2,):
            raise DataError(f"origin must have shape (2,), got {origin.shape}")
        for label, a in (("W", W), ("Q0", Q0), ("origin", origin)):
            if not np.all(np.isfinite(a)):
                raise DataError(f"shape-space {label} contains NaN or infinite values")
        names = tuple(self.names)
        if len(names) != W.shape[1] or not all(isinstance(n, str) and n for n in names):
            raise ConfigError(
                f"shape-space needs {W.shape[1]} non-empty parameter names, got {names!r}"
            )
        if len(set(names)) != len(names):
            raise ConfigError(f"shape-space parameter names must be distinct, got {names!r}")
        object.__setattr__(self, "W", _readonly(W))
        object.__setattr__(self, "Q0", _readonly(Q0))
        object.__setattr__(self, "origin", _readonly(origin))
        object.__setattr__(self, "names", names)
        ev = np.linalg.eigvalsh(self.H)
        if not ev[0] > 1e-10 * max(ev[-1], 1e-300):
            raise DataError(
                f"the columns of W are linearly dependent in the curve metric "
                f"(eigenvalues of H from {ev[0]:.3g} to {ev[-1]:.3g}); drop redundant columns "
                f"or key-frames"
            )

    # ------------------------------------------------------------------ basics
    @property
    def Nq(self) -> int:
        """Number of control points."""
        return self.basis.n_ctrl

    @property
    def Nx(self) -> int:
        """Dimension of the shape-space."""
        return self.W.shape[1]

    @property
    def base_kind(self) -> str:
        """The kind before any ``+keyframes`` / ``+pca`` extension."""
        return self.kind.split("+", 1)[0]

    @cached_property
    def H(self) -> np.ndarray:
        """``H = Wᵀ 𝒰 W``, shape (Nx, Nx), symmetric positive definite (AC eq 8.6)."""
        H = self.W.T @ self.basis.U @ self.W
        return _readonly(0.5 * (H + H.T))

    @cached_property
    def pinv(self) -> np.ndarray:
        """L2 pseudo-inverse ``W⁺ = H⁻¹ Wᵀ 𝒰``, shape (Nx, 2 Nq)."""
        return _readonly(np.linalg.solve(self.H, self.W.T @ self.basis.U))

    def _check_X(self, X) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        if X.ndim < 1 or X.shape[-1] != self.Nx:
            raise DataError(
                f"shape vectors must have last dimension Nx = {self.Nx}, got shape {X.shape}"
            )
        return X

    def _check_Q(self, Q) -> np.ndarray:
        Q = np.asarray(Q, dtype=float)
        if Q.ndim < 1 or Q.shape[-1] != 2 * self.Nq:
            raise DataError(
                f"control vectors must have last dimension 2*Nq = {2 * self.Nq}, "
                f"got shape {Q.shape}"
            )
        return Q

    def _check_sampler(self, sampler: CurveSampler) -> None:
        if not isinstance(sampler, CurveSampler) or sampler.basis != self.basis:
            raise ConfigError(
                f"the sampler must be a CurveSampler over {self.basis}, got "
                f"{getattr(sampler, 'basis', sampler)!r}"
            )

    # ------------------------------------------------------------ maps X <-> Q
    def to_control(self, X) -> np.ndarray:
        """Control vectors ``Q = W X + Q0``: (..., Nx) → (..., 2 Nq)."""
        return self._check_X(X) @ self.W.T + self.Q0

    def project(self, Q) -> np.ndarray:
        """L2 projection of curves onto the space: ``X = (Wᵀ𝒰W)⁻¹ Wᵀ𝒰 (Q − Q0)``.

        (..., 2 Nq) → (..., Nx).  Exact (``to_control(project(Q)) == Q``) for curves that
        lie in the space.
        """
        return (self._check_Q(Q) - self.Q0) @ self.pinv.T

    def scaled(self, X, factor) -> np.ndarray:
        """Curves scaled by ``factor`` about their position ``origin + (tx, ty)``: (..., Nx).

        ``factor`` (broadcast over the leading dimensions) multiplies the size and keeps the
        translation and the rotation: in a similarity space ``1 + X₂`` and ``X₃`` are
        multiplied by it, in an affine space the whole matrix ``A``.  Any other space gets
        the scaled control points projected onto it; a translation space, which has no
        scale, gives the curves back unchanged.
        """
        X = self._check_X(X)
        if self.base_kind == "translation":
            return np.array(X, dtype=float)
        f = np.asarray(factor, dtype=float)[..., None]
        Q = self.to_control(X)
        nq = self.Nq
        for axis, part in enumerate((slice(0, nq), slice(nq, 2 * nq))):
            c = self.origin[axis] + X[..., axis : axis + 1]
            Q[..., part] = c + f * (Q[..., part] - c)
        return self.project(Q)

    def points(self, X, sampler: CurveSampler) -> np.ndarray:
        """Curve points ``r(s_i)``: (..., Nx) → (..., M, 2)."""
        self._check_sampler(sampler)
        return sampler.points(self.to_control(X))

    def normals(self, X, sampler: CurveSampler) -> np.ndarray:
        """Unit normals at ``s_i`` (outward when closed): (..., Nx) → (..., M, 2)."""
        self._check_sampler(sampler)
        return sampler.normals(self.to_control(X))

    def points_normals(self, X, sampler: CurveSampler) -> tuple[np.ndarray, np.ndarray]:
        """``(points, normals)`` at ``s_i``, each (..., M, 2), from one evaluation of ``Q``."""
        self._check_sampler(sampler)
        return sampler.points_normals(self.to_control(X))

    def measurement_vectors(self, X, sampler: CurveSampler, normals=None) -> np.ndarray:
        """Measurement vectors ``h_iᵀ = n(s_i)ᵀ U(s_i) W`` (SPEC §3, AC Fig 8.6).

        ``h_iᵀ ΔX`` is the displacement of ``r(s_i)`` along its normal when ``X`` changes by
        ``ΔX``.

        Parameters
        ----------
        X : array_like of shape (..., Nx)
            Curve(s) whose normals are used (typically the predicted estimate).
        sampler : CurveSampler
        normals : array_like of shape (..., M, 2), optional
            Precomputed unit normals of that curve; computed from ``X`` if omitted.

        Returns
        -------
        ndarray of shape (..., M, Nx)
        """
        self._check_sampler(sampler)
        n = self.normals(X, sampler) if normals is None else np.asarray(normals, dtype=float)
        if n.shape[-2:] != (sampler.M, 2):
            raise DataError(f"normals must have shape (..., {sampler.M}, 2), got {n.shape}")
        BWx = sampler.B @ self.W[: self.Nq]
        BWy = sampler.B @ self.W[self.Nq :]
        return n[..., 0:1] * BWx + n[..., 1:2] * BWy

    # -------------------------------------------------------------------- pose
    @cached_property
    def _affine_about_template(self) -> ShapeSpace:
        W, names = constructive_columns("affine", self.basis, self.Q0, self.origin)
        return ShapeSpace(W, self.Q0, self.basis, "affine", names, self.origin)

    def pose(self, X) -> np.ndarray:
        """Translation, rotation and scale of curves: (..., Nx) → (..., 4) = ``(tx, ty, θ, s)``.

        ``θ`` is in radians from +x towards +y.  Read directly from the first columns when
        the space is (or extends) a constructive one:

        - translation: ``(tx, ty, 0, 1)``;
        - similarity: ``θ = atan2(X₃, 1 + X₂)``, ``s = hypot(1 + X₂, X₃)``;
        - affine, ``A = [[1 + X₂, X₅], [X₄, 1 + X₃]]``: ``θ = atan2(a21 − a12, a11 + a22)``
          and ``s = sqrt|det A|``.  For a similarity ``A = s R(θ)`` this gives back ``θ`` and
          ``s`` exactly; otherwise ``θ`` is the rotation of the closest similarity and ``s``
          the scale of area.

        Any other space (e.g. ``"pca"``) first projects the curve onto the affine space of
        its own template ``Q0`` about ``origin`` and reads that.
        """
        X = self._check_X(X)
        kind = self.base_kind
        if kind not in POSE_KINDS:
            X = self._affine_about_template.project(self.to_control(X))
            kind = "affine"
        t = X[..., :2]
        one = np.ones(X.shape[:-1])
        if kind == "translation":
            return np.concatenate([t, np.zeros_like(one)[..., None], one[..., None]], axis=-1)
        if kind == "similarity":
            c, s = 1.0 + X[..., 2], X[..., 3]
            return np.concatenate(
                [t, np.arctan2(s, c)[..., None], np.hypot(c, s)[..., None]], axis=-1
            )
        a11, a22, a21, a12 = 1.0 + X[..., 2], 1.0 + X[..., 3], X[..., 4], X[..., 5]
        angle = np.arctan2(a21 - a12, a11 + a22)
        scale = np.sqrt(np.abs(a11 * a22 - a12 * a21))
        return np.concatenate([t, angle[..., None], scale[..., None]], axis=-1)

    # --------------------------------------------------------------- projectors
    def span_projector(self, C) -> np.ndarray:
        """L2-orthogonal projection onto the span of the columns of ``C``.

        ``E = C (Cᵀ H C)⁻¹ Cᵀ H``: ``E² = E`` and ``Eᵀ H (I − E) = 0``, i.e. the part kept
        and the part removed are orthogonal as curve displacements.

        Parameters
        ----------
        C : array_like of shape (Nx, k)

        Returns
        -------
        E : ndarray of shape (Nx, Nx)
        """
        C = np.asarray(C, dtype=float)
        if C.ndim != 2 or C.shape[0] != self.Nx or C.shape[1] < 1:
            raise DataError(f"subspace basis must have shape ({self.Nx}, k >= 1), got {C.shape}")
        G = C.T @ self.H @ C
        ev = np.linalg.eigvalsh(G)
        if not ev[0] > 1e-10 * max(ev[-1], 1e-300):
            raise DataError("the subspace columns are linearly dependent (or zero)")
        return C @ np.linalg.solve(G, C.T @ self.H)

    def projector(self, columns: Sequence[int]) -> np.ndarray:
        """L2-orthogonal projection onto the coordinate axes ``columns`` of ``X``, (Nx, Nx).

        For a partition of the axes into groups, the projectors onto the H-orthogonal
        complements are ``I − E``; e.g. ``Ed = I − projector([0, 1])``.
        """
        idx = np.asarray(columns)
        if idx.ndim != 1 or idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
            raise ConfigError(f"columns must be a non-empty list of integers, got {columns!r}")
        if idx.min() < -self.Nx or idx.max() >= self.Nx or len(set(idx % self.Nx)) != idx.size:
            raise ConfigError(
                f"columns must be distinct indices in [0, {self.Nx - 1}], got {list(idx)}"
            )
        return self.span_projector(np.eye(self.Nx)[:, idx])

    def translation_projector(self) -> np.ndarray:
        """``Es``: L2-orthogonal projection onto the translation subspace, (Nx, Nx).

        The translation subspace is spanned by ``W⁺ T`` where ``T`` holds the two rigid
        translations of the curve; in a constructive space these are the ``tx, ty`` axes.
        In a space with no translation directions (e.g. a PCA space) it is the part of
        the space closest to translation.
        """
        T = np.zeros((2 * self.Nq, 2))
        T[: self.Nq, 0] = 1.0
        T[self.Nq :, 1] = 1.0
        return self.span_projector(self.pinv @ T)

    def deformation_projector(self) -> np.ndarray:
        """``Ed = I − Es`` (:meth:`translation_projector`), shape (Nx, Nx)."""
        return np.eye(self.Nx) - self.translation_projector()

    # ------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """Plain-Python description (lists, floats, strings) for YAML files.

        Keys: ``kind``, ``names``, ``basis`` (``n_ctrl``, ``degree``, ``closed``),
        ``origin`` (2), ``Q0`` (2 Nq) and ``W`` (2 Nq rows of Nx numbers).
        """
        return {
            "kind": self.kind,
            "names": list(self.names),
            "basis": {
                "n_ctrl": self.basis.n_ctrl,
                "degree": self.basis.degree,
                "closed": self.basis.closed,
            },
            "origin": self.origin.tolist(),
            "Q0": self.Q0.tolist(),
            "W": self.W.tolist(),
        }

    @classmethod
    def from_dict(cls, data, where: str = "shape_space") -> ShapeSpace:
        """Rebuild a space written by :meth:`to_dict`.

        Parameters
        ----------
        data : mapping
        where : str
            Key path used in error messages (e.g. ``"model.shape_space"``).

        Raises
        ------
        ModelError
            A key is missing or a value has the wrong type, shape or content.
        """
        if not isinstance(data, Mapping):
            raise ModelError(f"{where}: expected a mapping, got {type(data).__name__}")
        missing = [k for k in ("kind", "names", "basis", "origin", "Q0", "W") if k not in data]
        if missing:
            raise ModelError(f"{where}: missing key(s) {', '.join(missing)}")
        b = data["basis"]
        if not isinstance(b, Mapping) or "n_ctrl" not in b:
            raise ModelError(
                f"{where}.basis: expected a mapping with n_ctrl, degree, closed; got {b!r}"
            )
        try:
            basis = SplineBasis(b["n_ctrl"], b.get("degree", 2), b.get("closed", True))
        except TrackcliError as exc:
            raise ModelError(f"{where}.basis: {exc}") from None

        def array(key: str, shape: tuple[int | None, ...]) -> np.ndarray:
            try:
                a = np.array(data[key], dtype=float)
            except (TypeError, ValueError):
                got = repr(data[key])[:80]
                raise ModelError(f"{where}.{key}: expected numbers, got {got}") from None
            wrong = any(n is not None and m != n for m, n in zip(a.shape, shape))
            if a.ndim != len(shape) or wrong:
                want = "(" + ", ".join("Nx" if n is None else str(n) for n in shape)
                want += ",)" if len(shape) == 1 else ")"
                raise ModelError(f"{where}.{key}: expected shape {want}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ModelError(f"{where}.{key}: contains NaN or infinite values")
            return a

        n2 = 2 * basis.n_ctrl
        W = array("W", (n2, None))
        Q0 = array("Q0", (n2,))
        origin = array("origin", (2,))
        names = data["names"]
        if not isinstance(names, (list, tuple)):
            raise ModelError(f"{where}.names: expected a list of strings, got {names!r}")
        try:
            return cls(W, Q0, basis, data["kind"], tuple(names), origin)
        except TrackcliError as exc:
            raise ModelError(f"{where}: {exc}") from None


def _translation_columns(N: int) -> np.ndarray:
    W = np.zeros((2 * N, 2))
    W[:N, 0] = 1.0
    W[N:, 1] = 1.0
    return W


def constructive_columns(kind: str, basis: SplineBasis, Q0: np.ndarray,
                         origin: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """The shape-matrix ``W`` (2 Nq, Nx) and the parameter names of the constructive space
    ``kind`` (one of :data:`POSE_KINDS`) on the template ``Q0`` about the anchor ``origin``
    (the module docstring gives the columns)."""
    N = basis.n_ctrl
    qx, qy = Q0[:N] - origin[0], Q0[N:] - origin[1]
    if kind == "translation":
        return _translation_columns(N), ("tx", "ty")
    if kind == "similarity":
        W = np.column_stack([_translation_columns(N), np.concatenate([qx, qy]), np.concatenate([-qy, qx])])
        return W, ("tx", "ty", "scos_m1", "ssin")
    if kind == "affine":
        z = np.zeros_like(qx)
        W = np.column_stack(
            [
                _translation_columns(N),
                np.concatenate([qx, z]),
                np.concatenate([z, qy]),
                np.concatenate([z, qx]),
                np.concatenate([qy, z]),
            ]
        )
        return W, ("tx", "ty", "a11_m1", "a22_m1", "a21", "a12")
    raise ConfigError(f"constructive shape-space: expected one of {', '.join(POSE_KINDS)}, got {kind!r}")
