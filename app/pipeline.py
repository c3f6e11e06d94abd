"""The engine: undistort each frame and run the lane and vehicle stages on it.

The drivers (`app.drivers`, `app.debug`, `app.batch`) feed it frames and decide what to write; it
returns a typed `FrameResult` per frame. The stages are independent of each other (each sees the
undistorted frame), so the vehicle stage can run in a worker process, one frame ahead.
"""

from __future__ import annotations

import functools
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.errors import FrameSizeChanged
from app.events import Event, EventDetector, FrameSignals
from app.facts import FactsTracker, FrameFacts, RoadGeometry
from app.mounting import Mounting
from app.sources import Frame
from app.stages import FrameStage
from app.traffic import KeepLeft
from app.workers import StageWorker
from camera_cal import (
    Calibration,
    GroundScale,
    SceneGeometry,
    SceneTracker,
    Undistorter,
    calibrated_scale_height,
    horizon_estimates,
    undistorter_for,
)
from lanes.config import LaneConfig
from lanes.finder import LaneFinder, LaneResult
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


class Pipeline:
    """Undistorts frames of one size and runs the lane and vehicle stages on them.

    `prepare(size)` must be called before the first frame of a clip: it builds the undistortion
    maps, resets the stages' history and, with `vehicles_in_worker`, starts the vehicle stage in a
    forked worker process. A frame of another size raises `FrameSizeChanged`. Use it as a context
    manager, or call `close`, to stop the worker. The `mounting` the user states (`Mounting`)
    fixes the horizon, sizes the vehicle windows, mirrors the vehicle stage's frames for traffic
    keeping left, and levels the undistorted frames of a turned camera.
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
        # Traffic keeping left: the vehicle stage sees the frames mirrored (see app/traffic.py).
        self.vehicles: VehicleDetector | KeepLeft | None = (
            KeepLeft(vehicles) if self.mounting.keep_left and vehicles is not None else vehicles
        )
        self.vehicles_in_worker = vehicles_in_worker and vehicles is not None
        self.size: tuple[int, int] | None = None
        self._undistorter: Undistorter | None = None
        self._worker: StageWorker | None = None
        self._geometry: RoadGeometry | None = None
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
        self._undistorter = undistorter_for(self.calibration, size, self.mounting.roll_deg)
        self.size = size
        # The lane stage's own warp for this size (built once), or the default one without it.
        view = self.lanes.view(size) if self.lanes is not None else birdseye_for(size, LaneConfig())
        self._geometry = RoadGeometry.of(view)
        lens = calibrated_scale_height(self.calibration, size) if self.calibration else None
        lanes = self.lanes.config if self.lanes is not None else LaneConfig()
        # The lanes' ground scale is learned from their width: the warp needs the lanes' width
        # in the picture, whether a higher camera or narrower lanes make it. A car's size
        # depends on the camera's height alone, which the road does not tell: the vehicle
        # windows follow only a height the user states (sized by a learned 0.67, they boxed a
        # roadside sign on the rural clip's unmined part, 3 frames of 106).
        height = self.mounting.camera_height_m
        self._car_scale = (
            1.0 if height is None else round(self._geometry.camera_height_m / height, 3)
        )
        # An unknown camera: the stages wait for the footage's horizon (see `_wait`).
        unknown = self.calibration is None and self.mounting.horizon_y is None
        self._scene = SceneTracker(
            size,
            self._geometry.horizon_y,
            self.mounting.horizon_y,
            fixed_scale=lens,
            min_estimates=horizon_estimates(fps),
            full_size_first=unknown,
            # Lane widths over 10 s, believed after 1 s of them (counts at 25 fps for a still),
            # moved when they are ones the lane finder does not believe.
            ground=GroundScale(
                round(fps or 25),
                round(10 * (fps or 25)),
                (
                    lanes.min_lane_width_m / lanes.lane_width_m,
                    lanes.max_lane_width_m / lanes.lane_width_m,
                ),
            ),
        )
        self._facts = FactsTracker(fps)
        self._events.reset()
        self._fps, self._frame, self._started = fps, first_frame, 0
        self._vehicle_boxes.clear()
        self._wait = round(HORIZON_WAIT_S * fps) if unknown else 0
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
        assert self._scene is not None
        t0 = time.perf_counter()
        scene = self._scene.update(undistorted)
        timings["scene"] = (time.perf_counter() - t0) * 1000
        placement = self._scene.placement
        index = self._started
        held = not scene.estimated and index < self._wait
        self._started += 1
        if held:
            waiting = LaneResult(None, status=(WAITING,)) if self.lanes is not None else None
            return _Started(undistorted, scene, placement, waiting, timings, True, index)
        if self._worker is not None:
            self._worker.submit(undistorted, **self._for_vehicles(placement, scene))
        lane = None
        if self.lanes is not None:
            t0 = time.perf_counter()
            around = next((b for k, b in self._vehicle_boxes if k == index - 2), None)
            lane = self.lanes.process(undistorted, **placement, vehicles=around)
            timings["lanes"] = (time.perf_counter() - t0) * 1000
            self._scene.observe_lane_width(lane.width_sample, lane.width_believed)
        return _Started(undistorted, scene, placement, lane, timings, False, index)

    def _for_vehicles(self, placement: dict[str, Any], scene: SceneGeometry) -> dict[str, Any]:
        """The placement the vehicle stage takes: the scene's, with the cars' ground scale and
        the road's lightness."""
        return {**placement, "ground_scale": self._car_scale, "road_grey": scene.road_grey}

    def _finish(self, started: _Started) -> FrameOutput:
        """Add the vehicles (from the worker, or run here) to the frame's result."""
        undistorted, lane, timings = started.undistorted, started.lane, started.timings
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
            self._vehicle_boxes.append((started.index, vehicles.detections.boxes))
        facts = None
        # Metres follow the warp placed from the scene: the lane stage's, or without it the
        # default lane config's for the same placement.
        current = (
            self.lanes.current_view
            if self.lanes is not None
            else _scene_warp(
                (undistorted.shape[1], undistorted.shape[0]),
                started.placement["horizon_y"],
                started.placement["live"],
                started.placement["scale_height"],
                started.placement["vanishing_x"],
                started.placement["ground_scale"],
            )
        )
        if (
            self._geometry is not None
            and current is not None
            and current is not self._geometry.view
        ):
            self._geometry = RoadGeometry.of(current)
        if self._facts is not None and self._geometry is not None:
            facts = self._facts.update(
                vehicles.detections if vehicles is not None else None,
                lane.lane if lane is not None else None,
                lane.advance_m if lane is not None else None,
                self._geometry,
            )
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
                )
            )
        self._frame += 1
        result = FrameResult(lane, vehicles, facts, events, started.scene, timings)
        return FrameOutput(undistorted, result)
