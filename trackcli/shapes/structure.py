"""Structure templates: an object as a centre and rays to its parts (003, Zobel et al.).

A structure template is an ordinary contour template (the outline of the whole object, so
that every other command reads it) with a ``parts`` list: for each part its name, its box
``[x, y, w, h]`` on the template's frame and its grey-level image patch (a PNG, base64 in
the YAML).  The structure's centre is the mean of the parts' centres; each part hangs on
it by a ray (length, angle).  :mod:`trackcli.trackers.coupled` follows such a structure.
"""

from __future__ import annotations

import base64
import math
import re
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from trackcli.errors import ConfigError, TemplateError

#: part names: a letter, then letters, digits, ``_`` or ``-``
PART_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,31}$")


@dataclass(frozen=True, eq=False)
class Part:
    """One part: its name, box ``(x, y, w, h)`` on the template's frame, grey patch ``(h, w)`` uint8."""

    name: str
    box: tuple[float, float, float, float]
    patch: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        x, y, w, h = self.box
        return np.array([x + w / 2.0, y + h / 2.0])


def parse_part(spec: str) -> tuple[str, tuple[float, float, float, float]]:
    """``NAME:x,y,w,h`` → ``(name, box)``; a one-line :class:`ConfigError` otherwise."""
    name, sep, rest = spec.partition(":")
    if not sep or not PART_NAME.match(name):
        raise ConfigError(f"--parts {spec!r}: expected NAME:x,y,w,h with NAME a letter followed by letters, "
                          "digits, _ or -")
    try:
        box = tuple(float(v) for v in rest.split(","))
    except ValueError:
        raise ConfigError(f"--parts {spec!r}: x,y,w,h must be numbers") from None
    if len(box) != 4 or not all(math.isfinite(v) for v in box):
        raise ConfigError(f"--parts {spec!r}: expected four numbers x,y,w,h")
    if box[2] < 3 or box[3] < 3:
        raise ConfigError(f"--parts {spec!r}: a part must be at least 3x3 px")
    return name, box  # type: ignore[return-value]


def cut_parts(grey: np.ndarray, specs: Sequence[tuple[str, tuple[float, float, float, float]]]) -> list[Part]:
    """The patches of ``specs`` (name, box) cut from the grey frame; boxes must lie inside it."""
    h_img, w_img = grey.shape[:2]
    names = [n for n, _ in specs]
    if len(specs) < 2:
        raise ConfigError("--parts: a structure needs at least two parts")
    if len(set(names)) != len(names):
        raise ConfigError(f"--parts: part names must differ, got {', '.join(names)}")
    parts = []
    for name, (x, y, w, h) in specs:
        x0, y0 = int(round(x)), int(round(y))
        x1, y1 = x0 + int(round(w)), y0 + int(round(h))
        if x0 < 0 or y0 < 0 or x1 > w_img or y1 > h_img:
            raise ConfigError(f"--parts {name}: box {x:g},{y:g},{w:g},{h:g} is not inside the {w_img}x{h_img} frame")
        parts.append(Part(name, (float(x0), float(y0), float(x1 - x0), float(y1 - y0)),
                          np.ascontiguousarray(grey[y0:y1, x0:x1]).astype(np.uint8)))
    return parts


def parts_to_yaml(parts: Sequence[Part]) -> list[dict[str, Any]]:
    import cv2

    out = []
    for p in parts:
        ok, buf = cv2.imencode(".png", p.patch)
        if not ok:
            raise TemplateError(f"part {p.name}: cannot encode its patch")
        out.append({"name": p.name, "box": [round(float(v), 3) for v in p.box],
                    "patch_png": base64.b64encode(buf.tobytes()).decode("ascii")})
    return out


def parts_from_template(template: Any, where: str) -> list[Part]:
    """The parts of a structure template, validated; a one-line :class:`TemplateError` if it has none
    or any is malformed."""
    import cv2

    raw = getattr(template, "extra", {}).get("parts")
    if raw is None:
        raise TemplateError(f"{where}: not a structure template (no parts); draw one with "
                            "`trackcli draw CLIP --parts NAME:x,y,w,h ...`")
    if not isinstance(raw, list) or len(raw) < 2:
        raise TemplateError(f"{where}: parts must be a list of at least two parts")
    parts, names = [], set()
    for i, d in enumerate(raw):
        at = f"{where}: parts[{i}]"
        if not isinstance(d, dict):
            raise TemplateError(f"{at}: expected a mapping with name, box and patch_png")
        name = d.get("name")
        if not isinstance(name, str) or not PART_NAME.match(name) or name in names:
            raise TemplateError(f"{at}: name must be a unique word, got {name!r}")
        names.add(name)
        box = d.get("box")
        try:
            box_t = tuple(float(v) for v in box)
        except (TypeError, ValueError):
            raise TemplateError(f"{at}: box must be [x, y, w, h], got {box!r}") from None
        if len(box_t) != 4 or not all(math.isfinite(v) for v in box_t) or box_t[2] < 3 or box_t[3] < 3:
            raise TemplateError(f"{at}: box must be four finite numbers with w, h >= 3, got {box!r}")
        try:
            data = base64.b64decode(str(d.get("patch_png", "")), validate=True)
            patch = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
        except (ValueError, TypeError):
            patch = None
        if patch is None:
            raise TemplateError(f"{at}: patch_png is not a base64 PNG image")
        if patch.shape != (int(round(box_t[3])), int(round(box_t[2]))):
            raise TemplateError(f"{at}: the patch is {patch.shape[1]}x{patch.shape[0]} px, the box "
                                f"{box_t[2]:g}x{box_t[3]:g}")
        parts.append(Part(name, box_t, patch))  # type: ignore[arg-type]
    return parts
