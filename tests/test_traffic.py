"""Traffic keeping left: the vehicle stage sees the frames mirrored, and its boxes come back."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import pytest

from app.evaluate import evaluate, load_labels_document
from app.reframe import Framing, reframe_labels, write_reframed
from app.traffic import KeepLeft, mirrored_boxes
from camera_cal import default_calibration_path, load_calibration
from tests.helpers import assert_one_line_error, process_clip, run_cli
from vehicles.detections import Detections
from vehicles.detector import VehicleDebug, VehicleDetector, VehicleResult


def test_a_mirrored_box_covers_what_the_mirror_image_shows_there() -> None:
    """A white block drawn at a box lies, in the picture flipped left to right, exactly at the
    mirrored box; mirroring twice gives the box back."""
    frame = np.zeros((48, 100, 3), np.uint8)
    box = np.array([[0.0, 10.0, 30.0, 40.0], [61.0, 5.0, 100.0, 20.0]])
    for x0, y0, x1, y1 in box.astype(int):
        frame[y0:y1, x0:x1] = 255
    flipped = cv2.flip(frame, 1)
    moved = mirrored_boxes(box, 100)
    np.testing.assert_array_equal(moved, [[70, 10, 100, 40], [0, 5, 39, 20]])
    for x0, y0, x1, y1 in moved.astype(int):
        assert (flipped[y0:y1, x0:x1] == 255).all()
    assert (flipped > 0).sum() == (frame > 0).sum()
    np.testing.assert_array_equal(mirrored_boxes(moved, 100), box)
    assert mirrored_boxes(np.zeros((0, 4)), 100).shape == (0, 4)


class _Recorder:
    """A vehicle stage that keeps what it was given and finds one car at `box`."""

    def __init__(self, box: list[float]) -> None:
        self.box = box
        self.seen: dict[str, Any] = {}
        self.reset_with: float | None = None

    def process(self, frame: np.ndarray, *args: Any) -> VehicleResult:
        self.seen = {"frame": frame.copy(), "args": args}
        heat = np.zeros((12, 25), np.float32)
        heat[:, :5] = 1.0  # the mirrored frame's left fifth
        boxes = np.array([self.box])
        debug = VehicleDebug((), heat, heat, Detections.from_boxes(boxes, np.ones(1)), 2.5, boxes)
        return VehicleResult(Detections.from_boxes(boxes, np.array([0.9]), np.array([7])), debug)

    def reset(self, fps: float | None = None) -> None:
        self.reset_with = fps


def test_keep_left_shows_the_stage_the_mirrored_frame_and_scene() -> None:
    """The stage reads the frame flipped, with the live box, the vanishing column and caption
    boxes mirrored (horizon, scale, ground scale, the road's grey and grain, and whether the
    picture is monochrome, as they are); the car it
    finds, its debug boxes and heat come back mirrored, its id and score unchanged."""
    frame = np.zeros((48, 100, 3), np.uint8)
    frame[:, :10] = 200  # a bright left edge
    recorder = _Recorder([10.0, 20.0, 30.0, 40.0])
    stage = KeepLeft(cast(VehicleDetector, recorder))
    found = stage.process(
        frame, 20.0, (5, 0, 90, 48), 45.0, 60.0, ((0, 0, 20, 8),), 0.8, 33.0, 0.7, True
    )
    np.testing.assert_array_equal(recorder.seen["frame"], cv2.flip(frame, 1))
    mirrored = (20.0, (10, 0, 95, 48), 45.0, 40.0, ((80, 0, 100, 8),), 0.8, 33.0, 0.7, True)
    assert recorder.seen["args"] == mirrored
    np.testing.assert_array_equal(found.detections.boxes, [[70.0, 20.0, 90.0, 40.0]])
    assert found.detections.ids.tolist() == [7] and found.detections.scores.tolist() == [0.9]
    assert found.debug is not None
    np.testing.assert_array_equal(found.debug.regions.boxes, [[70.0, 20.0, 90.0, 40.0]])
    np.testing.assert_array_equal(found.debug.vetoed, [[70.0, 20.0, 90.0, 40.0]])
    assert found.debug.frame_heat[:, -5:].all() and not found.debug.frame_heat[:, :-5].any()
    stage.reset(12.5)
    assert recorder.reset_with == 12.5


def test_an_unknown_traffic_side_is_refused_in_one_line(test_video: Path, tmp_path: Path) -> None:
    """`--traffic` takes right or left; anything else is one clear line, and nothing is written."""
    out = tmp_path / "o.mp4"
    result = run_cli("process", test_video, "-o", out, "--traffic", "middle")
    assert_one_line_error(result, "--traffic middle", "right or left")
    assert not out.exists()


@pytest.mark.slow
def test_traffic_keeping_left_is_found_as_well_as_traffic_keeping_right(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_2 mirrored (traffic keeping left, its median barrier on the right) and run
    with `--traffic left`: the boxes land on the mirrored labels (precision >= 0.95), at least
    as many cars are found as when roadview is not told, and no more false boxes. Not told, the
    barrier's windows are not boxed either: their mirror images are the barrier the model knows
    (precision >= 0.95: 1.000, 0.876 before windows had to stand by their mirror image)."""
    video, labels = (
        data_dir / "videos" / "project_cut_2.mp4",
        data_dir / "labels" / "project_cut_2.json",
    )
    framing = Framing("mirrored", mirror=True)
    clip = tmp_path / "mirrored.mp4"
    size = write_reframed(video, framing, clip, load_calibration(default_calibration_path()))
    truth = load_labels_document(reframe_labels(json.loads(labels.read_text()), framing, size))
    scores = {}
    for side in ("right", "left"):
        folder = tmp_path / side
        folder.mkdir()
        records = process_clip(clip, folder, "--calibration", "none", "--traffic", side)
        scores[side] = evaluate(truth, records)["vehicles"]["iou_0.5"]
    told, untold = scores["left"], scores["right"]
    assert told["precision"] >= 0.95 and untold["precision"] >= 0.95, scores
    assert told["true_positives"] >= untold["true_positives"], scores
    assert told["false_positives"] <= untold["false_positives"], scores
