"""Burnt-in overlays: timestamps, logos and watermarks drawn onto the picture, and glare fixed
on the windscreen.

They are read off the frames as the edges that stay on the same pixel while the road streams
past: an overlay's letters keep their edges in place in every frame, the road's edges move (a
lane line beside the camera wobbles by a pixel or two; a bonnet's edge is a long thin line, not
a dense patch). Their boxes are kept out of the stages' work: no lane paint is read and no
window is heated where the picture shows a caption rather than the road.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 (x1, y1 exclusive)


def edge_map(grey: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """The picture's edges (Canny at thresholds low enough for a half-transparent watermark)."""
    return np.asarray(cv2.Canny(cv2.GaussianBlur(grey, (3, 3), 0), 30, 90) > 0)


def overlay_boxes(
    persistence: NDArray[np.float64],
    min_share: float = 0.8,
    min_density: float = 0.1,
    min_height: float = 0.015,
    max_height: float = 0.25,
    min_pixels: float = 0.0005,
) -> tuple[Box, ...]:
    """Boxes of the overlays in a map of how often each pixel was an edge (0-1): the pixels
    that were in `min_share` of the samples, grouped by a closing 3 % of the picture's width
    and 2 % of its height (a word's letters, a caption's words and lines),
    kept where a group's box is dense with them (`min_density`: letters, not a long thin
    line), between `min_height` and `max_height` of the picture tall, and holds at least
    `min_pixels` of the picture's pixels."""
    h, w = persistence.shape
    steady = np.asarray(persistence >= min_share, np.uint8)
    kernel = cv2.getStructuringElement(
        cv2.MORPH_RECT, (max(3, round(0.03 * w)), max(3, round(0.02 * h)))
    )
    groups = cv2.morphologyEx(steady, cv2.MORPH_CLOSE, kernel)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(groups, connectivity=8)
    if count <= 1:
        return ()
    # Steady pixels per group, counted at once over every group.
    pixels = np.bincount(labels[steady > 0], minlength=count)
    x, y, bw, bh = (stats[:, i] for i in range(4))
    keep = (
        (pixels >= min_density * bw * bh)
        & (bh >= min_height * h)
        & (bh <= max_height * h)
        & (pixels >= min_pixels * h * w)
    )
    keep[0] = False  # the background
    # A pixel's margin: the edges sit on the letters' outlines, the letters' halo beyond them.
    pad = max(1, round(0.005 * h))
    return tuple(
        (
            int(max(0, x[i] - pad)),
            int(max(0, y[i] - pad)),
            int(min(w, x[i] + bw[i] + pad)),
            int(min(h, y[i] + bh[i] + pad)),
        )
        for i in np.flatnonzero(keep)
    )


class OverlayTracker:
    """History for the overlays: how often each pixel was an edge, over frames sampled while
    the picture changes (a car standing still would keep every edge in place).

    Boxes are found once `min_samples` samples are in (a few seconds of driving), and again
    each `every` samples after; `still` is the share of a sample's edges that were edges in the
    previous sample too above which the sample is skipped (moving: 0.1-0.6).
    """

    def __init__(
        self,
        size: tuple[int, int],
        min_samples: int = 24,
        every: int = 10,
        still: float = 0.85,
    ) -> None:
        self.size = size  # (width, height) of the sampled pictures
        self.min_samples = min_samples
        self.every = every
        self.still = still
        self._counts = np.zeros((size[1], size[0]), np.uint16)
        self._previous: NDArray[np.bool_] | None = None
        self.samples = 0
        self.boxes: tuple[Box, ...] = ()

    def update(self, grey: NDArray[np.uint8]) -> tuple[Box, ...]:
        """Take in one sample (a grey picture of `size`); the overlays' boxes as of it."""
        edges = edge_map(grey)
        previous, self._previous = self._previous, edges
        if previous is not None and (edges & previous).sum() > self.still * max(1, edges.sum()):
            return self.boxes
        if self.samples < np.iinfo(np.uint16).max:
            self._counts += edges
            self.samples += 1
        if self.samples >= self.min_samples and (self.samples - self.min_samples) % self.every == 0:
            self.boxes = overlay_boxes(self._counts / self.samples)
        return self.boxes
