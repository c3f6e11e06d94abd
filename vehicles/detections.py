"""`Detections`, the value passed between the detector's stages, and overlaps of boxes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class Detections:
    """Boxes [x1, y1, x2, y2] in frame pixels, a score per box, and track ids (-1: none yet)."""

    boxes: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4)))
    scores: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))

    def __post_init__(self) -> None:
        if self.boxes.shape != (len(self.scores), 4) or len(self.ids) != len(self.scores):
            raise ValueError("boxes, scores and ids must describe the same detections")

    @classmethod
    def from_boxes(
        cls,
        boxes: NDArray[np.floating[Any]],
        scores: NDArray[np.floating[Any]],
        ids: NDArray[np.integer[Any]] | None = None,
    ) -> Detections:
        """Detections from array-likes (ids default to -1)."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        s = np.asarray(scores, dtype=np.float64).reshape(-1)
        i = np.full(len(s), -1, np.int64) if ids is None else np.asarray(ids, np.int64)
        return cls(b, s, i)

    def __len__(self) -> int:
        return len(self.scores)

    def subset(self, keep: NDArray[np.bool_]) -> Detections:
        """The detections where `keep` is true."""
        return Detections(self.boxes[keep], self.scores[keep], self.ids[keep])

    def clipped(self, region: tuple[float, float, float, float]) -> Detections:
        """The same detections with boxes cut to `region` (x0, y0, x1, y1: the frame, or the
        live picture inside black bars)."""
        x0, y0, x1, y1 = region
        boxes = np.clip(self.boxes, [x0, y0, x0, y0], [x1, y1, x1, y1])
        return Detections(boxes, self.scores, self.ids)


def _intersection(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pairwise intersection areas of two sets of [x1, y1, x2, y2] boxes: (len(a), len(b))."""
    ix = np.clip(
        np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None
    )
    iy = np.clip(
        np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None
    )
    return np.asarray(ix * iy)


def box_areas(boxes: NDArray[np.float64]) -> NDArray[np.float64]:
    """The area of each [x1, y1, x2, y2] box."""
    return np.asarray((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))


def iou_matrix(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pairwise IoU of two sets of [x1, y1, x2, y2] boxes."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    inter = _intersection(a, b)
    union = box_areas(a)[:, None] + box_areas(b)[None, :] - inter
    return np.asarray(inter / np.maximum(union, 1e-9))


def overlap_of_smaller(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pairwise intersection of two sets of boxes over the smaller box's area: 1 where one lies
    wholly inside the other, whatever their sizes."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    smaller = np.minimum(box_areas(a)[:, None], box_areas(b)[None, :])
    return np.asarray(_intersection(a, b) / np.maximum(smaller, 1e-9))


def inside_share(
    boxes: NDArray[np.float64], region: tuple[float, float, float, float]
) -> NDArray[np.float64]:
    """Share of each box's area that lies inside `region` (x0, y0, x1, y1)."""
    frame = np.array([region], np.float64)
    return np.asarray(_intersection(boxes, frame)[:, 0] / np.maximum(box_areas(boxes), 1e-9))


def cut_edges(
    boxes: NDArray[np.float64],
    region: tuple[float, float, float, float] | None,
    margin: float = 1.0,
) -> NDArray[np.bool_]:
    """Which edges (x1, y1, x2, y2) of each box lie on `region`'s edge (within `margin` px): a
    vehicle cut there reaches past it, so the box's edge is not the vehicle's."""
    if region is None:
        return np.zeros(boxes.shape, bool)
    x0, y0, x1, y1 = region
    return np.column_stack(
        [
            boxes[:, 0] <= x0 + margin,
            boxes[:, 1] <= y0 + margin,
            boxes[:, 2] >= x1 - margin,
            boxes[:, 3] >= y1 - margin,
        ]
    )


def covered_share(
    boxes: NDArray[np.float64], hidden: tuple[tuple[int, int, int, int], ...]
) -> NDArray[np.float64]:
    """The share of each box that the `hidden` boxes cover (they are taken not to overlap each
    other)."""
    if not hidden or len(boxes) == 0:
        return np.zeros(len(boxes))
    inside = _intersection(boxes, np.asarray(hidden, np.float64)).sum(axis=1)
    return np.asarray(np.minimum(inside / np.maximum(box_areas(boxes), 1e-9), 1.0))


def smaller_sides(boxes: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each box's width or height, whichever is less."""
    return np.asarray(np.minimum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]))
