"""A camera's roll read off the footage: the lean of the vehicles' rear edges.

The rear of a vehicle ahead is an upright face across the road, nearly parallel to the picture,
and lines parallel to the picture keep their direction in it: its bumper, lights, number plate,
rear window and roof line lie level in a level picture wherever the vehicle is, near or far,
left or right. In a picture turned by a camera mounted askew they lean by the turn. The road's
own lines do not tell it (their lean mixes the turn with where the camera is in its lane), and
a highway has few upright posts (README, A camera mounted askew).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class LevelConfig:
    """How a box's edges give a lean, and when the leans of many say the picture is turned.

    A box's lean is the commonest direction of its strongest edges within `search_deg` of level
    (the top `strong` share of its gradients, inside `inset` of its width and height off each
    side: the road and background at its rim), in bins of `bin_deg`, refined `passes` times as
    the mean of those within `band_deg` of it; boxes under `min_box_px` across are too coarse,
    and those over `max_box_px` are read shrunk to it (a near car's rear costs no more). The
    picture is taken as turned once `least` leans are in, their median at least
    `min_roll_deg` off level and at most `max_roll_deg`, their quartiles within
    `max_spread_deg` of each other, and the vehicles that gave `vehicle_leans` or more agree
    with it: at least `vehicles` of them, and more than half, with their own median within
    `max_spread_deg` of it. One vehicle's edges can lean on their own (a car seen from its
    side, or turned on a bend: one on the level LA clip leant 2.7 degrees for 21 frames); a
    turned picture turns every vehicle's. Measured (README): the shared clips level read -0.1
    to 0.3, turned 3 degrees 2.9-3.3; LA's leans scatter too far to be taken."""

    search_deg: float = 12.0
    bin_deg: float = 0.5
    band_deg: float = 4.0
    strong: float = 0.2
    inset: float = 0.05
    passes: int = 3
    min_pixels: int = 20
    min_box_px: int = 24
    max_box_px: int = 128
    least: int = 20
    min_roll_deg: float = 1.5
    max_roll_deg: float = 8.0
    max_spread_deg: float = 1.5
    vehicles: int = 2
    vehicle_leans: int = 5


def edge_lean(
    rgb: NDArray[np.uint8], box: tuple[float, float, float, float], config: LevelConfig
) -> float | None:
    """The lean in degrees (anticlockwise positive, rising to the right, as `--roll` counts)
    of the near-level edges inside `box` (x0, y0, x1, y1) of an RGB picture; None when the box
    is too small or shows too few such edges."""
    x0, y0, x1, y1 = box
    dx, dy = (x1 - x0) * config.inset, (y1 - y0) * config.inset
    h, w = rgb.shape[:2]
    c0, r0 = max(round(x0 + dx), 0), max(round(y0 + dy), 0)
    c1, r1 = min(round(x1 - dx), w), min(round(y1 - dy), h)
    if c1 - c0 < config.min_box_px or r1 - r0 < config.min_box_px // 2:
        return None
    grey = cv2.cvtColor(np.ascontiguousarray(rgb[r0:r1, c0:c1]), cv2.COLOR_RGB2GRAY)
    if c1 - c0 > config.max_box_px:  # a near car's rear: its edges lean as they do smaller
        scale = config.max_box_px / (c1 - c0)
        size = (config.max_box_px, max(round((r1 - r0) * scale), 1))
        grey = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
    # Scharr's kernels: their gradient's direction is truer than Sobel's (which read a step
    # edge turned 5 degrees as 4.5).
    # The crop's outermost pixels are left out: mirrored at the border, their horizontal
    # gradient is 0, so that every one of them read as a level edge (LA's small cars' leans
    # then stayed near level in a turned picture).
    gx = cv2.Scharr(grey, cv2.CV_32F, 1, 0)[1:-1, 1:-1]
    gy = cv2.Scharr(grey, cv2.CV_32F, 0, 1)[1:-1, 1:-1]
    energy = (gx * gx + gy * gy).ravel()
    cut = min(int(len(energy) * (1.0 - config.strong)), len(energy) - 1)
    strong = energy > np.partition(energy, cut)[cut]
    # An edge's lean from level is its gradient's from the vertical, folded into +-90 degrees
    # (of the strong ones alone: most of a box's cost is here).
    lean = (np.degrees(np.arctan2(gx.ravel()[strong], gy.ravel()[strong])) + 90.0) % 180.0 - 90.0
    weight = energy[strong]
    near = np.abs(lean) < config.search_deg
    lean, weight = lean[near], weight[near]
    if len(lean) < config.min_pixels:
        return None
    # The mode of the leans weighed by their energy (bins of `bin_deg`, smoothed over a degree
    # either way: a turned edge's pixel steps scatter them), then the weighted mean of those
    # within `band_deg` of it: a turned picture's edges are found wherever they lean within
    # the search, not pulled towards level.
    bins = round(2 * config.search_deg / config.bin_deg)
    index = np.clip(((lean + config.search_deg) / config.bin_deg).astype(int), 0, bins - 1)
    histogram = np.bincount(index, weight, bins)
    spread = np.arange(-4, 5) * config.bin_deg
    smooth = np.convolve(histogram, np.exp(-0.5 * (spread / 1.0) ** 2), mode="same")
    centre = (int(np.argmax(smooth)) + 0.5) * config.bin_deg - config.search_deg
    for _ in range(config.passes):
        close = np.abs(lean - centre) < config.band_deg
        if np.count_nonzero(close) < config.min_pixels:
            return None
        centre = float(np.sum(lean[close] * weight[close]) / np.sum(weight[close]))
    return centre


class RollReading:
    """History of the leans of vehicles' boxes (the last `keep`, with the vehicle's track id):
    the picture's turn once they, and the vehicles, agree on one."""

    def __init__(self, config: LevelConfig | None = None, keep: int = 200) -> None:
        self.config = config if config is not None else LevelConfig()
        self._leans: deque[tuple[int, float]] = deque(maxlen=keep)

    def reset(self) -> None:
        """Forget the leans (another shot, perhaps another camera)."""
        self._leans.clear()

    def update(
        self, rgb: NDArray[np.uint8], boxes: NDArray[np.float64], ids: NDArray[np.int_]
    ) -> float | None:
        """Take in one frame's vehicle boxes ((n, 4) x0, y0, x1, y1, wholly inside the
        picture) and their track ids; the turn read so far (see `roll_deg`)."""
        h, w = rgb.shape[:2]
        for (x0, y0, x1, y1), vehicle in zip(
            np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(ids), strict=True
        ):
            if x0 <= 0 or y0 <= 0 or x1 >= w or y1 >= h:
                continue  # cut by the picture's side: its edges may be the picture's
            lean = edge_lean(rgb, (x0, y0, x1, y1), self.config)
            if lean is not None:
                self._leans.append((int(vehicle), lean))
        return self.roll_deg

    @property
    def full(self) -> bool:
        """Whether it holds as many leans as it keeps: enough to have found a turn, so a
        picture they did not find turned may be taken as level."""
        return len(self._leans) == self._leans.maxlen

    @property
    def readings(self) -> int:
        """How many boxes gave a lean."""
        return len(self._leans)

    @property
    def roll_deg(self) -> float | None:
        """The picture's turn in degrees anticlockwise (the `--roll` that levels it), rounded
        to a tenth; None while too few leans are in, they disagree, or they say level."""
        c = self.config
        if len(self._leans) < c.least:
            return None
        ids, leans = (np.asarray(values) for values in zip(*self._leans, strict=True))
        q1, median, q3 = np.quantile(leans, [0.25, 0.5, 0.75])
        # Leans that scatter (a coarse picture's small cars) are not taken, however many: LA's
        # level picture would read a turn of 1.6 degrees (README).
        if q3 - q1 > c.max_spread_deg or not c.min_roll_deg <= abs(median) <= c.max_roll_deg:
            return None
        own = [
            float(np.median(leans[ids == vehicle]))
            for vehicle in np.unique(ids)
            if np.count_nonzero(ids == vehicle) >= c.vehicle_leans
        ]
        agree = sum(abs(lean - median) <= c.max_spread_deg for lean in own)
        if agree < c.vehicles or 2 * agree <= len(own):
            return None
        return round(float(median), 1)
