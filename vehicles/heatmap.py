"""`Heatmap`: window hits accumulated over recent frames, thresholded and labelled into boxes."""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np
from numpy.typing import NDArray

from vehicles.config import HeatConfig


def label_regions(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int32], list[tuple[slice, slice]]]:
    """4-connected regions of a mask: labels 1..n in raster order of their first pixel, and each
    region's bounding box as (rows, columns) slices, as `scipy.ndimage.label` and `find_objects`
    give them (OpenCV's labelling is as exact and spares the frame path scipy's import)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=4, ltype=cv2.CV_32S
    )
    windows = [
        (slice(int(y), int(y + h)), slice(int(x), int(x + w))) for x, y, w, h in stats[1:n, :4]
    ]
    return np.asarray(labels, np.int32), windows


def mean_filter(image: NDArray[np.float32], size: int) -> NDArray[np.float32]:
    """Mean over size x size neighbourhoods, borders mirrored (scipy's 'reflect')."""
    return np.asarray(cv2.blur(image, (size, size), borderType=cv2.BORDER_REFLECT), np.float32)


def max_filter(image: NDArray[np.float32], size: int) -> NDArray[np.float32]:
    """Maximum over size x size neighbourhoods (mirrored borders add no new values)."""
    kernel = np.ones((size, size), np.uint8)
    return np.asarray(cv2.dilate(image, kernel, borderType=cv2.BORDER_REFLECT), np.float32)


def box_heat(
    shape: tuple[int, int], boxes: NDArray[np.float64], weights: NDArray[np.float64], scale: int
) -> NDArray[np.float32]:
    """Sum of `weights` over each box, on a grid 1/scale of the frame (vectorised via corners)."""
    h, w = shape
    corners = np.zeros((h + 1, w + 1), np.float64)
    if len(boxes):
        b = np.round(boxes / scale).astype(np.intp)
        x1, y1 = np.clip(b[:, 0], 0, w), np.clip(b[:, 1], 0, h)
        x2, y2 = np.clip(b[:, 2], 0, w), np.clip(b[:, 3], 0, h)
        np.add.at(corners, (y1, x1), weights)
        np.add.at(corners, (y1, x2), -weights)
        np.add.at(corners, (y2, x1), -weights)
        np.add.at(corners, (y2, x2), weights)
    return corners.cumsum(0).cumsum(1)[:h, :w].astype(np.float32)


def split_peaks(
    heat: NDArray[np.float32], region: NDArray[np.bool_], valley: float
) -> list[NDArray[np.bool_]]:
    """Split a region into one part per heat peak when the peaks are separated by a clear valley."""
    # Smoothed heat, and only peaks reaching half the strongest: plateau bumps are not vehicles.
    local = mean_filter(np.asarray(heat * region, np.float32), 3) * region
    peaks = (local == max_filter(local, 5)) & region
    peaks &= local >= 0.5 * local.max()
    labels, windows = label_regions(peaks)
    n = len(windows)
    if n < 2:
        return [region]
    # Peak plateaus are tiny: their pixel coordinates give centre and value without a full sort.
    ys, xs = np.nonzero(labels)
    ids = labels[ys, xs] - 1
    counts = np.bincount(ids, minlength=n)
    centres = np.stack([np.bincount(ids, ys, n) / counts, np.bincount(ids, xs, n) / counts], 1)
    values = np.zeros(n)
    np.maximum.at(values, ids, local[ys, xs])
    order = np.argsort(values)[::-1]
    keep = [order[0]]
    for k in order[1:]:
        # A second peak counts when the heat between it and every kept peak dips low enough.
        ok = True
        for j in keep:
            line = np.linspace(centres[k], centres[j], 20).round().astype(int)
            dip = local[line[:, 0], line[:, 1]].min()
            if dip > valley * min(values[k], values[j]):
                ok = False
                break
        if ok:
            keep.append(k)
    if len(keep) < 2:
        return [region]
    # Each pixel of the region goes to the nearest kept peak (vectorised distance).
    ys, xs = np.nonzero(region)
    d = (ys[:, None] - centres[keep, 0]) ** 2 + (xs[:, None] - centres[keep, 1]) ** 2
    owner = np.argmin(d, axis=1)
    parts = []
    for i in range(len(keep)):
        part = np.zeros_like(region)
        part[ys[owner == i], xs[owner == i]] = True
        parts.append(part)
    return parts


class Heatmap:
    """The last `history` frames of heat.

    Their mean says where vehicles persist (a one-frame alarm never reaches the threshold); the
    last `recent` frames say where each one is now, so a vehicle moving across the image gets a
    box at its position, not along its trail.
    """

    def __init__(self, config: HeatConfig) -> None:
        self.config = config
        self.frames: deque[NDArray[np.float32]] = deque(maxlen=config.history)
        self.recent = max(1, min(config.recent, config.history))

    def reset(self) -> None:
        """Forget all frames."""
        self.frames.clear()

    def add(
        self, frame_size: tuple[int, int], boxes: NDArray[np.float64], weights: NDArray[np.float64]
    ) -> NDArray[np.float32]:
        """Add one frame's weighted boxes; returns this frame's heat."""
        w, h = frame_size
        scale = self.config.scale
        shape = (-(-h // scale), -(-w // scale))
        if self.frames and self.frames[-1].shape != shape:
            self.frames.clear()
        heat = box_heat(shape, boxes, weights, scale)
        self.frames.append(heat)
        return heat

    def _mean(self, count: int) -> NDArray[np.float32]:
        """Mean heat per frame over the newest `count` frames (missing frames count as zero)."""
        if not self.frames:
            return np.zeros((1, 1), np.float32)
        newest = list(self.frames)[-count:]
        return np.asarray(np.sum(np.stack(newest), axis=0) / count, dtype=np.float32)

    @property
    def combined(self) -> NDArray[np.float32]:
        """Mean heat per frame over the history (filled up to `history` frames)."""
        return self._mean(self.frames.maxlen or 1)

    @property
    def current(self) -> NDArray[np.float32]:
        """Mean heat per frame over the recent frames."""
        return self._mean(self.recent)

    def regions(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Boxes (frame pixels) and peak heat of the vehicles seen now where heat persists.

        Recent heat is labelled, split at clear valleys between peaks, and each part is kept when it
        touches the thresholded history; its box covers its recent heat above `peak_fraction` of
        its peak, tighter than the union of square windows. A region touching the frame's
        left or right side takes its horizontal extent at `edge_fraction` of its peak instead:
        windows reaching past the side see the vehicle and its mirror image, so heat piles up at
        the side and the vehicle's inner part falls below the usual fraction.
        """
        cfg = self.config
        persistent = self.combined > cfg.threshold
        heat = self.current
        labels, windows = label_regions(heat > cfg.recent_threshold)
        boxes, peaks = [], []
        for index, window in enumerate(windows, start=1):
            # Work inside the region's bounding box (a few hundred pixels, not the whole map).
            local_heat, local_persistent = heat[window], persistent[window]
            region = labels[window] == index
            if not local_persistent[region].any():
                continue
            for part in split_peaks(local_heat, region, cfg.split_valley):
                if not local_persistent[part].any():
                    continue
                peak = float(local_heat[part].max())
                core = part & (local_heat >= max(cfg.recent_threshold, cfg.peak_fraction * peak))
                ys, xs = np.nonzero(core)
                at_side = (window[1].start == 0 and bool(part[:, 0].any())) or (
                    window[1].stop == heat.shape[1] and bool(part[:, -1].any())
                )
                if cfg.edge_peak_fraction is not None and at_side:
                    edge = max(cfg.recent_threshold, cfg.edge_peak_fraction * peak)
                    wide = part & (local_heat >= edge)
                    xs = np.nonzero(wide)[1]
                y0, x0 = window[0].start, window[1].start
                boxes.append([x0 + xs.min(), y0 + ys.min(), x0 + xs.max() + 1, y0 + ys.max() + 1])
                peaks.append(peak)
        out = np.asarray(boxes, dtype=np.float64).reshape(-1, 4) * cfg.scale
        return out, np.asarray(peaks, dtype=np.float64)
