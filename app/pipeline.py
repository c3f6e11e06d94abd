"""The engine: undistort each frame and run the lane and vehicle stages on it.

The drivers (`app.drivers`, `app.debug`, `app.batch`) feed it frames and decide what to write; it
returns a typed `FrameResult` per frame. The stages are independent of each other (each sees the
undistorted frame), so the vehicle stage can run in a worker process, one frame ahead.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from contextlib import closing
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.errors import FrameSizeChanged
from app.events import Event, EventDetector, FrameSignals
from app.facts import FactsTracker, FrameFacts, RoadGeometry, along_scale
from app.mounting import Mounting, camera_height_note, dash_note
from app.sources import Frame
from app.stages import FrameStage
from app.traffic import KeepLeft
from app.workers import StageWorker
from camera_cal import (
    Calibration,
    DashScale,
    GroundScale,
    RollReading,
    SceneGeometry,
    SceneTracker,
    ShotDetector,
    Undistorter,
    calibrated_scale_height,
    focal_scale_height,
    horizon_estimates,
    same_camera,
    undistorter_for,
)
from lanes.config import LaneConfig
from lanes.finder import LaneFinder, LaneResult
from lanes.measure import reported_radius
from lanes.perspective import BirdsEye, birdseye_for
from vehicles.detections import Detections
from vehicles.detector import VehicleDetector, VehicleResult

# An unknown camera (no calibration, no --horizon): the stages wait this long at most for the
# footage's own horizon rather than place their work by a default that fits another camera.
HORIZON_WAIT_S = 3.0
WAITING = "waiting for the horizon"


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What the stages found in one frame; a stage that is off gives None."""

    lane: LaneResult | None = None
    vehicles: VehicleResult | None = None
    facts: FrameFacts | None = None
    events: tuple[Event, ...] = ()  # the driving events under way at this frame
    scene: SceneGeometry | None = None  # live picture and horizon as of this frame
    timings_ms: dict[str, float] = field(default_factory=dict)
    shot: int = 0  # shots before this frame's: 0 until the footage's first cut
    roll_deg: float = 0.0  # the turn levelled away in this frame (stated, or read: see Pipeline)


@dataclass(frozen=True, eq=False)
class FrameOutput:
    """One processed frame: the undistorted picture (the scene annotators draw on) and results."""

    undistorted: Frame
    result: FrameResult


@functools.lru_cache(maxsize=4)
def _scene_warp(
    size: tuple[int, int],
    horizon_y: float,
    live: tuple[int, int, int, int],
    scale_height: float,
    vanishing_x: float | None,
    ground_scale: float,
) -> BirdsEye:
    """The default lane config's warp for a scene placement (built once per placement)."""
    return birdseye_for(
        size, LaneConfig(), horizon_y, live, scale_height, vanishing_x, ground_scale
    )


@dataclass(frozen=True, eq=False)
class _Started:
    """A frame between the two halves of its processing (the vehicles may still be running)."""

    undistorted: Frame
    scene: SceneGeometry
    placement: dict[str, Any]  # the scene as the stages take it (see SceneTracker.placement)
    lane: LaneResult | None
    timings: dict[str, float]
    held: bool = False  # the stages waited for the horizon: they did not see this frame
    index: int = 0  # frames started before it since `prepare`
    cut: bool = False  # the first frame of another shot (see `camera_cal.shots`)
    roll_deg: float = 0.0  # the turn levelled away in this frame
    # The warp of this frame's metres (`Pipeline._view`; with the worker, the next frame is
    # started before this one finishes, and at a cut its warp is another scene's).
    view: BirdsEye | None = None
    # The same warp placed at the scene's horizon as estimated, where that is not where the
    # stages are placed (`Pipeline._measured`): the facts' metres.
    measured: BirdsEye | None = None
    # The road's length scale and the dash spacing read as of this frame (`SceneTracker.length`).
    length: tuple[float, float | None] = (1.0, None)


def lengthened(
    lane: LaneResult | None, length_scale: float, straight_m: float = math.inf
) -> LaneResult | None:
    """The lane stage's result with its radius of curvature on a road `length_scale` times as
    long as its view reads (the lines' offset across it kept, a bend x = y^2 / 2R reads R
    times the scale squared); a radius so scaled to `straight_m` or past it is straight (inf),
    as the lane stage reports one it reads so."""
    if length_scale == 1.0 or lane is None or lane.lane is None:
        return lane
    radius = reported_radius(1.0 / (lane.lane.curvature_m * length_scale**2), straight_m)
    return replace(lane, lane=replace(lane.lane, curvature_m=radius))


def measured_in(lane: LaneResult | None, started: _Started, straight_m: float) -> LaneResult | None:
    """The lane stage's result with its lane's radius, offset and width read in the warp at
    the horizon as estimated (`_Started.measured`), as the facts' metres are, where the stages
    are placed elsewhere: placed 1.1 % of the height above and below US winter's horizon, the
    lane stage read its width 3.21 and 3.67 m."""
    if lane is None or lane.lane is None or started.view is None or started.measured is None:
        return lane
    read = lane.lane.read_in(started.view, started.measured, started.scene.vanishing_x, straight_m)
    return replace(lane, lane=read)


class Pipeline:
    """Undistorts frames of one size and runs the lane and vehicle stages on them.

    `prepare(size)` must be called before the first frame of a clip: it builds the undistortion
    maps, resets the stages' history and, with `vehicles_in_worker`, starts the vehicle stage in a
    forked worker process. A frame of another size raises `FrameSizeChanged`. Use it as a context
    manager, or call `close`, to stop the worker. The `mounting` the user states (`Mounting`)
    fixes the horizon, sizes the vehicle windows, mirrors the vehicle stage's frames for traffic
    keeping left (or right, seen by a rear camera), levels the undistorted frames of a turned
    camera, and says whether the camera looks back.

    Where edited footage cuts to another shot (`camera_cal.ShotDetector`), the shot starts as a
    clip does: the stages forget their history, and the scene is measured afresh unless the
    same camera goes on (see `_scene_after_cut`); the vehicle ids go on counting, and the
    driving events under way end at the cut.

    A picture whose turn the user did not state is read for one from its vehicles' rear edges,
    its lane lines' spacing and its road's motion on either side (the lane stage's, asked for
    while the turn is read; `camera_cal.RollReading`); once they agree on a turn, the frames
    are levelled by it from the next one started (`levelled`). A stated turn stands;
    where the picture still reads turned after it, the turn it implies is kept for a note
    (`roll_contradicted`). The stages and the scene go on with their history, which the turn
    moves by a few pixels: started over, as at a cut, the turned shared clips lost more frames
    to it than they gained (README).

    An unknown camera's stages wait for its horizon (see `_wait`) unless it is read ahead: off
    the clip's first frames by `look_ahead`, and off a new shot's after a cut through
    `frames_from`, where the driver can read the clip again from its k-th frame since `prepare`
    (a second decoder; `prepare` clears it).
    """

    def __init__(
        self,
        calibration: Calibration | None,
        lanes: LaneFinder | None = None,
        vehicles: VehicleDetector | None = None,
        vehicles_in_worker: bool = False,
        mounting: Mounting | None = None,
    ) -> None:
        self.calibration = calibration
        self.mounting = mounting if mounting is not None else Mounting()
        self._car_scale = 1.0  # the vehicle windows' ground scale (see `prepare`)
        self.lanes = lanes
        # Traffic keeping left, or a rear camera's road: the vehicle stage sees the frames
        # mirrored (see app/traffic.py).
        self.vehicles: VehicleDetector | KeepLeft | None = (
            KeepLeft(vehicles) if self.mounting.mirrored and vehicles is not None else vehicles
        )
        self.vehicles_in_worker = vehicles_in_worker and vehicles is not None
        self.size: tuple[int, int] | None = None
        self._undistorter: Undistorter | None = None
        self._worker: StageWorker | None = None
        self._geometry: RoadGeometry | None = None
        # The last warp placed at the measured horizon, by the view and horizon it was made for.
        self._measured_view: tuple[tuple[BirdsEye, float], BirdsEye] | None = None
        self._default_horizon = 0.0  # the default warp's, where a scene starts (see `prepare`)
        self._scene: SceneTracker | None = None
        self._facts: FactsTracker | None = None
        self._events = EventDetector()
        self._fps = 0.0
        self._frame = 0  # index of the next frame to finish
        self._started = 0  # frames started since `prepare`
        self._wait = 0  # frames the stages may wait for the horizon
        # The vehicles of the last frames finished, by start index: the road's motion of frame k
        # is read around those of frame k - 2 (the newest a worker one frame ahead has done).
        self._vehicle_boxes: deque[tuple[int, NDArray[np.float64]]] = deque(maxlen=3)
        self._shots = ShotDetector()
        # The shots cut away from: the last frame, its scene, the tracker (a few, newest last).
        self._past_shots: deque[tuple[Frame, SceneGeometry, SceneTracker]] = deque(maxlen=4)
        self._last: tuple[Frame, SceneGeometry] | None = None  # the frame before, its scene
        self._shot_start = 0  # start index of the current shot's first frame
        self._id_offset = 0  # vehicle ids the earlier shots used
        self._last_id = 0
        self.cuts: list[int] = []  # frame numbers where a new shot started
        self.frames_from: Callable[[int], Generator[Frame, None, None]] | None = None
        self._horizon_found = False  # the footage showed its horizon in some frame
        self._roll = 0.0  # the turn the frames are levelled by
        # The edges' lean, the lane lines' spacing and the road's motion on either side, read
        # until the turn is known.
        self._level: RollReading | None = None
        # The turn read off the footage and the frame from which it was levelled, if any, and
        # what read it (`RollReading.cue`).
        self.levelled: tuple[float, int] | None = None
        self.levelled_by = "leans"
        # The turn the picture reads where the user stated another (None: they agree, or too
        # few edges and lines to tell).
        self.roll_contradicted: float | None = None

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the worker process, if any."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    @property
    def _stages(self) -> list[FrameStage]:
        return [s for s in (self.lanes, self.vehicles) if s is not None]

    def prepare(self, size: tuple[int, int], fps: float = 0.0, first_frame: int = 0) -> None:
        """Get ready for a clip of frames of `size` (width, height) at `fps` (0 for a still),
        starting at frame index `first_frame`: maps, road geometry, fresh history, worker.

        Raises `camera_cal.CalibrationMismatch` when the calibration does not fit the size.
        """
        self._roll = self.mounting.roll_deg or 0.0
        self._undistorter = undistorter_for(self.calibration, size, self._roll)
        # A still has too few vehicles to read a turn from.
        self._level = RollReading() if fps > 0 else None
        self.levelled, self.roll_contradicted = None, None
        self.levelled_by = "leans"
        self.size = size
        # The lane stage's own warp for this size (built once), or the default one without it.
        view = self.lanes.view(size) if self.lanes is not None else birdseye_for(size, LaneConfig())
        self._geometry = RoadGeometry.of(view)
        self._default_horizon = self._geometry.horizon_y
        # The lanes' ground scale is learned from their width: the warp needs the lanes' width
        # in the picture, whether a higher camera or narrower lanes make it. A car's size
        # depends on the camera's height alone, which the road does not tell: the vehicle
        # windows follow only a height the user states (sized by a learned 0.67, they boxed a
        # roadside sign on the rural clip's unmined part, 3 frames of 106).
        height = self.mounting.camera_height_m
        self._car_scale = (
            1.0 if height is None else round(self._geometry.camera_height_m / height, 3)
        )
        self._scene = self._new_scene(size, fps)
        self._facts = FactsTracker(
            fps, rear=self.mounting.rear, mirrored=self.mounting.facing == "rear-mirrored"
        )
        self._events.reset()
        self._fps, self._frame, self._started = fps, first_frame, 0
        self._vehicle_boxes.clear()
        self._shots.reset()
        self._past_shots.clear()
        self._last = None
        self._shot_start = self._id_offset = self._last_id = 0
        self.cuts = []
        self.frames_from = None
        self._horizon_found = False
        self._wait = round(HORIZON_WAIT_S * fps) if self._unknown_camera else 0
        frame_bytes = size[0] * size[1] * 3
        if self._worker is not None and self._worker.frame_bytes < frame_bytes:
            self.close()  # a larger frame than the slots hold: start the worker again
        for stage in self._stages:
            stage.reset(fps)
        if self._worker is not None:
            self._worker.reset(fps)
        elif self.vehicles_in_worker and self.vehicles is not None:
            # Forked now, before any reader/writer thread exists, with fresh stage history.
            self._worker = StageWorker(self.vehicles, frame_bytes)

    def height_note(self, ground_scale: float) -> str | None:
        """What a user should hear of the lanes' `ground_scale` (see `camera_height_note`), or
        None: the scale did not move, no lanes measured it, no vehicle windows are sized, or
        the user stated the camera's height."""
        if self.lanes is None or self.vehicles is None or self.size is None:
            return None
        if self.mounting.camera_height_m is not None:
            return None
        tuned = RoadGeometry.of(self.lanes.view(self.size)).camera_height_m
        return camera_height_note(ground_scale, tuned, self.lanes.config.lane_width_m)

    def dash_note(self) -> str | None:
        """What a user should hear of the road's length read off the lane dashes of the last
        shot (see `app.mounting.dash_note`), or None."""
        dashes = None if self._scene is None else self._scene.dashes
        if dashes is None:
            return None
        return dash_note(dashes.value, dashes.read_m, dashes.implausible_m, dashes.spacing_m)

    def horizon_note(self) -> str | None:
        """What a user should hear when an unknown camera's footage never showed its horizon:
        after waiting for it, the stages placed their work by the tuned camera's (None: it was
        found, stated or calibrated, or no stage ran)."""
        if self._horizon_found or not self._unknown_camera or self.size is None:
            return None
        if self.lanes is None and self.vehicles is None:
            return None
        return (
            "its road's vanishing point was never found (no straight road edges or lane lines "
            f"met below a horizon), so lanes and vehicles were looked for as under the shipped "
            f"camera's horizon, row {self._default_horizon:.0f} of {self.size[1]}: if the road "
            "vanishes elsewhere, pass --horizon Y (the row where it does), or --calibration "
            "FILE of this camera"
        )

    @property
    def facing_seen(self) -> bool | None:
        """What the current shot's road motion says of the camera (True: it faces backwards;
        None: not told yet), whatever the user stated (see `app.facts.Facing.seen`)."""
        return None if self._facts is None else self._facts.facing.seen

    @property
    def _unknown_camera(self) -> bool:
        """Neither a calibration nor `--horizon`: the stages wait for the footage's own horizon
        (see `_wait`), and the scene measures it hard while they do."""
        return self.calibration is None and self.mounting.horizon_y is None

    def look_ahead(self, frames: Iterable[Frame]) -> float | None:
        """Read an unknown camera's horizon off the clip's first `frames` before they are
        processed, so that its stages need not wait for it (see `_wait`): a scene tracker of
        its own takes them in until it estimates a horizon, or the picture cuts to another
        shot; the clip's scene gives the stages that horizon until it estimates its own
        (`SceneTracker.take_horizon`). Call it after `prepare`, with the frames the clip will
        start with: as many are read as the stages would wait. The row read, or None (a known
        camera's horizon, none found, or the frames ran out)."""
        if not self._unknown_camera or self._scene is None or self.size is None or self._started:
            return None
        return self._horizon_ahead(frames)

    def _horizon_ahead(self, frames: Iterable[Frame]) -> float | None:
        """The horizon a fresh scene tracker reads off `frames`, the current shot's from its
        first on, given to the shot's scene (see `look_ahead`); None if none was read before the
        stages would stop waiting, another cut, or the frames' end."""
        assert self._scene is not None and self.size is not None
        scene, shots = self._new_scene(self.size, self._fps), ShotDetector()
        for frame in itertools.islice(frames, self._wait):
            undistorted = self.undistort(frame)
            if shots.update(undistorted):
                return None  # what follows is another shot's
            geometry = scene.update(undistorted, frame)
            if geometry.estimated:
                self._scene.take_horizon(scene)
                self._horizon_found = True
                return geometry.horizon_y
        return None

    def _new_scene(self, size: tuple[int, int], fps: float) -> SceneTracker:
        """A scene tracker with no history, for a clip or a shot of frames of `size` at `fps`."""
        # The lens sets the scale where it is known: a calibration's, else a focal length stated
        # or tagged (a phone's); otherwise the scene takes the shipped camera's.
        lens = (
            calibrated_scale_height(self.calibration, size)
            if self.calibration
            else focal_scale_height(self.mounting.focal_mm, size)
            if self.mounting.focal_mm
            else None
        )
        lanes = self.lanes.config if self.lanes is not None else LaneConfig()
        return SceneTracker(
            size,
            self._default_horizon,
            self.mounting.horizon_y,
            fixed_scale=lens,
            min_estimates=horizon_estimates(fps),
            full_size_first=self._unknown_camera,
            # Lane widths over 10 s, believed after 1 s of them (counts at 25 fps for a still),
            # moved when they are ones the lane finder does not believe.
            ground=GroundScale(
                round(fps or 25),
                round(10 * (fps or 25)),
                (
                    lanes.min_lane_width_m / lanes.lane_width_m,
                    lanes.max_lane_width_m / lanes.lane_width_m,
                ),
                # A camera calibrated at this size is taken as the tuned one's height until
                # its lanes say otherwise; another one's lanes are measured before a side is
                # made up at their width (see GroundScale).
                assumed=self.calibration is not None
                and tuple(self.calibration.image_size) == tuple(size),
                confirm=max(3, round(0.2 * (fps or 25))),
            ),
            dashes=None if (spacing := self._dash_spacing) is None else DashScale(spacing),
        )

    @property
    def _dash_spacing(self) -> float | None:
        """The lane dashes' spacing the road's length scale is read from (the mounting's; None:
        not read, as without the lane stage, which reads the dashes)."""
        return self.mounting.dash_spacing_m if self.lanes is not None else None

    def _scene_after_cut(self, frame: Frame, ended: SceneTracker) -> SceneTracker:
        """The scene tracker of the shot the footage cut to at `frame`: the shot's that ended,
        or an earlier one's, where the same camera shows (its bonnet and overlays look the same,
        or the road's edges meet at its vanishing point: a compilation of one camera's clips,
        footage back from a zoomed replay as in the LA clip), else a fresh one. Each shot's is
        kept for a cut back to it."""
        assert self.size is not None and self._last is not None
        self._past_shots.append((*self._last, ended))
        back = next(
            (
                k
                for k in reversed(range(len(self._past_shots)))
                if same_camera(self._past_shots[k][0], frame, self._past_shots[k][1])
                or self._past_shots[k][2].fits(frame)
            ),
            None,
        )
        if back is None:
            return self._new_scene(self.size, self._fps)
        scene = self._past_shots[back][2]
        del self._past_shots[back]
        return scene

    def finish_events(self) -> list[Event]:
        """End of the clip: every driving event found in it, by start time."""
        return self._events.finish()

    def undistort(self, frame: Frame) -> Frame:
        """The undistorted frame (or the frame itself without a calibration)."""
        size = (frame.shape[1], frame.shape[0])
        if size != self.size:
            if self.size is None:
                raise RuntimeError("Pipeline.prepare(size) must be called before the first frame")
            raise FrameSizeChanged(self.size, size)
        return frame if self._undistorter is None else self._undistorter(frame)

    def run(self, frame: Frame) -> FrameOutput:
        """Undistort one frame and pass it through every stage."""
        return self._finish(self._start(frame))

    def stream(self, frames: Iterator[Frame]) -> Iterator[FrameOutput]:
        """Every frame's output, in order; with the worker, one frame is in flight meanwhile."""
        lag = 1 if self._worker is not None else 0
        pending: deque[_Started] = deque()
        for frame in frames:
            pending.append(self._start(frame))
            if len(pending) > lag:
                yield self._finish(pending.popleft())
        while pending:
            yield self._finish(pending.popleft())

    def _start(self, frame: Frame) -> _Started:
        """Undistort, hand the frame to the worker, and run the scene and the lanes here."""
        t0 = time.perf_counter()
        undistorted = self.undistort(frame)
        timings = {"undistort": (time.perf_counter() - t0) * 1000}
        assert self._scene is not None and self.size is not None
        t0 = time.perf_counter()
        index = self._started
        cut = self._shots.update(undistorted) and self._fps > 0
        if cut:  # another shot: its scene measured afresh, the stages' history forgotten
            self._scene = self._scene_after_cut(undistorted, self._scene)
            if (
                self._unknown_camera
                and not self._scene.current.estimated
                and self.frames_from is not None
            ):  # a fresh scene: its horizon read ahead off the shot's frames, this one first
                with closing(self.frames_from(index)) as ahead:
                    self._horizon_ahead(ahead)
            # Another camera may be turned: read afresh, unless a turn was found already (it
            # stands for the whole footage, as a stated one does).
            if self.levelled is None and self.roll_contradicted is None:
                self._level = RollReading()
            self._shot_start = index
            if self.lanes is not None:
                self.lanes.reset(self._fps)
            if self._worker is not None:
                self._worker.reset_before_next(self._fps)
            elif self.vehicles is not None:
                self.vehicles.reset(self._fps)
        scene = self._scene.update(undistorted, frame)
        self._horizon_found = self._horizon_found or scene.estimated
        self._last = (undistorted, scene)
        timings["scene"] = (time.perf_counter() - t0) * 1000
        placement = self._scene.placement
        held = not scene.estimated and index - self._shot_start < self._wait
        self._started += 1
        if held:
            waiting = LaneResult(None, status=(WAITING,)) if self.lanes is not None else None
            view = self._view(placement)
            return _Started(
                undistorted,
                scene,
                placement,
                waiting,
                timings,
                held=True,
                index=index,
                cut=cut,
                roll_deg=self._roll,
                view=view,
                measured=self._measured(view, scene),
            )
        if self._worker is not None:
            self._worker.submit(undistorted, **self._for_vehicles(placement, scene))
        lane = None
        if self.lanes is not None:
            t0 = time.perf_counter()
            around = next(
                (b for k, b in self._vehicle_boxes if k == index - 2 and k >= self._shot_start),
                None,
            )
            lane = self.lanes.process(
                undistorted,
                **placement,
                vehicles=around,
                width_known=self._scene.lane_width_known,
                road_x=scene.vanishing_x,
                read_turn=self._level is not None and self._level.wants_road,
            )
            timings["lanes"] = (time.perf_counter() - t0) * 1000
        view = self._view(placement)
        measured = self._measured(view, scene)
        if lane is not None:
            self._scene.observe_lane_width(lane.width_sample, lane.width_believed)
            spacings = lane.dash_spacings
            if spacings and view is not None and measured is not None:
                # In the facts' metres, so the length scale read off them applies to the facts.
                along = along_scale(view, measured)
                spacings = tuple(s * along for s in spacings)
            self._scene.observe_dashes(spacings)
        return _Started(
            undistorted,
            scene,
            placement,
            lane,
            timings,
            index=index,
            cut=cut,
            roll_deg=self._roll,
            view=view,
            measured=measured,
            length=self._scene.length,
        )

    def _view(self, placement: dict[str, Any]) -> BirdsEye | None:
        """The warp whose metres a frame started under `placement` is measured by: the lane
        stage's as of it, or without the lane stage the default lane config's for the same
        placement."""
        if self.lanes is not None:
            return self.lanes.current_view
        assert self.size is not None
        return _scene_warp(
            tuple(self.size),
            placement["horizon_y"],
            placement["live"],
            placement["scale_height"],
            placement["vanishing_x"],
            placement["ground_scale"],
        )

    def _measured(self, view: BirdsEye | None, scene: SceneGeometry) -> BirdsEye | None:
        """`view` placed at the `scene`'s horizon as estimated, where the stages are placed
        elsewhere (they follow it in steps; see `RoadGeometry`), else None: the same warp
        otherwise (live box, scale, column, ground scale), kept while the horizon stays."""
        if view is None or not scene.estimated or abs(scene.horizon_y - view.horizon_y) < 0.05:
            return None
        key = (view, scene.horizon_y)
        if self._measured_view is None or self._measured_view[0] != key:
            config = self.lanes.config if self.lanes is not None else LaneConfig()
            measured = birdseye_for(
                view.frame_size,
                config,
                scene.horizon_y,
                view.live,
                view.scale_height,
                view.vanishing_x,
                view.ground_scale,
            )
            self._measured_view = (key, measured)
        return self._measured_view[1]

    def _read_roll(
        self,
        undistorted: Frame,
        detections: Detections,
        index: int,
        scene: SceneGeometry,
        road_turn: float | None = None,
    ) -> None:
        """Take in the leans of the tracked vehicles of the frame started as `index`, its
        lane lines along the rays from the `scene`'s vanishing point once it is measured, and
        the turn its road's advance on either side read (`road_turn`, the lane stage's); once
        they read a turn, level the frames by it from the next one started, or, where the user
        stated the turn, keep the one they imply for a note (once: the reading then stops)."""
        if self._level is None:
            return
        tracked = detections.ids > 0
        vanishing = None
        if scene.estimated and scene.vanishing_x is not None:
            vanishing = (scene.vanishing_x, scene.horizon_y)
        turn = self._level.update(
            undistorted,
            detections.boxes[tracked],
            detections.ids[tracked],
            vanishing,
            scene.live,
            road_turn,
        )
        if turn is None:
            if self._level.full:  # level, or leaning every which way: read no more
                self._level = None
            return
        self.levelled_by = self._level.cue or "leans"
        self._level = None
        if self.mounting.roll_deg is not None:
            self.roll_contradicted = round(self._roll + turn, 1)
            return
        # From the next frame started (with the worker, frames after this one are started).
        assert self.size is not None
        self._roll += turn
        self._undistorter = undistorter_for(self.calibration, self.size, self._roll)
        self.levelled = (self._roll, self._frame + self._started - index)

    def _numbered(self, found: VehicleResult) -> VehicleResult:
        """`found` with its track ids after those of the earlier shots (each shot's tracker
        counts from 1), so that an id names one vehicle over the whole footage."""
        ids = found.detections.ids
        if len(ids):
            self._last_id = max(self._last_id, self._id_offset + int(ids.max()))
        if not self._id_offset or not len(ids):
            return found
        d = found.detections
        moved = np.where(ids > 0, ids + self._id_offset, ids)  # -1: no track yet
        return replace(found, detections=Detections(d.boxes, d.scores, moved))

    def _for_vehicles(self, placement: dict[str, Any], scene: SceneGeometry) -> dict[str, Any]:
        """The placement the vehicle stage takes: the scene's, with the cars' ground scale, the
        road's lightness and grain, and whether the picture is monochrome."""
        return {
            **placement,
            "ground_scale": self._car_scale,
            "road_grey": scene.road_grey,
            "grain": scene.grain,
            "monochrome": scene.monochrome,
        }

    def _finish(self, started: _Started) -> FrameOutput:
        """Add the vehicles (from the worker, or run here) to the frame's result."""
        undistorted, lane, timings = started.undistorted, started.lane, started.timings
        if started.cut:  # in frame order: what the last shot left under way ends here
            self.cuts.append(self._frame)
            self._id_offset = self._last_id
            if self._facts is not None:
                self._facts.reset()
            self._events.close()
        vehicles = None
        if started.held:
            vehicles = VehicleResult(Detections()) if self.vehicles is not None else None
        elif self._worker is not None:
            found, timings["vehicles"] = self._worker.collect()
            assert isinstance(found, VehicleResult)
            vehicles = found
        elif self.vehicles is not None:
            t0 = time.perf_counter()
            vehicles = self.vehicles.process(
                undistorted, **self._for_vehicles(started.placement, started.scene)
            )
            timings["vehicles"] = (time.perf_counter() - t0) * 1000
        if vehicles is not None:
            vehicles = self._numbered(vehicles)
            self._vehicle_boxes.append((started.index, vehicles.detections.boxes))
            road_turn = lane.road_turn_deg if lane is not None else None
            self._read_roll(
                undistorted, vehicles.detections, started.index, started.scene, road_turn
            )
        facts = None
        current = started.view
        if (
            self._geometry is not None
            and current is not None
            and (
                current is not self._geometry.view
                or started.measured is not self._geometry.measured
            )
        ):
            self._geometry = RoadGeometry.of(current, started.measured)
        road_x = started.scene.vanishing_x
        if self._geometry is not None and self._geometry.road_x != road_x:
            self._geometry = replace(self._geometry, road_x=road_x)
        if self._facts is not None and self._geometry is not None:
            facts = self._facts.update(
                vehicles.detections if vehicles is not None else None,
                lane.lane if lane is not None else None,
                lane.advance_m if lane is not None else None,
                self._geometry,
            ).scaled(*started.length)
        straight = self.lanes.config.straight_radius_m if self.lanes is not None else math.inf
        lane = measured_in(lane, started, straight)
        lane = lengthened(lane, started.length[0], straight)
        events: tuple[Event, ...] = ()
        if self._fps > 0:  # events need time: not for a still
            estimate = lane.lane if lane is not None else None
            events = self._events.update(
                FrameSignals(
                    self._frame,
                    self._frame / self._fps,
                    estimate.offset_m if estimate is not None else None,
                    estimate.width_m if estimate is not None else None,
                    facts.headway_s if facts is not None else None,
                    facts.ttc_s if facts is not None else None,
                    facts.ahead_id if facts is not None else None,
                    facts is not None and facts.rear,
                    facts is not None and facts.mirrored,
                )
            )
        self._frame += 1
        shot = len(self.cuts)
        result = FrameResult(
            lane, vehicles, facts, events, started.scene, timings, shot, started.roll_deg
        )
        return FrameOutput(undistorted, result)
