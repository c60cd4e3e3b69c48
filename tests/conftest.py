"""Shared fixtures: the repository root, the sample clips, and a small synthetic clip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# Property tests draw the same examples on every run: a newcomer's first run passes or fails
# exactly as CI did (examples are still varied across the strategies, not random per run).
settings.register_profile("trackcli", derandomize=True)
settings.load_profile("trackcli")

REPO = Path(__file__).resolve().parent.parent
SAMPLE_DATA = REPO / "sample_data"
CONFIGS = REPO / "configs"

# The small synthetic clip: a dark ellipse drifting right over a light, noisy background.
CLIP_SIZE = (160, 120)  # (width, height)
CLIP_FRAMES = 6
CLIP_ELLIPSE = (70.0, 60.0, 28.0, 36.0)  # cx, cy, semi-axis along x, semi-axis along y in frame 0
CLIP_DRIFT = 2.0  # px per frame along x


def sample_clip(name: str) -> Path:
    """The sample video ``name`` (``train``, ``test``, ...) or skip the test if it is absent."""
    for ext in (".mp4", ".avi"):
        p = SAMPLE_DATA / f"{name}{ext}"
        if p.is_file():
            truth = SAMPLE_DATA / f"{name}.truth.csv"
            outline = SAMPLE_DATA / f"{name}.outline.json"
            if truth.is_file() and outline.is_file():
                return p
    pytest.skip(f"sample_data/{name} (video, truth and outline) not generated yet")


def ellipse_frame(rng: np.random.Generator, k: int = 0) -> np.ndarray:
    """Frame ``k`` of the synthetic clip: ``(120, 160, 3)`` uint8 BGR."""
    import cv2

    w, h = CLIP_SIZE
    img = np.full((h, w, 3), 200.0) + rng.normal(0.0, 6.0, (h, w, 3))
    img = np.clip(img, 0, 255).astype(np.uint8)
    cx, cy, a, b = CLIP_ELLIPSE
    cv2.ellipse(img, ((cx + CLIP_DRIFT * k, cy), (2 * a, 2 * b), 0.0), (40, 40, 40), -1, cv2.LINE_AA)
    return img


def write_ellipse_clip(path: Path, n_frames: int = CLIP_FRAMES, seed: int = 11) -> Path:
    """Write ``n_frames`` of :func:`ellipse_frame` to ``path`` as a 25 frames/s Motion-JPEG .avi."""
    import cv2

    rng = np.random.default_rng(seed)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, CLIP_SIZE)
    assert writer.isOpened(), "OpenCV cannot write MJPG .avi here"
    for k in range(n_frames):
        writer.write(ellipse_frame(rng, k))
    writer.release()
    return path


@pytest.fixture(scope="session")
def ellipse_clip(tmp_path_factory) -> Path:
    """A 6-frame 160x120 Motion-JPEG .avi of a dark ellipse drifting over a noisy background."""
    return write_ellipse_clip(tmp_path_factory.mktemp("clip") / "ellipse.avi")


def check_placed(learned, placed) -> None:
    """A stable learned model must be placed stable (spectral radius < 1)."""
    if learned.spectral_radius() < 1.0:
        radius = placed.spectral_radius()
        assert radius < 1.0, f"placing a stable model (spectral radius {learned.spectral_radius():.4f}) " \
                             f"gave spectral radius {radius:.4f}"


@pytest.fixture(autouse=True)
def _every_placed_model_is_checked(monkeypatch):
    """Route every ``trackcli.dynamics.model.place_dynamics`` call of a test through :func:`check_placed`."""
    from trackcli.dynamics import model

    original = model.place_dynamics

    def checked(dynamics, *args, **kwargs):
        placed = original(dynamics, *args, **kwargs)
        check_placed(dynamics, placed)
        return placed

    monkeypatch.setattr(model, "place_dynamics", checked)
