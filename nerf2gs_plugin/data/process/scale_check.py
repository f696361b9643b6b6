"""Is the reconstruction one scale along the capture? A check of the camera's height above its own road.

Why: incremental SfM can register every frame and still join two stretches of a capture at different
scales (the synthetic street's drive down and back: every frame registered, each pass accurate, the
second pass many times the scale of the first). A registered count does not show it, and the metric
scale, set from the median camera height, is then wrong for one of the stretches. A car or a walker
carries the camera at about one height, so the camera's height above the road it sees, in SfM units,
should be about constant along the capture; a stretch where it jumps by several times is a join at
the wrong scale (or a capture that is not one road).

Each camera's local height is read from its own observations: the sparse points it sees below it
(along up) and nearer than the median of them (horizontally: far points carry any error of up times
their distance), of which the road is the lowest surface, so a high percentile of their drops below
the camera is its height above the road. Scale-free: only ratios of heights are compared.

A join can also keep the scale and misplace the second stretch along the path (a forward drive came
out as two accurate halves a few frame spacings apart along the street): the camera's step from one
frame to the next (in name order) then jumps. :func:`path_jump` finds the largest step against the
steps around it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Optional, Sequence

import numpy as np

MAX_HEIGHT_JUMP = 4.0
"""The largest ratio between the median local camera heights of two stretches of one capture that is
still one scale. A mount's height above its road moves by well under 2x (slopes, kerbs, a walker's
stride); good captures stay far below it and wrong joins far above (a join that keeps the scale is the
path check's case; benchmarks/results/scale_check.md)."""
DROP_PERCENTILE = 90.0
"""The percentile of a camera's drops to the points below it taken as its height: the road is the
lowest surface it sees, most points lie above it (facades, cars)."""
MAX_STEP_JUMP = 4.0
"""The largest step between consecutive frames of an ordered capture (a video, or photos matched
sequentially), over the median of the steps around it, that is still one path: a video's frames come
at one rate, and a blurry frame dropped doubles one step; a wrong join jumps far more."""
MAX_STEP_JUMP_PHOTOS = 10.0
"""The same for a photo set matched exhaustively (its name order may not be a path): a walker's photos
jump, a wrong join (two passes joined, a frame misplaced) jumps more."""
STEP_WINDOW = 5
"""Steps on each side a step is compared with."""
STANDING = 0.1
"""A step under this fraction of the path's moving scale (its steps' 75th percentile) is the camera standing."""
STANDING_DEG = 2.0
"""A frame within :data:`STANDING` of the last frame kept is still a new view when it turned by more than this."""
MIN_POINTS_BELOW = 10
"""Fewer observed points below a camera than this: no local height for it."""


def local_camera_heights(centres: np.ndarray, observed: Sequence[np.ndarray], up: np.ndarray) -> np.ndarray:
    """``[N]`` each camera's height above the surface it sees below it (data units; NaN where it sees
    fewer than :data:`MIN_POINTS_BELOW` points below it): :data:`DROP_PERCENTILE` of the drops to the
    nearer half of those points. ``centres [N, 3]``, ``observed``: per camera the ``[K, 3]`` sparse
    points it observes, ``up [3]`` in the same frame."""
    up = np.asarray(up, dtype=np.float64)
    up = up / (np.linalg.norm(up) + 1e-12)
    out = np.full(len(centres), np.nan)
    for i, (c, pts) in enumerate(zip(np.asarray(centres, dtype=np.float64), observed)):
        v = c - np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        drop = v @ up
        below = drop > 0
        if int(below.sum()) < MIN_POINTS_BELOW:
            continue
        across = np.linalg.norm(v[below] - drop[below, None] * up, axis=1)  # horizontal distance
        out[i] = np.percentile(drop[below][across <= np.median(across)], DROP_PERCENTILE)
    return out


@dataclass
class ScaleCheck:
    """The strongest scale jump along a capture (frames in capture order)."""

    frames: int
    measured: int
    """Cameras with a local height."""
    ratio: float
    """Median local height of the higher stretch over the lower one (1.0: one scale)."""
    split: int
    """Index of the first frame of the second stretch, in capture order (0: no split measured)."""
    first_name: str = ""
    """Name of that frame."""
    second_higher: bool = True
    """The second stretch stands higher above its road (in data units) than the first."""

    @property
    def consistent(self) -> bool:
        return self.ratio <= MAX_HEIGHT_JUMP

    def problem(self) -> tuple[str, str]:
        """(what is wrong, what it means and what to try) of an inconsistent capture."""
        where = f"from frame {self.split} ({self.first_name}) on" if self.first_name else f"from frame {self.split} on"
        return (f"the reconstruction changes scale along the capture: {where} the camera stands {self.ratio:.1f}x "
                f"{'higher' if self.second_higher else 'lower'} above the road, in SfM units, than before it",
                "SfM joined two stretches at different scales and the metric scale fits one of them: try --matching "
                "exhaustive, more frames (--fps / --num-frames), or process the stretches separately")

    @property
    def summary(self) -> str:
        if self.split == 0:
            return f"scale not compared ({self.measured} of {self.frames} cameras see points below them)"
        if self.consistent:
            return f"one scale (camera height above the road within {self.ratio:.1f}x along the capture)"
        return f"scale {self.ratio:.1f}x apart from {self.first_name or f'frame {self.split}'} on"

    def to_json(self) -> dict:
        return {**asdict(self), "consistent": self.consistent, "max_ratio": MAX_HEIGHT_JUMP}


def scale_jump(heights: np.ndarray, names: Optional[Sequence[str]] = None, min_segment: Optional[int] = None) -> ScaleCheck:
    """The change point of the capture's log local heights (in order): the split into two stretches
    that fits them best by their medians (least absolute deviations), and the ratio of those medians.
    Both stretches hold at least ``min_segment`` measured cameras (default: 3, or 5% of them)."""
    h = np.asarray(heights, dtype=np.float64)
    idx = np.flatnonzero(np.isfinite(h) & (h > 0))
    m = min_segment if min_segment is not None else max(3, int(0.05 * len(idx)))
    if len(idx) < 2 * m:
        return ScaleCheck(len(h), len(idx), 1.0, 0)
    logs = np.log(h[idx])
    best = None
    for k in range(m, len(idx) - m + 1):
        a, b = np.median(logs[:k]), np.median(logs[k:])
        cost = float(np.abs(logs[:k] - a).sum() + np.abs(logs[k:] - b).sum())
        if best is None or cost < best[0]:
            best = (cost, k, float(b - a))
    _, at, d = best
    split = int(idx[at])
    return ScaleCheck(len(h), len(idx), float(np.exp(abs(d))), split, names[split] if names is not None else "", d > 0)


@dataclass
class PathJump:
    """The largest step of an ordered capture's camera path against the steps around it."""

    ratio: float
    index: int
    """The step from frame ``index`` to frame ``index + 1`` (capture order)."""
    names: tuple[str, str] = ("", "")
    max_ratio: float = MAX_STEP_JUMP

    @property
    def consistent(self) -> bool:
        return self.ratio <= self.max_ratio

    @property
    def _frames(self) -> tuple[str, str]:
        return self.names if self.names[0] else (f"frame {self.index}", f"frame {self.index + 1}")

    @property
    def summary(self) -> str:
        if self.consistent:
            return f"one path (largest step {self.ratio:.1f}x the steps around it)"
        a, b = self._frames
        return f"path jump {self.ratio:.1f}x between {a} and {b}"

    def problem(self) -> tuple[str, str]:
        a, b = self._frames
        return (f"the camera path jumps between {a} and {b}: {self.ratio:.1f}x the step between the frames around them",
                "a gap in the capture, or SfM joined two stretches of it in the wrong place (every frame registered, the "
                "path broken): try --matching exhaustive, more frames (--fps / --num-frames), or process the stretches separately")

    def to_json(self) -> dict:
        return {**asdict(self), "consistent": self.consistent}


def _steps_and_standing(centres: np.ndarray) -> tuple[np.ndarray, float]:
    """``[N-1]`` the path's steps (capture order) and the step under which the camera stands: :data:`STANDING`
    of the path's moving scale (its steps' 75th percentile)."""
    steps = np.linalg.norm(np.diff(np.asarray(centres, dtype=np.float64), axis=0), axis=1)
    return steps, STANDING * float(np.percentile(steps, 75))


def path_jump(centres: np.ndarray, names: Optional[Sequence[str]] = None, max_ratio: float = MAX_STEP_JUMP) -> Optional[PathJump]:
    """The step of the path ``centres [N, 3]`` (capture order) largest against the median of the moving steps
    among the :data:`STEP_WINDOW` steps on each side, flagged above ``max_ratio``; None for fewer than 4 frames.
    Standing steps (under :data:`STANDING` of the path's moving scale: a car at a red light) are compared with
    nothing and taken as nothing's neighbour: beside a stop, half the window would be ~0 and any motion a jump."""
    c = np.asarray(centres, dtype=np.float64)
    if len(c) < 4:
        return None
    steps, standing = _steps_and_standing(c)
    n, w = len(steps), STEP_WINDOW
    ratio = np.zeros(n)
    moving = steps > standing
    for i in np.flatnonzero(moving):
        near = np.r_[max(0, i - w):i, i + 1:min(n, i + 1 + w)]
        around = steps[near[moving[near]]]
        if len(around):
            ratio[i] = steps[i] / float(np.median(around))
    i = int(ratio.argmax())
    return PathJump(float(ratio[i]), i, (names[i], names[i + 1]) if names is not None else ("", ""), max_ratio)


def standing_frames(c2w: np.ndarray, names: Sequence[str]) -> list[str]:
    """The frames of an ordered capture (``c2w [N, 3|4, 4]``, capture order) where the camera stood: within
    :data:`STANDING` of the path's moving scale and :data:`STANDING_DEG` of the last frame kept (the first of
    a stop is kept). A car at a red light films one view many times: the training draws it as often, and
    the views from above repeat it."""
    c2w = np.asarray(c2w, dtype=np.float64)
    if len(c2w) < 4:
        return []
    centres = c2w[:, :3, 3]
    _, near = _steps_and_standing(centres)
    cos_max = np.cos(np.radians(STANDING_DEG))
    out, last = [], 0
    for i in range(1, len(c2w)):
        turn = (np.trace(c2w[last, :3, :3].T @ c2w[i, :3, :3]) - 1) / 2  # cos of the rotation between them
        if np.linalg.norm(centres[i] - centres[last]) < near and turn > cos_max:
            out.append(str(names[i]))
        else:
            last = i
    return out
