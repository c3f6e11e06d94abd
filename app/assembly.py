"""Builds the stage list that `process` and `debug` run, from the user's switches."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from app.stages import FrameStage, StageResult
from app.video import Frame

if TYPE_CHECKING:
    from vehicles.model import VehicleModel


def build_stages(
    lanes: bool = True,
    vehicles: bool = True,
    model: Path | None = None,
    keep_debug: bool = False,
    still: bool = False,
    classifier: VehicleModel | None = None,
) -> list[FrameStage]:
    """The lane and vehicle stages that are switched on, in pipeline order.

    For a still there is no history: every band is searched and nothing waits for confirmation.
    A `classifier` already loaded is used instead of loading `model`.
    """
    stages: list[FrameStage] = []
    if lanes:
        from lanes.finder import LaneFinder

        stages.append(LaneFinder(keep_debug=keep_debug))
    if vehicles:
        from vehicles.config import DetectorConfig
        from vehicles.detector import VehicleDetector
        from vehicles.model import load_model

        classifier = classifier if classifier is not None else load_model(model)
        config = DetectorConfig().for_still() if still else DetectorConfig()
        stages.append(VehicleDetector(classifier, config, keep_debug=keep_debug))
    return stages


def make_compositor(
    insets: bool = False,
) -> Callable[[Frame, Mapping[str, StageResult], float], Frame]:
    """The compositor `process` and `batch` draw with."""
    from app.compose import ComposeOptions, compose

    options = ComposeOptions(insets=insets)

    def compositor(frame: Frame, results: Mapping[str, StageResult], fps: float) -> Frame:
        return compose(frame, results, fps, options)

    return compositor
