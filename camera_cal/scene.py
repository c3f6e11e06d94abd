"""Scene geometry from the footage itself: the live part of the picture and the horizon.

A dashcam's picture may carry black bars (a 4:3 sensor in a 16:9 file, a letterbox) and its
horizon sits wherever the camera's height and pitch put it. Both are read off the frames: bars are
rows and columns that stay black in every frame seen; the horizon is the row of the vanishing
point of the road's straight edges (lane lines, kerbs, barriers), the median over recent frames,
and the caller's default until there is enough evidence.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 (x1, y1 exclusive)
MEASURE_WIDTH = 640


@dataclass(frozen=True)
class SceneGeometry:
    """Where the road can be seen in frames of `size`: the live box and the horizon row."""

    size: tuple[int, int]
    horizon_y: float
    live: Box
    estimated: bool = False  # the horizon came from the footage (not the default)


def scale_height(live_size: tuple[int, int]) -> float:
    """The height of the 16:9 picture a live box of `live_size` (width, height) is taken to be
    cut from: its longer side spans the 16:9 width or its shorter side the height, whichever
    gives more. A flat road does not reveal the focal length, so without a calibration the lens
    is taken as the tuned one: cropped at the top, bottom or sides, scaled or padded, the
    pictures then keep the tuned scale (another lens scales distances by the focal lengths'
    ratio)."""
    long_side, short_side = max(live_size), min(live_size)
    return float(max(long_side * 9 / 16, short_side))


def live_box(row_max: NDArray[np.uint8], col_max: NDArray[np.uint8], dark: int = 24) -> Box:
    """The box inside the black bars, from the brightest value seen in each row and column
    (a bar is black in every frame; a whole dark frame yields the full box)."""
    rows = np.flatnonzero(row_max > dark)
    cols = np.flatnonzero(col_max > dark)
    if len(rows) == 0 or len(cols) == 0:
        return 0, 0, len(col_max), len(row_max)
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def road_segments(grey: NDArray[np.uint8], live: Box, top: int) -> NDArray[np.float64]:
    """Straight edge segments (x1, y1, x2, y2) below row `top` inside the live box, slanted
    20-75 degrees from the horizontal as the road's edges are seen ahead."""
    x0, y0, x1, y1 = live
    top = max(top, y0)
    if y1 - top < 16 or x1 - x0 < 16:
        return np.empty((0, 4))
    part = cv2.GaussianBlur(grey[top:y1, x0:x1], (5, 5), 0)
    edges = cv2.Canny(part, 60, 150)
    # Bar edges and the picture's border are no road edges.
    edges[:, :3] = edges[:, -3:] = 0
    edges[-3:] = 0
    h = y1 - y0
    found = cv2.HoughLinesP(
        edges, 1, np.pi / 180, 40, minLineLength=max(h // 12, 12), maxLineGap=max(h // 60, 2)
    )
    if found is None:
        return np.empty((0, 4))
    segments = found.reshape(-1, 4).astype(np.float64) + np.array([x0, top, x0, top])
    dx = segments[:, 2] - segments[:, 0]
    dy = segments[:, 3] - segments[:, 1]
    angle = np.degrees(np.arctan2(np.abs(dy), np.abs(dx)))
    return np.asarray(segments[(angle > 20) & (angle < 75)], np.float64)


def vanishing_point(
    segments: NDArray[np.float64], tolerance: float, min_segments: int = 4
) -> NDArray[np.float64] | None:
    """The point nearest to every segment's line (length-weighted least squares, outliers
    down-weighted past `tolerance` pixels), or None with too few segments leaning both ways."""
    if len(segments) < min_segments:
        return None
    dx = segments[:, 2] - segments[:, 0]
    dy = segments[:, 3] - segments[:, 1]
    leaning = np.sign(dx * dy)
    if min((leaning > 0).sum(), (leaning < 0).sum()) < 2:
        return None  # one family of parallel edges fixes no point
    length = np.hypot(dx, dy)
    normals = np.column_stack([dy, -dx]) / length[:, None]
    offsets = (normals * segments[:, :2]).sum(axis=1)
    weights = length
    point = None
    for _ in range(8):
        point = np.linalg.lstsq(normals * weights[:, None], offsets * weights, rcond=None)[0]
        residual = np.abs(normals @ point - offsets)
        weights = length / (1.0 + (residual / tolerance) ** 2)
    assert point is not None
    return np.asarray(point, np.float64)


class SceneTracker:
    """History for the scene geometry: the brightest value seen per row and column (for the
    bars) and the recent vanishing points (for the horizon).

    `default_horizon` is used until `min_estimates` frames gave a vanishing point, and always when
    `fixed_horizon` is set (the user's `--horizon`). The horizon is measured on every frame until
    then, and every `every` frames after (it changes slowly; each costs a few milliseconds).
    `fixed_scale` is the scale height of a calibrated lens; without it the live box gives it.
    """

    def __init__(
        self,
        size: tuple[int, int],
        default_horizon: float,
        fixed_horizon: float | None = None,
        window: int = 60,
        min_estimates: int = 5,
        every: int = 3,
        settle: float = 0.015,
        fixed_scale: float | None = None,
    ) -> None:
        self.size = size
        self.fixed_scale = fixed_scale
        self.default_horizon = default_horizon
        self.fixed_horizon = fixed_horizon
        self.min_estimates = min_estimates
        self.every = every
        self.settle = settle
        self._estimates: deque[float] = deque(maxlen=window)
        self._row_max = np.zeros(size[1], np.uint8)
        self._col_max = np.zeros(size[0], np.uint8)
        self._count = 0
        self._current = SceneGeometry(
            size, fixed_horizon if fixed_horizon is not None else default_horizon, self._box()
        )
        self._placed = (self._current.horizon_y, self._current.live)

    def _box(self) -> Box:
        if not self._count:
            return 0, 0, self.size[0], self.size[1]
        return live_box(self._row_max, self._col_max)

    @property
    def current(self) -> SceneGeometry:
        """The geometry as of the last frame."""
        return self._current

    def update(self, rgb: NDArray[np.uint8]) -> SceneGeometry:
        """Take in one frame; the geometry as of it."""
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        # Bars: sample every 4th row and column (bars are wide; this costs ~1 ms).
        np.maximum(self._row_max, grey[:, ::4].max(axis=1), out=self._row_max)
        np.maximum(self._col_max, grey[::4].max(axis=0), out=self._col_max)
        # Every frame until the first estimate stands (the stages use the default until then),
        # then every few.
        due = self._count % self.every == 0 or len(self._estimates) < self.min_estimates
        live = self._box() if due else self._current.live
        if self.fixed_horizon is None and due:
            self._measure(grey, live)
        self._count += 1
        if self.fixed_horizon is not None:
            horizon, estimated = self.fixed_horizon, False
        elif len(self._estimates) >= self.min_estimates:
            horizon, estimated = float(np.median(self._estimates)), True
        else:
            horizon, estimated = self.default_horizon, False
        self._current = SceneGeometry(self.size, horizon, live, estimated)
        tolerance = self.settle * self.size[1]
        placed_horizon, placed_live = self._placed
        moved = abs(horizon - placed_horizon) > tolerance or any(
            abs(a - b) > tolerance for a, b in zip(live, placed_live, strict=True)
        )
        if moved:
            self._placed = (horizon, live)
        return self._current

    @property
    def placement(self) -> dict[str, Any]:
        """The horizon, live box and scale height as the stages place their work by (their
        `process` keywords): they follow the estimate in steps of more than `settle` of the
        height, so its wobble neither restarts the lanes' history nor moves the vehicle bands."""
        horizon, (x0, y0, x1, y1) = self._placed
        return {
            "horizon_y": horizon,
            "live": (x0, y0, x1, y1),
            "scale_height": scale_height((x1 - x0, y1 - y0))
            if self.fixed_scale is None
            else self.fixed_scale,
        }

    def _measure(self, grey: NDArray[np.uint8], live: Box) -> None:
        """Add this frame's vanishing point row, when the road's edges give one (measured at
        most 640 pixels wide: as exact, and four times cheaper on HD)."""
        scale = min(1.0, MEASURE_WIDTH / grey.shape[1])
        if scale < 1.0:
            grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        x0, y0, x1, y1 = (round(v * scale) for v in live)
        h = y1 - y0
        # Edges from a little below the current horizon down: the road, not the sky.
        top = round(max(self._current.horizon_y * scale, y0 + 0.2 * h) + 0.05 * h)
        segments = road_segments(grey, (x0, y0, x1, y1), top)
        point = vanishing_point(segments, tolerance=0.02 * h)
        if point is None:
            return
        x, y = point
        if x0 <= x < x1 and y0 + 0.15 * h <= y <= y0 + 0.8 * h:
            self._estimates.append(float(y) / scale)
