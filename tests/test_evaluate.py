"""`roadview evaluate` on small hand-built records against the real labels."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from app.evaluate import FrameLabels, evaluate, iou, load_labels
from tests.helpers import run_cli


@pytest.fixture(scope="module")
def labels(data_dir: Path) -> dict[int, FrameLabels]:
    return load_labels(data_dir / "labels" / "test_video.json")


def _perfect_record(labels: dict[int, FrameLabels], dx: float = 0.0) -> list[dict[str, Any]]:
    records = []
    for frame, truth in sorted(labels.items()):
        vehicles = [
            {"id": v.id, "box": [v.box[0] + dx, v.box[1], v.box[2] + dx, v.box[3]], "score": 1.0}
            for v in truth.vehicles
            if not v.ignore
        ]
        lane = {
            side: [[x + dx, y] for y, x in sorted(rows.items())]
            for side, rows in truth.lane.items()
        }
        records.append(
            {
                "frame": frame,
                "time_s": frame / 25,
                "vehicles": vehicles,
                "lane": {**lane, "curvature_m": 1000.0, "offset_m": 0.0},
            }
        )
    return records


def test_interpolation_between_keyframes(labels: dict[int, FrameLabels]) -> None:
    assert min(labels) == 0 and max(labels) == 37 and len(labels) == 38
    a, b, mid = labels[0], labels[5], labels[2]
    car_a = next(v for v in a.vehicles if v.id == 1)
    car_b = next(v for v in b.vehicles if v.id == 1)
    car_mid = next(v for v in mid.vehicles if v.id == 1)
    assert car_mid.box[0] == pytest.approx(car_a.box[0] + 0.4 * (car_b.box[0] - car_a.box[0]))


def test_perfect_record_scores_perfectly(labels: dict[int, FrameLabels]) -> None:
    scores = evaluate(labels, _perfect_record(labels))
    v = scores["vehicles"]["iou_0.5"]
    assert v["precision"] == 1.0 and v["recall"] == 1.0 and v["mean_iou"] == pytest.approx(1.0)
    assert v["false_positives_per_frame"] == 0.0
    assert scores["lane"]["mean_abs_error_px"] == pytest.approx(0.0, abs=1e-9)
    assert scores["lane"]["share_within_20px"] == 1.0
    assert scores["frames_scored"] == 28


def test_id_switches_count_a_vehicle_matched_by_another_track(
    labels: dict[int, FrameLabels],
) -> None:
    """A labelled vehicle's track id changing between its matches is one switch each time; a
    record that keeps each vehicle's id has none."""
    records = _perfect_record(labels)
    assert evaluate(labels, records)["vehicles"]["iou_0.5"]["id_switches"] == 0
    frames = [r for r in records if r["frame"] >= 10 and r["vehicles"]]
    first = frames[0]["vehicles"][0]["id"]
    for record in frames[len(frames) // 2 :]:  # its second half under another id
        for vehicle in record["vehicles"]:
            if vehicle["id"] == first:
                vehicle["id"] = 99
    scores = evaluate(labels, records)["vehicles"]
    assert scores["iou_0.5"]["id_switches"] == 1
    assert scores["iou_0.5"]["recall"] == 1.0  # a switch costs no match


def test_empty_record_scores_zero_recall(labels: dict[int, FrameLabels]) -> None:
    empty: list[dict[str, Any]] = [{"frame": f, "vehicles": [], "lane": None} for f in labels]
    scores = evaluate(labels, empty)
    assert scores["vehicles"]["iou_0.5"]["recall"] == 0.0
    assert scores["vehicles"]["iou_0.5"]["true_positives"] == 0
    assert scores["lane"]["missing"] == scores["lane"]["points"] > 0
    assert scores["lane"]["share_within_20px"] == 0.0


def test_shifted_boxes(labels: dict[int, FrameLabels]) -> None:
    # Cars are >= 100 px wide: a 10 px shift keeps IoU > 0.5; lanes are off by exactly 10 px.
    scores = evaluate(labels, _perfect_record(labels, dx=10.0))
    v = scores["vehicles"]["iou_0.5"]
    assert v["recall"] == 1.0 and 0.75 < v["mean_iou"] < 0.95
    assert scores["lane"]["mean_abs_error_px"] == pytest.approx(10.0)
    # Shifted by a whole box width, nothing matches: all false positives and misses.
    far = evaluate(labels, _perfect_record(labels, dx=400.0))["vehicles"]["iou_0.3"]
    assert far["true_positives"] == 0 and far["false_positives"] == far["false_negatives"] > 0


def test_detection_on_ignored_vehicle_counts_neither_way(labels: dict[int, FrameLabels]) -> None:
    records = _perfect_record(labels)
    for record in records:
        truth = labels[record["frame"]]
        record["vehicles"] += [
            {"id": 99, "box": list(v.box), "score": 1.0} for v in truth.vehicles if v.ignore
        ]
    v = evaluate(labels, records)["vehicles"]["iou_0.5"]
    assert v["precision"] == 1.0 and v["false_positives"] == 0


def test_iou_basics() -> None:
    assert iou([0, 0, 10, 10], [0, 0, 10, 10]) == 1.0
    assert iou([0, 0, 10, 10], [5, 0, 15, 10]) == pytest.approx(1 / 3)
    assert iou([0, 0, 10, 10], [20, 20, 30, 30]) == 0.0


def test_evaluate_cli_json(labels: dict[int, FrameLabels], data_dir: Path, tmp_path: Path) -> None:
    record = tmp_path / "r.jsonl"
    record.write_text("".join(json.dumps(r) + "\n" for r in _perfect_record(labels)))
    result = run_cli(
        "evaluate",
        "--labels",
        data_dir / "labels" / "test_video.json",
        "--record",
        record,
        "--json",
    )
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    assert scores["vehicles"]["iou_0.5"]["recall"] == 1.0
    text = run_cli(
        "evaluate", "--labels", data_dir / "labels" / "test_video.json", "--record", record
    )
    assert "precision 1.000" in text.stdout
