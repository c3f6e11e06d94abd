"""A small multi-object tracker: stable integer ids, smoothed boxes, confirm and drop rules.

Each track follows its box with an alpha-beta filter (constant velocity per box edge): matching
uses the box predicted for this frame, so a car crossing the image quickly keeps its id and its
shown box does not trail behind it. A shown vehicle lost for longer than a track coasts (glare,
another car in front, the classifier unsure for a while) keeps its id when it is found again
where it would have driven.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from vehicles.assignment import linear_sum_assignment
from vehicles.config import TrackConfig
from vehicles.detections import (
    Detections,
    box_areas,
    cut_edges,
    inside_share,
    iou_matrix,
    overlap_of_smaller,
)


@dataclass
class Track:
    """One tracked vehicle: box and per-frame velocity of its edges (x1, y1, x2, y2); `id` is 0
    until the track is first shown; `cut`: which edges its last box had at the picture's edge
    (the vehicle reaches past them, so they were not seen)."""

    box: NDArray[np.float64]
    score: float
    velocity: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    hits: int = 1
    missed: int = 0
    id: int = 0
    cut: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(4, bool))
    # The box and edge velocity when it was last measured (`missed` frames ago).
    seen: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    seen_velocity: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    forget: int = 0  # once lost (see `Tracker._rejoin`): kept until unseen this many frames

    def predicted(self) -> NDArray[np.float64]:
        """The box expected in the next frame."""
        return self.box + self.velocity

    def expected(self, reach: float = 1.0) -> NDArray[np.float64]:
        """Where the vehicle would be now, `missed` frames after it was last measured: the box
        then, moved on by `reach` times its centre's velocity. Its size stays as measured: over
        many frames the edges' own velocities, which heat gathering or thinning moves too,
        spread a coasting box wider than the vehicle (LA's SUV, 114 px against 88 after 10
        frames)."""
        centre = (self.seen_velocity[:2] + self.seen_velocity[2:]) / 2
        return self.seen + np.tile(centre, 2) * self.missed * reach


class Tracker:
    """Associates each frame's boxes with predicted tracks by IoU (optimal assignment)."""

    def __init__(self, config: TrackConfig, lag: float = 0.0) -> None:
        self.config = config
        self.lag = lag
        self.tracks: list[Track] = []
        # Shown tracks dropped unseen in the picture, kept for their ids (see `_rejoin`).
        self.lost: list[Track] = []
        self._next_id = 1

    def reset(self) -> None:
        """Forget every track (ids start again at 1)."""
        self.tracks = []
        self.lost = []
        self._next_id = 1

    def measured_velocities(self, ids: NDArray[np.int64]) -> NDArray[np.float64]:
        """The per-frame velocity of the edges (x1, y1, x2, y2) of the shown tracks `ids` that
        were measured in this frame; 0 for one coasting on its prediction."""
        by_id = {t.id: t.velocity * (t.missed == 0) for t in self.tracks if t.id}
        return np.array([by_id[i] for i in ids.tolist()], np.float64).reshape(-1, 4)

    def update(
        self,
        detections: Detections,
        region: tuple[float, float, float, float] | None = None,
        horizon_y: float | None = None,
    ) -> Detections:
        """Fold in one frame's detections; return the confirmed, shown tracks.

        A measured box is taken to show the vehicle `lag` frames ago (heat averaged over recent
        frames), so it is moved on by `lag` times the track's velocity before it corrects the track.
        Ids count shown vehicles only (1, 2, 3, ...): a candidate never confirmed uses none. With
        `region` (the frame or its live picture, x0, y0, x1, y1), a track whose predicted box has
        left it (less than `min_inside` of it inside) is dropped at once instead of lingering.
        With `horizon_y`, a receding track's velocity slows between frames as a vehicle's on a
        flat road does (`road_velocity`). An edge that was cut by `region`'s edge (`cut_edges`) and
        is seen now, as a vehicle comes into the picture (`entering_sides`), is placed where it
        is seen, at the opposite edge's velocity: its jump out of the picture's edge is where the
        vehicle's side is, not its motion. A track shown for the first time takes the id of a
        vehicle lost a moment ago that could be where it is (`_rejoin`).
        """
        cfg = self.config
        boxes = detections.boxes
        predicted = np.array([t.predicted() for t in self.tracks]).reshape(-1, 4)
        iou = iou_matrix(predicted, boxes)
        matched: dict[int, int] = {}
        if iou.size:
            rows, cols = linear_sum_assignment(-iou)
            matched = {r: c for r, c in zip(rows, cols, strict=True) if iou[r, c] >= cfg.match_iou}
        a, b = cfg.smoothing, cfg.velocity_gain
        cut = cut_edges(boxes, region)
        for r, track in enumerate(self.tracks):
            onward = track.velocity
            if horizon_y is not None:
                onward = road_velocity(track.box, track.velocity, horizon_y)
            if r in matched:
                c = matched[r]
                measured = boxes[c] + self.lag * track.velocity
                innovation = measured - predicted[r]
                track.box = predicted[r] + a * innovation
                track.velocity = onward + b * innovation
                entering = entering_sides(
                    track.cut & ~cut[c], innovation, track.velocity, cfg.entering_frames
                )
                track.box[entering] = measured[entering]
                track.velocity[entering] = track.velocity[_OPPOSITE][entering]
                track.cut = cut[c]
                track.score = a * float(detections.scores[c]) + (1 - a) * track.score
                track.hits += 1
                track.missed = 0
                track.seen, track.seen_velocity = track.box.copy(), track.velocity.copy()
            else:
                track.box = predicted[r]  # coast on
                track.velocity = onward
                track.missed += 1
        for lost in self.lost:
            lost.missed += 1
        self.lost = [t for t in self.lost if t.missed <= t.forget]
        inside = [True] * len(self.tracks)
        if region is not None and self.tracks:
            share = inside_share(np.array([t.box for t in self.tracks]), region)
            inside = [s >= cfg.min_inside for s in share]
        kept = []
        for track, within in zip(self.tracks, inside, strict=True):
            if within and track.missed <= cfg.max_missed:
                kept.append(track)
            elif track.id:
                self._remember(track, region)
        self.tracks = kept
        for c in sorted(set(range(len(boxes))) - set(matched.values())):
            box = boxes[c].copy()
            self.tracks.append(Track(box, float(detections.scores[c]), cut=cut[c], seen=box.copy()))
        for track in list(self.tracks):  # `_rejoin` may drop a coasting twin from the list
            if track.id == 0 and self._showing(track):
                track.id = self._rejoin(track)
        shown = [t for t in self.tracks if self._showing(t)]
        return Detections.from_boxes(
            np.array([t.box for t in shown]).reshape(-1, 4),
            np.array([t.score for t in shown]),
            np.array([t.id for t in shown], dtype=np.int64),
        )

    def _showing(self, track: Track) -> bool:
        """Whether `track` is shown: confirmed, and not unseen for long."""
        cfg = self.config
        return track.hits >= cfg.confirm_frames and track.missed <= cfg.show_missed

    def _remember(self, track: Track, region: tuple[float, float, float, float] | None) -> None:
        """Keep a shown track being dropped for its id (see `_rejoin`): unseen, or its box past
        the picture's edge, but where it would be by its last motion is in the picture, for
        `forget_missed` frames; still shown, its box run past the picture's side by a velocity
        read off boxes the side cuts, which jitter (an SUV beside us), as long as a track
        coasts, in which a vehicle gone is not replaced there by another. Else forgotten."""
        cfg = self.config
        expected = track.expected()[None]
        if region is None or inside_share(expected, region)[0] >= cfg.min_inside:
            track.forget = cfg.forget_missed
        elif track.missed <= cfg.show_missed:
            track.forget = cfg.max_missed
        else:
            return
        self.lost.append(track)

    def remembered(self) -> Detections:
        """The vehicles lost and kept for their ids, at the boxes where they would be now (each
        last measured box moved on by its centre's motion; see `_rejoin`)."""
        return Detections.from_boxes(
            np.array([t.expected() for t in self.lost]).reshape(-1, 4),
            np.array([t.score for t in self.lost]),
            np.array([t.id for t in self.lost], dtype=np.int64),
        )

    def _rejoin(self, track: Track) -> int:
        """The id for `track`, shown for the first time: that of a vehicle lost or coasting
        unseen (`forget_missed` frames at most) that could now be where `track` is, the one
        overlapping most; else a new one. It could be anywhere along its last motion, from
        where it was last seen (a partial box's jump can read as motion) to `rejoin_reach`
        times as far as that motion takes it (a car we pass speeds up across the picture as it
        nears): a box there and `track`'s overlap by `rejoin_overlap` of the smaller one (a box
        on a part of a car is that car), their areas within `rejoin_area` times each other."""
        cfg = self.config
        unseen = [t for t in self.tracks if t.id and t.missed] + self.lost
        if unseen:
            reach = np.linspace(0.0, cfg.rejoin_reach, 9)
            along = np.array([[t.expected(k) for k in reach] for t in unseen]).reshape(-1, 4)
            overlap = overlap_of_smaller(along, track.box[None]).reshape(len(unseen), -1)
            area = box_areas(np.array([t.seen for t in unseen])) / box_areas(track.box[None])
            sized = (area <= cfg.rejoin_area) & (area >= 1 / cfg.rejoin_area)
            overlap = overlap.max(axis=1) * sized
            best = int(np.argmax(overlap))
            if overlap[best] >= cfg.rejoin_overlap:
                found = unseen[best]
                self.tracks = [t for t in self.tracks if t is not found]
                self.lost = [t for t in self.lost if t is not found]
                return found.id
        self._next_id += 1
        return self._next_id - 1


_OPPOSITE = np.array([2, 3, 0, 1])  # x1 <-> x2, y1 <-> y2
_INWARD = np.array([1.0, 1.0, -1.0, -1.0])  # away from each edge's side of the picture


def entering_sides(
    appeared: NDArray[np.bool_],
    jump: NDArray[np.float64],
    velocity: NDArray[np.float64],
    frames: float,
) -> NDArray[np.bool_]:
    """Which edges that `appeared` from the picture's edge (x1, y1, x2, y2) are a vehicle's side
    coming into the picture: its opposite edge moves away from that side (`velocity`), fast
    enough to have brought the side in within `frames` frames (the edge's `jump` from where it
    was predicted). A jump that its motion cannot explain is the heat falling short of a
    vehicle still cut by the edge."""
    inward = velocity[_OPPOSITE] * _INWARD
    return np.asarray(appeared & (inward > 0) & (np.abs(jump) <= frames * inward))


def road_velocity(
    box: NDArray[np.float64],
    velocity: NDArray[np.float64],
    horizon_y: float,
    least_offset: float = 4.0,
    largest_step: float = 1.5,
) -> NDArray[np.float64]:
    """The velocity of a receding vehicle's box in the next frame, once it moved on by `velocity`.

    On a flat road a box's size and its edges' offsets from the vanishing point go as one over
    the vehicle's distance, and at a steady speed each edge's velocity as its offset squared:
    over a frame in which the distance grew by k (the bottom's offset from `horizon_y` before
    over after), the velocity shrinks by k squared, so a receding vehicle's box slows towards the
    vanishing point instead of running past it. A nearing vehicle's is left as it is: its box
    also grows as heat gathers on it, and speeding it up by that growth ran boxes ahead of
    oncoming cars. A bottom within `least_offset` px of the horizon tells no distance, and k is
    held within `largest_step`.
    """
    before = float(box[3]) - horizon_y
    after = before + float(velocity[3])
    if before < least_offset or after < least_offset or after >= before:
        return velocity
    shrink = max(after / before, 1 / largest_step)
    return velocity * shrink * shrink
