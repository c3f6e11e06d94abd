"""Hard negatives: windows cut out as patches, one per false alarm, and what the shipped
verifier (trained also on patches mined from the first 60 % of two clips without vehicles) does
on the rest."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.mining import DUSK, Dimming, dimmed_copy, grainy
from app.sinks import VideoWriter
from app.sources import probe_video, read_frames
from tests.helpers import process_clip, run_cli
from vehicles.mining import surest_apart, window_patches
from vehicles.model import (
    default_dark_verifier_path,
    default_model_path,
    default_verifier_path,
    load_model,
)

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


def test_a_dimmed_copy_is_darker_and_grainy_anew_in_every_frame(tmp_path: Path) -> None:
    """A still grey clip, dimmed as the dark verifier's copies are: darker, at the rows asked
    for, and its grain differs from frame to frame (a dim sensor's, not a pattern)."""
    clip = tmp_path / "grey.mp4"
    writer = VideoWriter(clip, (64, 36), 25.0)
    for _ in range(4):
        writer.write(np.full((36, 64, 3), 120, np.uint8))
    writer.close()
    dimming = Dimming(0.6, -0.06, 0.7, grain=8, seed=3, rows=72)
    out = dimmed_copy(clip, dimming, tmp_path / "dim.mp4")
    info = probe_video(out)
    frames = np.stack(list(read_frames(out, info))).astype(float)
    assert info.size == (128, 72) and len(frames) == 4
    assert frames.mean() < 90
    assert np.abs(np.diff(frames, axis=0)).mean() > 1.0  # the grain moves
    assert {d.rows for d in DUSK} == {None, 720}  # mined at the clips' size and upscaled


def test_a_grainy_copy_keeps_the_light_and_at_a_dashcams_bitrate_its_grain(
    tmp_path: Path,
) -> None:
    """A still grey clip given daylight grain (`grainy`): as light as it was, its filter no
    `eq`, and at CRF 18 more of the grain kept than at x264's default, 23."""
    clip = tmp_path / "grey.mp4"
    writer = VideoWriter(clip, (128, 72), 25.0)
    for _ in range(4):
        writer.write(np.full((72, 128, 3), 120, np.uint8))
    writer.close()
    copy = grainy(6)
    assert "eq=" not in copy.filters()
    spread = {}
    for crf in (copy.crf, 23):
        out = dimmed_copy(clip, replace(copy, crf=crf), tmp_path / f"grainy_{crf}.mp4")
        frames = np.stack(list(read_frames(out, probe_video(out)))).astype(float)
        assert abs(frames.mean() - 120) < 2
        spread[crf] = float(frames.std())
    assert spread[18] > 1.2 * spread[23] > 0, spread


def test_mine_dusk_mines_each_dimmed_copy(test_video: Path, tmp_path: Path) -> None:
    out = tmp_path / "dusk"
    result = run_cli("mine", test_video, "--out", out, "--share", "0.3", "--every", "4", "--dusk")
    assert result.returncode == 0, result.stderr
    names = [p.name for p in out.glob("*.png")]
    for k in range(len(DUSK)):
        assert any(name.startswith(f"{test_video.stem}_dim{k}_") for name in names), k
    assert not list(tmp_path.glob(".dusk.*"))  # the copies went with the temporary folder


def test_the_dark_verifier_learned_the_dimmed_copies_too() -> None:
    verifier, dark = load_model(default_verifier_path()), load_model(default_dark_verifier_path())
    assert dark.report["n_hard_negatives"] > 2 * verifier.report["n_hard_negatives"]
    assert dark.config == verifier.config
    assert dark.report["grouped_split"]["accuracy"] >= 0.985


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
