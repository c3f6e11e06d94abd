"""Builds the stages that `process`, `batch` and `debug` run, from the user's switches."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    from lanes.finder import LaneFinder
    from vehicles.detector import VehicleDetector
    from vehicles.model import VehicleModel


class Stages(NamedTuple):
    """The lane and vehicle stages; None where switched off."""

    lanes: LaneFinder | None
    vehicles: VehicleDetector | None


def build_stages(
    lanes: bool = True,
    vehicles: bool = True,
    model: Path | None = None,
    keep_debug: bool = False,
    still: bool = False,
    classifier: VehicleModel | None = None,
    verifier: Path | None = None,
    verify: bool = True,
    small: bool = True,
    lowres: bool = True,
) -> Stages:
    """The stages that are switched on.

    For a still there is no history: every band is searched and nothing waits for confirmation.
    A `classifier` already loaded is used instead of loading `model`. The vehicle stage's windows
    are also checked by the `verifier` model (the shipped one by default, and on a dark road the
    shipped dark verifier) unless `verify` is off.
    The smallest windows are read by the shipped 32 px model unless `small` is off. With the
    shipped model (no `model` nor `classifier` given), pictures of few rows are read by the
    shipped low-resolution model (see `DetectorConfig.lowres_rows`) unless `lowres` is off, and
    monochrome pictures by the shipped grey models (with their verifiers unless `verify` is off;
    the 32 px one unless `small` is off).
    """
    lane_stage = vehicle_stage = None
    if lanes:
        from lanes.finder import LaneFinder

        lane_stage = LaneFinder(keep_debug=keep_debug)
    if vehicles:
        from vehicles.config import DetectorConfig
        from vehicles.detector import Scorer, VehicleDetector
        from vehicles.model import (
            default_dark_verifier_path,
            default_grey_paths,
            default_lowres_path,
            default_small_paths,
            default_verifier_path,
            load_model,
        )

        shipped = model is None and classifier is None
        classifier = classifier if classifier is not None else load_model(model)
        config = DetectorConfig().for_still() if still else DetectorConfig()
        checker = load_model(verifier or default_verifier_path()) if verify else None
        small_path, small_checker = default_small_paths()
        twin = (
            Scorer.of(load_model(small_path), load_model(small_checker) if verify else None)
            if small
            else None
        )
        coarse = load_model(default_lowres_path()) if shipped and lowres else None
        # On a dark road the shipped verifier gives way to its twin that also learned a dim
        # sensor's grain; a verifier of the user's own checks every road.
        dark = load_model(default_dark_verifier_path()) if verify and verifier is None else None
        grey = None
        if shipped:
            sizes = default_grey_paths() if small else default_grey_paths()[:1]
            grey = {
                scorer.model.config.patch_size: scorer
                for scorer in (
                    Scorer.of(load_model(path), load_model(check) if verify else None)
                    for path, check in sizes
                )
            }
        vehicle_stage = VehicleDetector(
            classifier,
            config,
            keep_debug,
            checker,
            twin,
            lowres=coarse,
            dark_verifier=dark,
            grey=grey,
        )
    return Stages(lane_stage, vehicle_stage)
