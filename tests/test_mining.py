"""Hard negatives: windows cut out as patches, one per false alarm, and what the shipped
verifier (trained also on patches mined from the first 60 % of two clips without vehicles) does
on the rest."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.helpers import process_clip, run_cli
from vehicles.mining import surest_apart, window_patches
from vehicles.model import default_model_path, default_verifier_path, load_model

NO_VEHICLES = ("rural_2lane_wet", "night_highway_istock")  # see the wild clips' README


def test_window_patches_cut_and_scale_each_window() -> None:
    frame = np.zeros((200, 300, 3), np.uint8)
    frame[50:150, 100:200] = (200, 30, 30)  # a red square
    boxes = np.array([[100.0, 50.0, 200.0, 150.0], [-32.0, 0.0, 32.0, 64.0]])
    patches = window_patches(frame, boxes, 64)
    assert patches.shape == (2, 64, 64, 3)
    assert (patches[0] == (200, 30, 30)).all()  # the square fills the first window
    assert patches[1].max() == 0  # the second, mirrored past the edge, is black road


def test_one_patch_per_false_alarm_surest_first() -> None:
    # Two false alarms, each seen by overlapping windows, and one window below the bar.
    boxes = np.array(
        [[0, 0, 64, 64], [8, 0, 72, 64], [200, 0, 264, 64], [204, 4, 268, 68], [400, 0, 464, 64]],
        np.float64,
    )
    scores = np.array([0.7, 0.9, 0.8, 0.6, 0.4])
    assert surest_apart(boxes, scores, 0.5, 10).tolist() == [1, 2]
    assert surest_apart(boxes, scores, 0.5, 1).tolist() == [1]


def test_mine_writes_patches_of_a_clip_and_refuses_a_bad_share(
    test_video: Path, tmp_path: Path
) -> None:
    # (A clip with cars: the command cannot know; here it gives windows to cut, the cars.)
    clip = test_video
    out = tmp_path / "negatives"
    result = run_cli("mine", clip, "--out", out, "--share", "0.5", "--every", "5")
    assert result.returncode == 0, result.stderr
    patches = [cv2.imread(str(p)) for p in sorted(out.glob("*.png"))]
    assert patches and all(p is not None and p.shape == (64, 64, 3) for p in patches)
    bad = run_cli("mine", clip, "--out", tmp_path / "x", "--share", "0")
    assert bad.returncode != 0 and "--share" in bad.stderr and not (tmp_path / "x").exists()


def test_the_shipped_verifier_learned_hard_negatives_and_kept_its_accuracy() -> None:
    model, verifier = load_model(default_model_path()), load_model(default_verifier_path())
    assert verifier.report["n_hard_negatives"] > 0 == model.report["n_hard_negatives"]
    assert verifier.config == model.config  # it scores the model's own window features
    assert verifier.report["grouped_split"]["accuracy"] >= 0.985


@pytest.mark.slow
@pytest.mark.parametrize("clip", NO_VEHICLES)
def test_no_boxes_where_no_vehicle_is_on_the_unmined_rest(
    wild_dir: Path, tmp_path: Path, clip: str
) -> None:
    """The last 40 % of each clip without vehicles (not mined): at most 0.02 boxes a frame
    (0.066 and 0.179 without the verifier). The whole clip is run, so the scene geometry is
    settled as it would be."""
    video = wild_dir / f"{clip}.mp4"
    record = process_clip(video, tmp_path, "--calibration", "none")
    rest = record[round(0.6 * len(record)) :]
    boxes = sum(len(r.get("vehicles", [])) for r in rest)
    assert len(rest) > 60
    assert boxes / len(rest) <= 0.02, boxes
