"""Hard negatives: the windows a detector is sure of in footage without vehicles, cut out as
training patches, so that what fooled it (dark road, shade, glare, paint) is learned as road."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


def window_patches(
    frame: NDArray[np.uint8], boxes: NDArray[np.float64], size: int = 64
) -> NDArray[np.uint8]:
    """The square windows `boxes` (x0, y0, x1, y1) of `frame` resized to `size` x `size`; windows
    reaching past the frame are mirrored there, as the band search does."""
    h, w = frame.shape[:2]
    out = np.empty((len(boxes), size, size, 3), np.uint8)
    for k, box in enumerate(np.round(boxes).astype(int)):
        x0, y0, x1, y1 = box
        pad = (max(0, -y0), max(0, y1 - h), max(0, -x0), max(0, x1 - w))
        crop = frame[max(0, y0) : min(h, y1), max(0, x0) : min(w, x1)]
        if any(pad):
            crop = cv2.copyMakeBorder(crop, *pad, cv2.BORDER_REFLECT)
        shrink = crop.shape[0] > size
        interpolation = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
        out[k] = cv2.resize(crop, (size, size), interpolation=interpolation)
    return out


def surest_apart(
    boxes: NDArray[np.float64],
    scores: NDArray[np.float64],
    min_score: float,
    limit: int,
    max_overlap: float = 0.3,
) -> NDArray[np.intp]:
    """Indices of at most `limit` windows scoring at least `min_score`, surest first, none
    overlapping a surer one by more than `max_overlap` IoU: one false alarm's many neighbouring
    windows give one patch, and every false alarm in the frame gets its turn."""
    if len(boxes) == 0:
        return np.zeros(0, np.intp)
    xywh = np.column_stack([boxes[:, :2], boxes[:, 2:] - boxes[:, :2]]).tolist()
    keep = cv2.dnn.NMSBoxes(xywh, scores.tolist(), min_score, max_overlap, top_k=limit)
    return np.asarray(keep, np.intp).reshape(-1)[:limit]
