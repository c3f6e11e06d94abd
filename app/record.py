"""The per-frame record: its schema in one place (see `record.schema.json` and the README).

One JSON object per frame, in pixels of the undistorted frame. A stage that did not run has no
field at all; one that ran and found nothing has an empty value (`[]`, `null`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from app.errors import InputError
from app.facts import VehicleFacts
from app.pipeline import FrameResult
from lanes.finder import LaneEstimate
from vehicles.detections import Detections


def lane_record(lane: LaneEstimate | None) -> dict[str, Any] | None:
    """The `lane` field: boundaries as [x, y] points, radius (null when straight), offset and
    width."""
    if lane is None:
        return None
    return {
        "left": np.round(lane.left, 1).tolist(),
        "right": np.round(lane.right, 1).tolist(),
        "curvature_m": round(lane.curvature_m, 1) if math.isfinite(lane.curvature_m) else None,
        "offset_m": round(lane.offset_m, 3),
        "width_m": round(lane.width_m, 2) if math.isfinite(lane.width_m) else None,
    }


def vehicles_record(detections: Detections) -> list[dict[str, Any]]:
    """The `vehicles` field: id, box [x1, y1, x2, y2] and score of each shown vehicle."""
    return [
        {"id": int(i), "box": [round(float(v), 1) for v in box], "score": round(float(s), 3)}
        for box, s, i in zip(detections.boxes, detections.scores, detections.ids, strict=True)
    ]


def _rounded(value: float | None, digits: int) -> float | None:
    return round(value, digits) if value is not None else None


def vehicle_facts_record(facts: VehicleFacts) -> dict[str, Any]:
    """A vehicle's facts in metres: distance, lateral offset, lane, closing speed."""
    return {
        "distance_m": round(facts.distance_m, 1),
        "lateral_m": round(facts.lateral_m, 2),
        "lane": facts.lane,
        "closing_mps": _rounded(facts.closing_mps, 2),
    }


def frame_record(
    index: int,
    time_s: float,
    size: tuple[int, int],
    result: FrameResult,
    focal_mm: float | None = None,
    rotate_deg: int = 0,
) -> dict[str, Any]:
    """The record object of one frame; `focal_mm` is the lens's focal length in 35 mm terms
    where it, not a calibration, gave the distances (the frames are then as decoded);
    `rotate_deg` the turn clockwise that stood the stored picture upright (`--rotate`)."""
    record: dict[str, Any] = {
        "frame": index,
        "time_s": round(time_s, 4),
        "size": list(size),
        "shot": result.shot,
    }
    if focal_mm is not None:
        record["focal_mm"] = focal_mm
    if rotate_deg:
        record["rotate_deg"] = rotate_deg
    if result.roll_deg:
        record["roll_deg"] = round(result.roll_deg, 1)
    if result.scene is not None:
        record["horizon_y"] = round(result.scene.horizon_y, 1)
        record["vanishing_x"] = _rounded(result.scene.vanishing_x, 1)
        record["ground_scale"] = round(result.scene.ground_scale, 3)
        record["road_grey"] = _rounded(result.scene.road_grey, 1)
        record["grain"] = _rounded(result.scene.grain, 2)
        if result.scene.monochrome:
            record["monochrome"] = True
        record["overlays"] = [list(box) for box in result.scene.overlays]
    facts = result.facts
    if result.vehicles is not None:
        vehicles = vehicles_record(result.vehicles.detections)
        by_id = {f.id: f for f in facts.vehicles} if facts is not None else {}
        for vehicle in vehicles:
            if (known := by_id.get(vehicle["id"])) is not None:
                vehicle.update(vehicle_facts_record(known))
        record["vehicles"] = vehicles
        record["headway_s"] = _rounded(facts.headway_s, 2) if facts is not None else None
        record["ttc_s"] = _rounded(facts.ttc_s, 2) if facts is not None else None
    if result.lane is not None:
        record["lane"] = lane_record(result.lane.lane)
        record["speed_kmh"] = _rounded(facts.speed_kmh, 1) if facts is not None else None
        if facts is not None:
            record["length_scale"] = round(facts.length_scale, 3)
            record["dash_m"] = _rounded(facts.dash_m, 2)
        if facts is not None and facts.rear:
            record["facing"] = "rear-mirrored" if facts.mirrored else "rear"
    return record


def read_record_lines(
    path: Path, what: str = "record", option: str = "--json"
) -> Iterator[tuple[int, dict[str, Any]]]:
    """(line number, object) of each line of a JSON-lines file written by roadview, with a clear
    error on a missing file or a malformed line; `what` names the file in the error and
    `option` the `process` option that writes it."""
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        reason = error.strerror if isinstance(error, OSError) else "not text"
        raise InputError(
            f"cannot read {what} {path} ({reason}); make one with 'roadview process {option}'"
        ) from None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError:
            raise InputError(
                f"{path}:{number} is not a JSON line; pass a {what} "
                f"written by 'roadview process {option}'"
            ) from None
        if not isinstance(obj, dict):
            raise InputError(f"{path}:{number} is not a JSON object; not a roadview {what}")
        yield number, obj


def read_record(path: Path) -> Iterator[dict[str, Any]]:
    """Frame objects of a record file, with a clear error on a malformed line."""
    for number, obj in read_record_lines(path):
        if "frame" not in obj or "time_s" not in obj:
            raise InputError(f"{path}:{number} has no 'frame' field; not a roadview record")
        yield obj
