"""Facts from the pictures: distance and lateral position of each vehicle, its lane, how fast it
closes in, our own speed, headway and time to collision, and which way the camera faces.

Geometry is the flat-road model of the lane stage's bird's-eye warp: that homography maps road
points of the frame to metres on the road. For a camera over a flat road the bird's-eye row of a
frame row v is an affine function of 1 / (v - v0), v0 the horizon row where the warp's
denominator vanishes; so the distance from the camera is Z(v) = K / (v - v0), with K read off the
warp itself (no focal length or camera height needed).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from app.events import LANE_WIDTH_M
from lanes.finder import LaneEstimate
from lanes.motion import NEAR_PART
from lanes.perspective import BirdsEye
from lanes.search import evaluate_fit
from vehicles.detections import Detections


def along_scale(
    view: BirdsEye, measured: BirdsEye, near: float = NEAR_PART, samples: int = 16
) -> float:
    """Metres of road, as `measured` reads them, in one metre along `view` over its nearest
    `near` rows (where the lane stage reads the road's motion and the dashes): two warps of
    one picture whose horizons differ (the lane stage's, placed in steps, and the scene's as
    estimated) read the same stretch of road as of other lengths. The ratio is averaged over
    the picture's rows that part shows, along the camera's line: the motion is read off the
    picture's pixels, which crowd into the view's far rows (placed 1.1 % of the height below
    and above four wild clips' horizons, the lane stage read their advance 1.13-1.39 times as
    long; taken through this ratio, 0.93-1.02 times; averaged over the view's rows, the ratio
    overshot on each clip)."""
    bw, bh = view.size
    ends = view.to_frame(np.array([[bw / 2, (1.0 - near) * bh], [bw / 2, float(bh)]]))[:, 1]
    rows = np.linspace(ends[0], ends[1], samples + 1)
    points = np.column_stack([np.full(len(rows), view.camera_column), rows])
    placed = view.to_birdseye(points)[:, 1] * view.ym_per_px
    moved = measured.to_birdseye(points)[:, 1] * measured.ym_per_px
    return float(np.mean(np.diff(moved) / np.diff(placed)))


@dataclass(frozen=True)
class RoadGeometry:
    """The flat-road model of one frame size: horizon row and the scale K of Z = K / (v - v0),
    and the column of the road's vanishing point as last read (`road_x`; None: the view's).

    `view` is the lane stage's warp, whose bird's-eye pixels its lane fits are in; it is placed
    by the scene's horizon in steps (1.5 % of the height), which at 360 rows moves a speed read
    off the near road by up to a fifth. `measured`, where given, is the same warp placed at the
    horizon as estimated: the facts' metres are read off it (None: off `view`)."""

    view: BirdsEye
    horizon_y: float
    k: float
    road_x: float | None = None
    measured: BirdsEye | None = None

    @classmethod
    def of(cls, view: BirdsEye, measured: BirdsEye | None = None) -> RoadGeometry:
        """The model implied by a bird's-eye warp (by `measured`'s, where given)."""
        metric = view if measured is None else measured
        w, h = metric.frame_size
        m = metric.matrix
        cx = w / 2
        horizon = -(m[2, 0] * cx + m[2, 2]) / m[2, 1]
        bottom = h - 1.0
        near, far = bottom, horizon + 0.25 * (bottom - horizon)
        rows = metric.to_birdseye(np.array([[cx, near], [cx, far]]))[:, 1]
        # D(far) - D(near) in metres = K (1/(far - v0) - 1/(near - v0)).
        metres = (rows[0] - rows[1]) * metric.ym_per_px
        k = metres / (1 / (far - horizon) - 1 / (near - horizon))
        return cls(view, float(horizon), float(k), measured=measured)

    @property
    def metric(self) -> BirdsEye:
        """The warp whose metres the facts read."""
        return self.view if self.measured is None else self.measured

    @functools.cached_property
    def advance_scale(self) -> float:
        """What the road's advance read in `view`'s metres is multiplied by to be in the
        facts' (see `along_scale`; 1 without `measured`)."""
        return 1.0 if self.measured is None else along_scale(self.view, self.measured)

    @property
    def camera_height_m(self) -> float:
        """The camera's height over the road as the warp reads it: a row d pixels below the
        horizon shows d / height pixels a metre across (for the tuned warp, 1.24 m)."""
        w, h = self.view.frame_size
        row = self.horizon_y + 0.5 * (h - 1 - self.horizon_y)
        across = self.lateral(np.array([[w / 2, row], [w / 2 + 1.0, row]]))
        return float((row - self.horizon_y) * (across[1] - across[0]))

    def distance(self, rows: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance ahead of the camera, in metres, of road points at frame rows `rows`
        (inf at or above the horizon)."""
        below = np.asarray(rows, np.float64) - self.horizon_y
        with np.errstate(divide="ignore"):
            return np.where(below > 0.5, self.k / np.maximum(below, 0.5), np.inf)

    @property
    def road_column(self) -> float:
        """The frame column of the road line under the camera: upright through the road's
        vanishing point (see `BirdsEye.camera_column`), as last read rather than as the view is
        placed by it (in steps of 3 % of the width: a point 60 m ahead on our line read
        1.6 m to its side with the road 2 % of the width off the view's column)."""
        return self.view.camera_column if self.road_x is None else self.road_x

    def lateral(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Metres to the right of the road line under the camera (`road_column`) of road
        points (x, y) of the frame."""
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        ahead = np.column_stack([np.full(len(pts), self.road_column), pts[:, 1]])
        metric = self.metric
        xs = metric.to_birdseye(pts)[:, 0] - metric.to_birdseye(ahead)[:, 0]
        return np.asarray(xs * metric.xm_per_px)


def lane_of(
    lateral_m: float, distance_m: float, lane: LaneEstimate | None, geometry: RoadGeometry
) -> str:
    """'ego', 'left', 'right' or 'other': where a road point lies relative to our lane.

    The lane's centre and width are read from its boundaries at the point's distance (at the
    farthest fitted row beyond the bird's-eye view); without a lane, lanes of 3.7 m around us.
    """
    centre, width = 0.0, LANE_WIDTH_M
    if lane is not None:
        view = geometry.view
        cx = geometry.road_column
        # The camera's line at the point's distance, in the bird's-eye view (rows beyond the
        # view are read at its far edge: the fits are not extrapolated).
        row = geometry.horizon_y + geometry.k / max(distance_m, 1e-3)
        axis = view.to_birdseye(np.array([[cx, row]]))[0]
        bird_row = np.array([float(np.clip(axis[1], 0, view.size[1]))])
        left = evaluate_fit(lane.left_fit, bird_row)[0]
        right = evaluate_fit(lane.right_fit, bird_row)[0]
        centre = ((left + right) / 2 - axis[0]) * view.xm_per_px
        width = max((right - left) * view.xm_per_px, 2.0)
    offset = (lateral_m - centre) / width
    if abs(offset) <= 0.5:
        return "ego"
    if abs(offset) <= 1.5:
        return "right" if offset > 0 else "left"
    return "other"


@dataclass(frozen=True)
class VehicleFacts:
    """One shown vehicle in metres: distance ahead, lateral offset, lane, closing speed."""

    id: int
    distance_m: float
    lateral_m: float
    lane: str
    closing_mps: float | None


@dataclass(frozen=True)
class FrameFacts:
    """The facts of one frame."""

    speed_kmh: float | None
    vehicles: tuple[VehicleFacts, ...]
    headway_s: float | None = None  # to the nearest vehicle ahead in our lane
    ttc_s: float | None = None  # to it, while it closes in
    ahead_id: int | None = None  # that vehicle
    # A rear camera (the road moves away): "ahead" is then behind us, the vehicle following;
    # `mirrored`: its file saved mirrored, as a rear-view mirror shows the road (stated only).
    rear: bool = False
    mirrored: bool = False
    # The road's length per metre of the bird's-eye view (`DashScale`): distances and speeds
    # above are scaled by it; the lane dashes' spacing as the view read it (None: not read).
    length_scale: float = 1.0
    dash_m: float | None = None

    def scaled(self, length_scale: float, dash_m: float | None) -> FrameFacts:
        """These facts, read in the view's metres, with the road's lengths `length_scale` times
        as long: distances, closing speeds and our speed scale; headway and time to collision
        (a distance over a speed) do not."""
        vehicles = tuple(
            replace(
                v,
                distance_m=v.distance_m * length_scale,
                closing_mps=None if v.closing_mps is None else v.closing_mps * length_scale,
            )
            for v in self.vehicles
        )
        speed = None if self.speed_kmh is None else self.speed_kmh * length_scale
        return replace(
            self, speed_kmh=speed, vehicles=vehicles, length_scale=length_scale, dash_m=dash_m
        )


class Facing:
    """History for the way the camera faces, read from the road's motion: the road comes
    towards a front camera and moves away from a rear one (a dual-channel dashcam's rear file,
    or footage played backwards). Rear once at least `least` frames' advances moved away and
    they outnumber those that came towards it; the shared and wild clips' road never read as
    moving away, in any frame (README). Only advances of at least `min_advance_m` count: a car
    reversing (out of a parking space, as a dashcam's first seconds often show) moves slowly,
    and a rear camera sees the road move away at driving speeds. A `stated` facing (True:
    rear) is taken as it is."""

    def __init__(self, least: int, stated: bool | None = None, min_advance_m: float = 0.0) -> None:
        self.least = least
        self.stated = stated
        self.min_advance_m = min_advance_m
        self._towards = 0
        self._away = 0

    def reset(self) -> None:
        """Forget the advances: another shot, perhaps another camera."""
        self._towards = self._away = 0

    def update(self, advance_m: float | None) -> bool:
        """Take in one frame's signed advance (None: not measured); whether the camera faces
        backwards."""
        if advance_m and abs(advance_m) >= self.min_advance_m:
            if advance_m > 0:
                self._towards += 1
            else:
                self._away += 1
        return self.rear

    @property
    def rear(self) -> bool:
        """Whether the camera faces backwards: as stated, or as the road's motion says."""
        if self.stated is not None:
            return self.stated
        return self.seen is True

    @property
    def seen(self) -> bool | None:
        """What the road's motion alone says, whatever was stated (True: it moved away from the
        camera more than towards it, in at least `least` frames; False: the other way); None
        while too little of it moved at driving speed to tell."""
        if self._away >= self.least and self._away > self._towards:
            return True
        if self._towards >= self.least and self._towards > self._away:
            return False
        return None


class FactsTracker:
    """History for the facts: each track's smoothed distance (for its closing speed).

    Distances are smoothed along a track (exponential, weight `smoothing` on the new value at
    `frame_rate`, so that the same time is averaged at any `fps`) and the closing speed is the
    slope of the smoothed distance over the last `window_s` seconds (at least 3 frames). Our
    speed is the road's advance towards a front camera, or away from a rear one once `Facing`
    read it so over `facing_s` seconds at `facing_kmh` or more, or the user `rear` said so
    (before, and against the facing, it is not known); `mirrored`: the user said the rear
    camera's file is saved mirrored.
    """

    def __init__(
        self,
        fps: float,
        smoothing: float = 0.3,
        window_s: float = 0.4,
        frame_rate: float = 25.0,
        facing_s: float = 0.4,
        rear: bool | None = None,
        facing_kmh: float = 15.0,
        mirrored: bool = False,
    ) -> None:
        self.fps = fps
        rate = fps if fps > 0 else frame_rate
        # The weight left on the past after one of this video's frames, as after the same time
        # at the reference rate.
        self.smoothing = 1 - (1 - smoothing) ** (frame_rate / rate)
        self.window = max(3, round(window_s * rate))
        self._distances: dict[int, deque[float]] = {}
        self.facing = Facing(max(3, round(facing_s * rate)), rear, facing_kmh / 3.6 / rate)
        self.mirrored = mirrored

    def reset(self) -> None:
        """Forget every track, and the way the camera faces (a cut may be to another)."""
        self._distances.clear()
        self.facing.reset()

    def update(
        self,
        detections: Detections | None,
        lane: LaneEstimate | None,
        advance_m: float | None,
        geometry: RoadGeometry,
    ) -> FrameFacts:
        """The facts of one frame's shown vehicles, lane and road motion (`advance_m` signed:
        towards the camera positive, in `geometry.view`'s metres)."""
        if advance_m is not None:
            advance_m *= geometry.advance_scale
        rear = self.facing.update(advance_m)
        along = None if advance_m is None else -advance_m if rear else advance_m
        speed = along * self.fps * 3.6 if along is not None and along > 0 else None
        found: list[VehicleFacts] = []
        if detections is not None and len(detections):
            boxes = detections.boxes
            feet = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]])
            distances = geometry.distance(feet[:, 1])
            laterals = geometry.lateral(feet)
            for track_id, raw, lateral in zip(detections.ids, distances, laterals, strict=True):
                if not math.isfinite(raw):
                    continue
                history = self._distances.setdefault(int(track_id), deque(maxlen=self.window))
                smoothed = (
                    raw
                    if not history
                    else self.smoothing * raw + (1 - self.smoothing) * history[-1]
                )
                history.append(float(smoothed))
                closing = None
                if len(history) >= 3 and self.fps > 0:
                    slope = np.polyfit(np.arange(len(history)), np.asarray(history), 1)[0]
                    closing = float(-slope * self.fps)
                found.append(
                    VehicleFacts(
                        int(track_id),
                        float(smoothed),
                        float(lateral),
                        lane_of(float(lateral), float(smoothed), lane, geometry),
                        closing,
                    )
                )
        shown = {f.id for f in found}
        for gone in [i for i in self._distances if i not in shown]:
            del self._distances[gone]
        ahead = min((f for f in found if f.lane == "ego"), key=lambda f: f.distance_m, default=None)
        headway = ttc = None
        if ahead is not None:
            if speed is not None and speed > 5:
                headway = ahead.distance_m / (speed / 3.6)
            if ahead.closing_mps is not None and ahead.closing_mps > 0.3:
                ttc = ahead.distance_m / ahead.closing_mps
        return FrameFacts(
            speed,
            tuple(found),
            headway,
            ttc,
            ahead.id if ahead is not None else None,
            rear,
            rear and self.mirrored,
        )
