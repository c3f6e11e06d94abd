"""A small multi-object tracker: stable integer ids, smoothed boxes, confirm and drop rules."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from vehicles.detections import Detections, iou_matrix


@dataclass
class Track:
    """One tracked vehicle."""

    id: int
    box: NDArray[np.float64]
    score: float
    hits: int = 1
    missed: int = 0


class Tracker:
    """Associates each frame's boxes with tracks by IoU (optimal assignment)."""

    def __init__(
        self,
        match_iou: float,
        smoothing: float,
        confirm_frames: int,
        max_missed: int,
        show_missed: int,
    ) -> None:
        self.match_iou = match_iou
        self.smoothing = smoothing
        self.confirm_frames = confirm_frames
        self.max_missed = max_missed
        self.show_missed = show_missed
        self.tracks: list[Track] = []
        self._next_id = 1

    def reset(self) -> None:
        """Forget every track (ids start again at 1)."""
        self.tracks = []
        self._next_id = 1

    def update(self, detections: Detections) -> Detections:
        """Fold in one frame's detections; return the confirmed, shown tracks."""
        boxes = detections.boxes
        previous = np.array([t.box for t in self.tracks]).reshape(-1, 4)
        iou = iou_matrix(previous, boxes)
        matched_tracks: set[int] = set()
        matched_dets: set[int] = set()
        if iou.size:
            rows, cols = linear_sum_assignment(-iou)
            for r, c in zip(rows, cols, strict=True):
                if iou[r, c] >= self.match_iou:
                    track = self.tracks[r]
                    a = self.smoothing
                    track.box = a * boxes[c] + (1 - a) * track.box
                    track.score = a * float(detections.scores[c]) + (1 - a) * track.score
                    track.hits += 1
                    track.missed = 0
                    matched_tracks.add(r)
                    matched_dets.add(c)
        for r, track in enumerate(self.tracks):
            if r not in matched_tracks:
                track.missed += 1
        self.tracks = [t for t in self.tracks if t.missed <= self.max_missed]
        for c in range(len(boxes)):
            if c not in matched_dets:
                self.tracks.append(
                    Track(self._next_id, boxes[c].copy(), float(detections.scores[c]))
                )
                self._next_id += 1
        shown = [
            t for t in self.tracks if t.hits >= self.confirm_frames and t.missed <= self.show_missed
        ]
        return Detections.from_boxes(
            np.array([t.box for t in shown]).reshape(-1, 4),
            np.array([t.score for t in shown]),
            np.array([t.id for t in shown], dtype=np.int64),
        )
