"""Keyframes of three wild clips labelled by hand (`tests/labels/`, the `../labels/` format): the
Udacity challenge clip A (an SUV beside us under an overpass; oncoming cars over the barrier
marked ignore), a span of the US winter highway with nothing ahead (frames 140-240) and 2 s of
the LA freeway's dense traffic (frames 100-160, every 10th; cars under 27 px wide, 40 px at
1280, marked ignore)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from app.evaluate import evaluate, load_labels, load_labels_document
from tests.helpers import process_clip, run_cli
from vehicles.detections import inside_share, iou_matrix, overlap_of_smaller
from vehicles.model import default_model_path

LABELS = Path(__file__).with_name("labels")


def _scores(clip: Path, tmp_path: Path, *options: str) -> dict[str, float]:
    rows = process_clip(clip, tmp_path, "--no-lanes", *options)
    scores = evaluate(load_labels(LABELS / f"{clip.stem}.json"), rows)
    return dict(scores["vehicles"]["iou_0.5"])


def _only(document: dict[str, Any], vehicle: int) -> dict[str, Any]:
    """The labels with every vehicle but `vehicle` marked ignore (its own recall)."""
    only: dict[str, Any] = json.loads(json.dumps(document))
    for keyframe in only["keyframes"].values():
        for v in keyframe["vehicles"]:
            v["ignore"] = v["ignore"] or v["id"] != vehicle
    return only


@pytest.mark.slow
def test_challenge_clip_the_car_beside_and_no_boxes_on_barrier_or_shadow(
    wild_dir: Path, tmp_path: Path
) -> None:
    clip = wild_dir / "udacity_challenge_video_clipA_2.4s.mp4"  # the shipped camera: calibrated
    rows = process_clip(clip, tmp_path, "--no-lanes")
    labels = load_labels(LABELS / f"{clip.stem}.json")
    checked = dict(evaluate(labels, rows)["vehicles"]["iou_0.5"])
    unchecked = _scores(clip, tmp_path, "--verifier", "none")
    # The SUV in the overpass's shadow is boxed over its upper half at IoU 0.4-0.5 (frames
    # 37-42), so a small change moves a frame across 0.5: recall 0.731 / 0.692 / 0.731 before
    # the tracker's weights forgot as much a second at any rate / before a receding track
    # slowed towards the vanishing point and a side coming into the picture was placed / since.
    assert checked["recall"] >= 0.65
    # Its false boxes are the SUV's while it enters the picture, boxed lower than its label
    # (IoU 0.3-0.5; precision 0.717 / 0.691 / 0.655 / 0.745 before windows stood by their
    # mirror images / before the weights per second / before the receding track slowed /
    # since; 0.512 unchecked). Each box lies mostly on a labelled vehicle (at least 0.73 of
    # it); unchecked, 27 lie wholly off them, on the barrier and the shadow.
    assert checked["precision"] >= 0.6 > unchecked["precision"]
    for index, frame in labels.items():
        for found in rows[index]["vehicles"]:
            box = np.array([found["box"]], np.float64)
            on = max((float(inside_share(box, v.box)[0]) for v in frame.vehicles), default=0.0)
            assert on >= 0.5, (index, found)
    # Boxes reach the SUV's left side and its tyres (0.656 from the heat alone).
    assert checked["mean_iou"] >= 0.70
    # One id throughout: its track's box, run past the picture's side while the SUV is there,
    # was dropped twice and the SUV boxed as #1, #2 and #3.
    assert checked["id_switches"] == 0


@pytest.mark.slow
def test_winter_highway_with_nothing_ahead_gets_no_box(wild_dir: Path, tmp_path: Path) -> None:
    clip = wild_dir / "us_highway_winter.mp4"
    scores = _scores(clip, tmp_path, "--calibration", "none", "--end", "8.2")
    assert scores["false_positives_per_frame"] <= 0.02


@pytest.mark.slow
def test_la_freeway_the_car_ahead_is_boxed(wild_dir: Path, tmp_path: Path) -> None:
    """Another camera (854x480, a mirror in its corner, glare on the windscreen) in dense
    traffic. The SUV ahead in the next lane, seen from behind, is boxed in most frames; the
    clip's other required cars are not (an SUV beside us seen from the side, cut by the frame's
    edge, and a car seen only through the glare's reflection), which the README reports. Under
    540 rows the low-resolution model reads the picture: most boxes are cars, where the model
    of sharp crops (given as --model, it reads every size) put most on the mirror and glare."""
    clip = wild_dir / "la_freeway_minidashcam_2.mp4"
    options = ("--no-lanes", "--calibration", "none", "--end", "5.5")
    for name in ("lowres", "sharp"):
        (tmp_path / name).mkdir()
    rows = process_clip(clip, tmp_path / "lowres", *options)
    document = json.loads((LABELS / f"{clip.stem}.json").read_text())
    ahead = evaluate(load_labels_document(_only(document, 2)), rows)["vehicles"]["iou_0.5"]
    assert ahead["recall"] >= 0.75
    assert ahead["mean_iou"] >= 0.6
    every = evaluate(load_labels_document(document), rows)["vehicles"]["iou_0.5"]
    sharp_rows = process_clip(
        clip, tmp_path / "sharp", *options, "--model", str(default_model_path())
    )
    sharp = evaluate(load_labels_document(document), sharp_rows)["vehicles"]["iou_0.5"]
    # 0.877 before windows stood by their mirror image: 7 boxes on the mirror's reflective part.
    assert every["precision"] >= 0.95 > 0.5 > sharp["precision"], (every, sharp)


@pytest.mark.slow
def test_la_freeway_the_suv_we_pass_keeps_its_id_through_the_glare(
    wild_dir: Path, tmp_path: Path
) -> None:
    """The SUV passed on our left (labelled 2) is boxed until frame 150, then through the
    windscreen's glare no window heats on it for half a second: found again, it keeps its id
    (it had been given a new one, and both were shown on it at once for 7 frames while its old
    track coasted beside it)."""
    clip = wild_dir / "la_freeway_minidashcam_2.mp4"
    rows = process_clip(clip, tmp_path, "--no-lanes", "--calibration", "none", "--end", "6.5")
    labels = load_labels(LABELS / f"{clip.stem}.json")

    def suv(frame: int) -> NDArray[np.float64]:
        return np.array([next(v.box for v in labels[frame].vehicles if v.id == 2)], np.float64)

    def boxes(frame: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        found = rows[frame]["vehicles"]
        box = np.array([v["box"] for v in found], np.float64).reshape(-1, 4)
        return box, np.array([v["id"] for v in found], np.int64)

    before: set[int] = set()
    for frame in range(120, 151, 10):
        found, ids = boxes(frame)
        before |= set(ids[iou_matrix(found, suv(frame))[:, 0] >= 0.5].tolist())
    assert len(before) == 1, before
    # Its first box after the glare lies on where the SUV was at frame 160 (its label).
    after = next(f for f in range(161, len(rows)) if len(boxes(f)[0]))
    found, ids = boxes(after)
    on = overlap_of_smaller(found, suv(160))[:, 0] >= 0.5
    assert on.any(), (after, found)
    assert set(ids[on].tolist()) == before
    for row in rows:  # and no vehicle is boxed twice
        found, ids = boxes(row["frame"])
        assert len(set(ids.tolist())) == len(ids)
        twice = overlap_of_smaller(found, found) >= 0.5
        assert not (twice & ~np.eye(len(found), dtype=bool)).any(), row["frame"]


@pytest.mark.slow
def test_la_freeway_the_debug_mode_draws_the_suv_remembered_through_the_glare(
    wild_dir: Path, tmp_path: Path
) -> None:
    """While no box is on the SUV (frame 158, in the glare), the debug mode's tracks picture
    draws it in grey where it would be, under the id it keeps: the only thing drawn there."""
    clip = wild_dir / "la_freeway_minidashcam_2.mp4"
    out = tmp_path / "dbg"
    result = run_cli(
        "debug", clip, "--frames", "158", "--out", out, "--calibration", "none", "--from-start"
    )
    assert result.returncode == 0, result.stderr
    frame = out / "frame_000158"
    tracks = np.asarray(cv2.imread(str(frame / "09_tracks.png")), int)
    plain = np.asarray(cv2.imread(str(frame / "01_undistorted.png")), int)
    drawn = (np.abs(tracks - plain).sum(axis=2) > 0) & (tracks == 150).all(axis=2)
    ys, xs = np.nonzero(drawn)
    assert len(xs), "nothing drawn"
    box = np.array([[xs.min(), ys.min(), xs.max(), ys.max()]], np.float64)
    labels = load_labels(LABELS / f"{clip.stem}.json")
    suv = np.array([next(v.box for v in labels[158].vehicles if v.id == 2)], np.float64)
    assert overlap_of_smaller(box, suv)[0, 0] >= 0.5, (box, suv)
