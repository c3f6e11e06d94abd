"""What stays fixed in the picture while the road streams past: burnt-in timestamps, logos and
watermarks, glare fixed on the windscreen, and parts of one's own car (a mirror, a pillar).

Captions are read off the frames as the edges that stay on the same pixel: an overlay's letters
keep their edges in place in every frame, the road's edges move (a lane line beside the camera
wobbles by a pixel or two; a bonnet's edge is a long thin line, not a dense patch). A part of the
car is a still patch reaching in from the picture's side and outlined by such steady
edges (a smooth road is still too, but its outline, the lane lines, moves). Their boxes are kept
out of the stages' work: no window is heated where the picture shows them rather than the road.
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


def fixed_part_boxes(
    change: NDArray[np.float64],
    persistence: NDArray[np.float64],
    top: int = 0,
    inside: Box | None = None,
    still_ratio: float = 0.2,
    min_area: float = 0.005,
    min_outline: float = 0.15,
    strip: float = 0.05,
    known: NDArray[np.bool_] | None = None,
    keep_ratio: float = 0.75,
) -> tuple[Box, ...]:
    """Boxes over the parts of one's own car in the picture (a mirror, a pillar, the dashboard)
    from `change`, each pixel's mean change between samples, and `persistence`, how often it was
    an edge (0-1): patches below row `top` that change less than `still_ratio` of the typical
    pixel there, reach the picture's left or right side (a bonnet is found on its own), cover
    `min_area` of it, and whose outline lies along steady edges (persistence >= 0.8) for
    `min_outline` of its length (a smooth road's patch between moving lane lines has about
    none). Each patch is given as a stack of boxes `strip` of the height tall, so a slanted
    pillar does not hide the road beside it. `inside` (the picture within black bars) is where
    it looks, and whose sides count (a still black bar is no part of the car). Pixels of parts
    found before (`known`) stay still while they change less than `keep_ratio` of the typical
    pixel: a mirror reflects the moving scene a little, and a part of the car does not leave."""
    ox, oy, ex, ey = inside if inside is not None else (0, 0, change.shape[1], change.shape[0])
    change, persistence = change[oy:ey, ox:ex], persistence[oy:ey, ox:ex]
    h, w = change.shape
    if h < 2 or w < 2:
        return ()
    top = min(max(0, top - oy), h - 1)
    reference = float(np.median(change[top:]))
    if reference <= 0:
        return ()
    still = change < still_ratio * reference
    if known is not None:
        still |= known[oy:ey, ox:ex] & (change < keep_ratio * reference)
    still = np.asarray(still, np.uint8)
    still[:top] = 0
    still = cv2.morphologyEx(still, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(still, connectivity=8)
    steady = cv2.dilate(np.asarray(persistence >= 0.8, np.uint8), np.ones((5, 5), np.uint8)) > 0
    ring_kernel = np.ones((3, 3), np.uint8)
    tall = max(1, round(strip * h))
    boxes: list[Box] = []
    for i in range(1, count):
        x, y, bw, bh, area = (int(v) for v in stats[i])
        if area < min_area * h * w or not (x == 0 or x + bw == w):
            continue
        whole = np.asarray(labels == i, np.uint8)
        # Its outline: the pixels around it, but above `top` (where it was cut off, not seen).
        ring = (cv2.dilate(whole, ring_kernel) > 0) & (whole == 0)
        ring[:top] = False
        outline = int(ring.sum())
        if not outline or (ring & steady).sum() < min_outline * outline:
            continue
        part = whole[y : y + bh, x : x + bw]
        rows = np.flatnonzero(part.any(axis=1))
        for start in range(int(rows[0]), int(rows[-1]) + 1, tall):
            cols = np.flatnonzero(part[start : start + tall].any(axis=0))
            if len(cols):
                x0, y0 = ox + x + int(cols[0]), oy + y + start
                boxes.append((x0, y0, ox + x + int(cols[-1]) + 1, oy + y + min(bh, start + tall)))
    return tuple(boxes)


class OverlayTracker:
    """History for the overlays: how often each pixel was an edge, and how much it changed from
    one sample to the next, over frames sampled while the picture changes (a car standing still
    would keep every edge and pixel in place).

    Captions are found once `min_samples` samples are in (a few seconds of driving), and again
    each `every` samples after; parts of the car, a still patch outlined by steady edges, from
    `part_samples` on, every `part_every` (a mirror is boxed as a car until found). `still` is
    the share of a sample's edges that were edges in the previous sample too above which the
    sample is skipped (moving: 0.1-0.6). A part once found is kept while it changes less than
    three quarters as much as the typical pixel (`fixed_part_boxes`'s `keep_ratio`), so it does
    not come and go as its reflections or shade change.
    """

    def __init__(
        self,
        size: tuple[int, int],
        min_samples: int = 24,
        every: int = 10,
        still: float = 0.85,
        part_samples: int = 12,
        part_every: int = 5,
    ) -> None:
        self.size = size  # (width, height) of the sampled pictures
        self.min_samples = min_samples
        self.every = every
        self.part_samples = part_samples
        self.part_every = part_every
        self.still = still
        self._counts = np.zeros((size[1], size[0]), np.uint16)
        self._previous: NDArray[np.bool_] | None = None
        self._change = np.zeros((size[1], size[0]), np.float32)
        self._last: NDArray[np.uint8] | None = None  # the last sample taken in
        self.samples = 0
        self._captions: tuple[Box, ...] = ()
        self._parts: tuple[Box, ...] = ()
        self._part_mask = np.zeros((size[1], size[0]), bool)  # where the parts found last are

    @property
    def boxes(self) -> tuple[Box, ...]:
        """The captions' and the car's parts' boxes as of the last sample."""
        return self._captions + self._parts

    def update(
        self, grey: NDArray[np.uint8], top: int = 0, inside: Box | None = None
    ) -> tuple[Box, ...]:
        """Take in one sample (a grey picture of `size`); the overlays' boxes as of it (parts of
        the car are looked for below row `top`, the horizon: the sky is still too, and within
        `inside`, the picture inside black bars)."""
        edges = edge_map(grey)
        previous, self._previous = self._previous, edges
        if previous is not None and (edges & previous).sum() > self.still * max(1, edges.sum()):
            return self.boxes
        if self.samples < np.iinfo(np.uint16).max:
            self._counts += edges
            if self._last is not None:
                self._change += cv2.absdiff(grey, self._last)
            self._last = grey
            self.samples += 1
        n = self.samples
        if n >= self.min_samples and (n - self.min_samples) % self.every == 0:
            self._captions = overlay_boxes(self._counts / n)
        if n >= self.part_samples and (n - self.part_samples) % self.part_every == 0:
            self._parts = fixed_part_boxes(
                self._change / (n - 1), self._counts / n, top, inside, known=self._part_mask
            )
            self._part_mask[:] = False
            for x0, y0, x1, y1 in self._parts:
                self._part_mask[y0:y1, x0:x1] = True
        return self.boxes
