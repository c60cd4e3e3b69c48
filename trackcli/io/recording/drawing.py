"""What a :class:`~trackcli.io.recording.Recording` draws: 2-D overlays, time series,
histograms and text.

:class:`Overlays` holds the ``log_*`` methods of a recording; it is a part of
:class:`~trackcli.io.recording.Recording` and relies on its ``stream``, ``_emit`` (log now or
hold for the batch), ``_note``/``_note_series`` (what the blueprint shows), ``_styled`` and
``_bar_edges``.  Colours are RGB or RGBA integers 0-255; widths and radii are in image pixels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.io.recording.arrow import _color, _edges, _flatten, _half_width, _plain, _points
from trackcli.io.recording.layout import TEXT_LEVELS, histogram_image, weight_colors


def _drop_collinear(pts: np.ndarray, closed: bool) -> np.ndarray:
    """``pts`` (M, 2) without the points that lie between their two neighbours on one line."""
    if len(pts) < 3 or not np.all(np.isfinite(pts)):
        return pts
    p = pts.astype(np.float64)
    prev, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    a, b = p - prev, nxt - p
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    scale = np.hypot(a[:, 0], a[:, 1]) * np.hypot(b[:, 0], b[:, 1])
    between = (np.abs(cross) <= 1e-9 * scale) & (np.einsum("ij,ij->i", a, b) > 0)
    if not closed:
        between[0] = between[-1] = False
    if between.all():  # a closed "curve" on one line: keep it as given
        return pts
    return pts[~between]


def _simplify(pts: np.ndarray, tolerance: float, closed: bool) -> np.ndarray:
    """``pts`` (M, 2) with the fewest points whose polyline stays within ``tolerance`` pixels of
    every given point (Douglas-Peucker); the points kept are given points, in their order."""
    if tolerance <= 0 or len(pts) < 4 or not np.all(np.isfinite(pts)):
        return pts
    import cv2

    kept = cv2.approxPolyDP(np.ascontiguousarray(pts, dtype=np.float32).reshape(-1, 1, 2), float(tolerance),
                            bool(closed)).reshape(-1, 2)
    return kept if len(kept) >= (3 if closed else 2) else pts


class Overlays:
    """The drawing methods of :class:`~trackcli.io.recording.Recording` (see the module docstring)."""

    stream: Any
    _styled: set[str]
    _bar_edges: dict[str, np.ndarray]

    # -- 2-D overlays --------------------------------------------------------

    def log_contour(self, entity: str, points: np.ndarray, color: Sequence[int] = (255, 64, 0),
                    width: float = 2.0, *, closed: bool = True, tolerance: float = 0.0) -> None:
        """Draw one curve through ``points``.

        Parameters
        ----------
        points : ndarray of shape (M, 2)
            Curve samples in image coordinates (x, y).
        width : float
            Line width in image pixels.
        closed : bool
            Join the last point back to the first.
        tolerance : float
            With a positive value, the curve is stored by as few of its points as keep the
            line within ``tolerance`` pixels of every point given (Douglas-Peucker): a dense
            curve drawn a few pixels wide looks the same in a fraction of the space.

        Points that lie on the straight segment between their neighbours are left out: the
        line drawn is the same, and a pixel-traced outline (its straight runs of pixels) takes
        half the space.
        """
        pts = _simplify(_drop_collinear(_points(points, "points", leading=1), closed), tolerance, closed)
        if closed and len(pts) > 1:
            pts = np.concatenate([pts, pts[:1]])
        self._emit(entity, "LineStrips2D", strips=pts[None], colors=_color(color)[None],
                   radii=np.array([_half_width(width)], np.float32))

    def log_contours(self, entity: str, curves: np.ndarray, weights: np.ndarray | None = None,
                     width: float = 1.0, *, closed: bool = True) -> None:
        """Draw K curves shaded by weight (see :func:`weight_colors`), heaviest on top.

        Parameters
        ----------
        curves : ndarray of shape (K, M, 2)
            Curve samples in image coordinates.
        weights : ndarray of shape (K,), optional
            Non-negative weights; equal weights if None.
        """
        c = _points(curves, "curves", leading=2)
        k = c.shape[0]
        w = np.ones(k) if weights is None else np.asarray(weights, dtype=float)
        if w.shape != (k,):
            raise DataError(f"weights must have shape ({k},) to match curves, got {w.shape}")
        colors = weight_colors(w)
        order = np.argsort(w, kind="stable")
        c, colors = c[order], colors[order]
        if closed and c.shape[1] > 1:
            c = np.concatenate([c, c[:, :1]], axis=1)
        self._emit(entity, "LineStrips2D", strips=c, colors=colors, radii=np.array([_half_width(width)], np.float32))

    def log_points(self, entity: str, pts: np.ndarray, colors: Any = None,
                   radii: float | np.ndarray | None = None) -> None:
        """Draw P points (features, particle centroids …).

        Parameters
        ----------
        pts : ndarray of shape (P, 2)
            Positions in image coordinates.
        colors : ndarray of shape (P, 3 or 4) or one colour, optional
            E.g. ``weight_colors(w)``.
        radii : float or ndarray of shape (P,), optional
            In image pixels.
        """
        p = _points(pts, "pts", leading=1)
        if colors is not None:
            col = np.asarray(colors)
            if col.ndim == 1:
                col = _color(col, "colors")
            elif col.shape != (len(p), col.shape[-1]) or col.shape[-1] not in (3, 4):
                raise DataError(f"colors must have shape ({len(p)}, 3 or 4), got {col.shape}")
            elif np.any(col < 0) or np.any(col > 255):
                raise DataError("colors must be integers in 0..255")
            colors = col.astype(np.uint8)
        if radii is not None:
            r = np.asarray(radii, dtype=np.float32)
            if r.ndim > 1 or (r.ndim == 1 and r.shape != (len(p),)) or np.any(r <= 0):
                raise DataError(f"radii must be positive, one value or shape ({len(p)},)")
            radii = r
        if colors is not None and colors.ndim == 1:
            colors = colors[None]
        if radii is not None and radii.ndim == 0:
            radii = radii[None]
        self._emit(entity, "Points2D", positions=p, colors=colors, radii=radii)

    def log_segments(self, entity: str, starts: np.ndarray, ends: np.ndarray,
                     color: Sequence[int] = (0, 200, 255), width: float = 1.0) -> None:
        """Draw K straight segments, e.g. the measurement lines along the curve normals.

        Parameters
        ----------
        starts, ends : ndarray of shape (K, 2)
            End points in image coordinates.
        """
        a = _points(starts, "starts", leading=1)
        b = _points(ends, "ends", leading=1)
        if a.shape != b.shape:
            raise DataError(
                f"starts and ends must have the same shape, got {a.shape} and {b.shape}"
            )
        self._emit(entity, "LineStrips2D", strips=np.stack([a, b], axis=1), colors=_color(color)[None],
                   radii=np.array([_half_width(width)], np.float32))

    # -- time series ---------------------------------------------------------

    def log_scalar(self, entity: str, value: float | Sequence[float], *,
                   names: str | Sequence[str] | None = None,
                   colors: Any = None, unit: str | None = None) -> None:
        """Log one value (or k values, one line each) at the current frame.

        ``names``/``colors`` style the lines; they are logged once per entity (static).
        ``unit`` (e.g. ``"px"``) groups the series into one plot with the others of that
        unit; series without a unit get a plot each.
        """
        import rerun as rr

        v = np.atleast_1d(np.asarray(value, dtype=float))
        if v.ndim != 1:
            raise DataError(f"a scalar sample must be one value or shape (k,), got shape {v.shape}")
        self._style(entity, names, colors, v.size)
        self._note_series(entity, unit)
        self.stream.log(entity, rr.Scalars(v))

    def send_series(self, entity: str, frames: np.ndarray, times: np.ndarray, values: np.ndarray, *,
                    names: str | Sequence[str] | None = None, colors: Any = None,
                    unit: str | None = None) -> None:
        """Send a whole time series at once (``send_columns``; far faster than per frame).

        Parameters
        ----------
        frames : ndarray of shape (T,), int
            Frame indices (the ``frame`` timeline).
        times : ndarray of shape (T,), float
            Seconds (the ``video_time`` timeline).
        values : ndarray of shape (T,) or (T, k)
            One line, or k lines plotted together (e.g. ``tx`` and ``ty``).
        names : str or sequence of k str, optional
            Legend names; with ``colors`` (k RGB(A) colours) logged once, static.
        unit : str, optional
            Groups the series into one plot with the others of that unit (see
            :meth:`log_scalar`).
        """
        import rerun as rr

        f = np.asarray(frames)
        t = np.asarray(times, dtype=float)
        v = np.asarray(values, dtype=float)
        n = f.shape[0] if f.ndim == 1 else -1
        if f.ndim != 1 or not np.issubdtype(f.dtype, np.integer):
            raise DataError(
                f"frames must be integers of shape (T,), got {f.dtype} of shape {f.shape}"
            )
        if t.shape != (n,):
            raise DataError(f"times must have shape ({n},) to match frames, got {t.shape}")
        if v.ndim not in (1, 2) or v.shape[0] != n:
            raise DataError(f"values must have shape ({n},) or ({n}, k), got {v.shape}")
        if not np.all(np.isfinite(t)):
            raise DataError("times must be finite")
        k = 1 if v.ndim == 1 else v.shape[1]
        self._style(entity, names, colors, k)
        if n == 0:
            return
        self._note_series(entity, unit)
        column = rr.Scalars.columns(scalars=v.reshape(-1)).partition(np.full(n, k))
        self.stream.send_columns(
            entity,
            indexes=[rr.TimeColumn("frame", sequence=f.astype(np.int64)),
                     rr.TimeColumn("video_time", duration=t)],
            columns=column,
        )

    def _style(self, entity: str, names: Any, colors: Any, k: int) -> None:
        """Log static ``SeriesLines`` names/colours the first time an entity gets them."""
        if (names is None and colors is None) or entity in self._styled:
            return
        import rerun as rr

        if names is not None:
            names = [names] if isinstance(names, str) else [str(s) for s in names]
            if len(names) != k:
                raise DataError(f"{entity}: {len(names)} names given for {k} lines")
        if colors is not None:
            col = np.asarray(colors)
            col = col[None] if col.ndim == 1 else col
            if col.ndim != 2 or col.shape[0] != k:
                raise DataError(
                    f"{entity}: colors must be {k} RGB(A) colours, got shape {col.shape}"
                )
            colors = np.stack([_color(c, "colors") for c in col])
        self.stream.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
        self._styled.add(entity)

    # -- histograms ----------------------------------------------------------

    def log_histogram(self, entity: str, counts: np.ndarray, x_edges: np.ndarray | None = None, *,
                      color: Sequence[int] | None = None) -> None:
        """Log a bar chart for the current frame.

        Parameters
        ----------
        counts : ndarray of shape (B,)
            Bar heights (counts or summed weights).
        x_edges : ndarray of shape (B + 1,), optional
            Bin edges; bars are placed at the bin centres with the bin widths.  Bars are
            at 0..B-1 if None.
        """
        c = np.asarray(counts, dtype=float)
        if c.ndim != 1:
            raise DataError(f"counts must have shape (B,), got {c.shape}")
        kwargs: dict[str, Any] = {}
        if x_edges is not None:
            e = _edges(x_edges, c.shape[0])
            # the bins' places and widths are logged again only when they change (the viewer
            # shows the latest ones): converting them took half the time of every frame's chart
            if not np.array_equal(self._bar_edges.get(entity), e):
                kwargs["abscissa"] = 0.5 * (e[:-1] + e[1:])
                kwargs["widths"] = np.diff(e).astype(np.float32)
                self._bar_edges[entity] = e
        if color is not None:
            kwargs["color"] = _color(color)[None]
        self._note(entity)
        self._emit(entity, "BarChart", values=c, **kwargs)

    def log_histogram_image(self, entity: str, matrix: np.ndarray, x_edges: np.ndarray, *,
                            first_frame: int = 0) -> None:
        """Log the static "histogram over time" heat-map (see :func:`histogram_image`).

        Row ``t`` is frame ``first_frame + t`` and runs down the image; column ``j`` is bin
        ``j``.  A transform places the image so that its 2-D coordinates read directly as
        (bin value, frame): pixel column ``j`` covers ``x_edges[j]..x_edges[j+1]``.  The
        edges are also stored on the entity (``x_edges``).

        Parameters
        ----------
        matrix : ndarray of shape (T, B)
            Non-negative counts per frame and bin.
        x_edges : ndarray of shape (B + 1,)
            Equally spaced bin edges.
        """
        import rerun as rr

        img = histogram_image(matrix)
        e = _edges(x_edges, img.shape[1])
        step = np.diff(e)
        if not np.allclose(step, step[0], rtol=1e-6, atol=0.0):
            raise DataError("x_edges must be equally spaced for the histogram image")
        # Rerun reads an image one row high as having one channel: a one-frame heat-map is
        # stored as two rows of half a frame each
        rows_per_frame = 2 if img.shape[0] == 1 else 1
        img = np.repeat(img, rows_per_frame, axis=0)
        self._note(entity)
        self.stream.log(entity, rr.Image(img, color_model="RGB"), static=True)
        self.stream.log(entity, rr.Transform3D(translation=[float(e[0]), float(first_frame), 0.0],
                                               scale=[float(step[0]), 1.0 / rows_per_frame, 1.0]), static=True)
        self.stream.log(entity, rr.AnyValues(x_edges=e.tolist(), first_frame=int(first_frame)),
                        static=True)

    def log_label_strip(self, entity: str, posterior: np.ndarray, names: Sequence[str], *,
                        first_frame: int = 0, row_height: int = 12) -> None:
        """Log the static label strip of a mixed-state run: one band per label, one column per
        frame, brighter where the label's posterior probability is higher (viridis: dark 0,
        yellow 1).  Pixel column ``t`` is frame ``first_frame + t``; the label names are stored
        on the entity (``labels``, top to bottom).

        Parameters
        ----------
        posterior : ndarray of shape (T, L)
            Per frame the posterior probability of each of the ``L`` labels.
        """
        import cv2
        import rerun as rr

        P = np.asarray(posterior, dtype=float)
        if P.ndim != 2 or P.shape[1] != len(names) or P.shape[0] < 1:
            raise DataError(f"posterior must have shape (T, {len(names)}), got {P.shape}")
        P = np.clip(np.nan_to_num(P, nan=0.0), 0.0, 1.0)
        grey = np.rint(255 * P.T).astype(np.uint8)  # (L, T)
        colour = cv2.applyColorMap(np.repeat(grey, row_height, axis=0), cv2.COLORMAP_VIRIDIS)[..., ::-1]
        self._note(entity)
        self.stream.log(entity, rr.Image(np.ascontiguousarray(colour), color_model="RGB"), static=True)
        self.stream.log(entity, rr.Transform3D(translation=[float(first_frame), 0.0, 0.0]), static=True)
        self.stream.log(entity, rr.AnyValues(labels=list(names), first_frame=int(first_frame)), static=True)

    # -- text ----------------------------------------------------------------

    def log_params(self, entity: str, params: Mapping[str, Any]) -> None:
        """Store the run's settings (static): as ``AnyValues`` and as a YAML document.

        Nested mappings become dotted keys (``dynamics.beta``); None values are left out
        of the ``AnyValues`` but kept in the YAML text.
        """
        import rerun as rr
        import yaml

        if not isinstance(params, Mapping):
            raise DataError(f"params must be a mapping, got {type(params).__name__}")
        text = yaml.safe_dump(_plain(params), sort_keys=False, default_flow_style=False)
        self._note(entity)
        self.stream.log(entity, rr.TextDocument(f"```yaml\n{text}```", media_type="text/markdown"),
                        static=True)
        flat = _flatten(params)
        if flat:
            self.stream.log(entity, rr.AnyValues(**flat), static=True)

    def log_text(self, entity: str, text: str, level: str = "INFO") -> None:
        """Log a message at the current frame, with a level from :data:`TEXT_LEVELS`."""
        import rerun as rr

        lv = str(level).upper()
        if lv not in TEXT_LEVELS:
            raise ConfigError(f"unknown text level {level!r}; valid: {', '.join(TEXT_LEVELS)}")
        self._note(entity)
        self.stream.log(entity, rr.TextLog(str(text), level=lv))

