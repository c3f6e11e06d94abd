"""Keyframes of two wild clips labelled by hand (`tests/labels/`, the `../labels/` format): the
Udacity challenge clip A (an SUV beside us under an overpass; oncoming cars over the barrier
marked ignore) and a span of the US winter highway with nothing ahead (frames 140-240)."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.evaluate import evaluate, load_labels
from tests.helpers import process_clip

LABELS = Path(__file__).with_name("labels")


def _scores(clip: Path, tmp_path: Path, *options: str) -> dict[str, float]:
    rows = process_clip(clip, tmp_path, "--no-lanes", *options)
    scores = evaluate(load_labels(LABELS / f"{clip.stem}.json"), rows)
    return dict(scores["vehicles"]["iou_0.5"])


@pytest.mark.slow
def test_challenge_clip_the_car_beside_and_no_boxes_on_barrier_or_shadow(
    wild_dir: Path, tmp_path: Path
) -> None:
    clip = wild_dir / "udacity_challenge_video_clipA_2.4s.mp4"  # the shipped camera: calibrated
    checked = _scores(clip, tmp_path)
    unchecked = _scores(clip, tmp_path, "--verifier", "none")
    assert checked["recall"] >= 0.7
    assert checked["precision"] >= 0.7 > unchecked["precision"]
    # Boxes reach the SUV's left side and its tyres (0.656 from the heat alone).
    assert checked["mean_iou"] >= 0.70


@pytest.mark.slow
def test_winter_highway_with_nothing_ahead_gets_no_box(wild_dir: Path, tmp_path: Path) -> None:
    clip = wild_dir / "us_highway_winter.mp4"
    scores = _scores(clip, tmp_path, "--calibration", "none", "--end", "8.2")
    assert scores["false_positives_per_frame"] <= 0.02
