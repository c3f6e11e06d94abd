"""Re-framed clips and labels: the picture and its labels move together, and roadview holds on
framings of the labelled clips it was not tuned on (horizon moved, bars, another size)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.evaluate import FrameLabels, LabelledVehicle, iou, load_labels_document
from app.reframe import (
    MONOCHROME_FRAMING,
    REAR_FRAMINGS,
    WIDE_LENS_FRAMING,
    Framing,
    distance_ratios,
    dusk_framings,
    framing_scores,
    framing_table,
    offset_shifts,
    pooled,
    reframe_image,
    reframe_labels,
    retime_labels,
    standard_framings,
    turned_labels,
    upright_framing,
    write_reframed,
)
from app.sinks import VideoSink
from app.sources import probe_video, read_frames
from camera_cal import build_undistorter, default_calibration_path, load_calibration

# The aim, pooled over the three clips (see the README's table).
PRECISION = 0.95
RECALL_DROP = 0.05
MEAN_IOU = 0.75
LANE_WITHIN = 0.99
DISTANCE_DRIFT = 0.05  # median distance of the same vehicles (and speed), re-framed over as it is
OFFSET_DRIFT_M = 0.05  # median shift of the lane offset, re-framed against as it is


def _labels(box: list[int], lane: dict[str, int]) -> dict[str, Any]:
    return {
        "clip": "synthetic",
        "frames": 1,
        "keyframes": {"0": {"vehicles": [{"id": 1, "box": box}], "lane": {"left": lane}}},
    }


@pytest.mark.parametrize(
    "framing",
    [
        *standard_framings((1280, 720)),
        upright_framing((1280, 720)),
        *dusk_framings((1280, 720)),
        *REAR_FRAMINGS,
        WIDE_LENS_FRAMING,
        MONOCHROME_FRAMING,
    ],
    ids=lambda f: f.name,
)
def test_labels_move_with_the_picture(framing: Framing) -> None:
    """A white box and a white lane dot drawn where the labels say are found, after re-framing
    the picture, where the re-framed labels say (within a pixel and a half)."""
    frame = np.zeros((720, 1280, 3), np.uint8)
    box = [500, 400, 700, 520]
    frame[400:520, 500:700] = 255
    frame[596:605, 376:385] = 255  # the lane point (380, 600)
    moved = reframe_image(frame, framing)
    if framing.roll_stated:  # roadview is told: it levels the picture, where the labels stay
        size = framing.output_size((1280, 720))
        moved = build_undistorter(None, size, framing.roll_stated)(moved)
    labels = reframe_labels(_labels(box, {"600": 380}), framing, (1280, 720))
    keyframe = labels["keyframes"]["0"]
    assert moved.shape[:2][::-1] == framing.output_size((1280, 720))
    (vehicle,) = keyframe["vehicles"]
    # White is as light as the framing's light lets it be (dusk: 0.4 of 255).
    assert moved.max() == round(255 * framing.light)
    white = np.argwhere(moved[..., 0] > 127 * framing.light)
    top_part = white[white[:, 0] < min(int(vehicle["box"][3]) + 2, moved.shape[0])]
    ys, xs = top_part[:, 0], top_part[:, 1]
    in_box = (xs < vehicle["box"][2] + 2) & (ys < vehicle["box"][3] + 2)
    found = [xs[in_box].min(), ys[in_box].min(), xs[in_box].max() + 1, ys[in_box].max() + 1]
    np.testing.assert_allclose(found, vehicle["box"], atol=1.5)
    # A mirrored picture's left line is the right one.
    side = "right" if framing.mirror else "left"
    assert not keyframe["lane"].get("left" if framing.mirror else "right")
    (row, x), *_ = keyframe["lane"][side].items()
    assert moved[int(row), round(x)].max() > 127 * framing.light
    assert not vehicle["ignore"]


def test_a_vehicle_cut_by_the_crop_is_ignored_and_one_outside_dropped() -> None:
    framing = Framing("right half", crop=(640, 0, 1280, 720))
    labels = reframe_labels(
        {
            "keyframes": {
                "0": {
                    "vehicles": [
                        {"id": 1, "box": [560, 400, 700, 480]},  # 60 of 140 px still shown
                        {"id": 2, "box": [100, 400, 300, 480]},  # gone
                        {"id": 3, "box": [800, 400, 900, 480]},
                    ]
                }
            }
        },
        framing,
        (1280, 720),
    )
    vehicles = {v["id"]: v for v in labels["keyframes"]["0"]["vehicles"]}
    assert set(vehicles) == {1, 3}
    assert vehicles[1]["box"] == [0, 400, 60, 480] and vehicles[1]["ignore"]
    assert vehicles[3]["box"] == [160, 400, 260, 480] and not vehicles[3]["ignore"]


@pytest.mark.parametrize("turn", [-3.0, 0.7, 3.0])
def test_labels_turn_with_a_picture_as_roadview_left_it_turned(turn: float) -> None:
    """A white box and a white lane line, turned `turn` degrees as `reframe_image` turns a
    picture: the turned labels' box has the white's centre and lies inside its bounds (less
    half their growth: a car is no rectangle), the lane is where the white line crosses each
    labelled row; a frame left level keeps its labels."""
    frame = np.zeros((720, 1280, 3), np.uint8)
    frame[400:520, 500:700] = 255
    lane_only = np.zeros_like(frame)
    rows = range(470, 671, 40)
    for row in range(440, 700):  # x = 300 + (670 - row): the line leans left going up
        lane_only[row, 300 + (670 - row) - 3 : 300 + (670 - row) + 4] = 255
    labels = {
        0: FrameLabels(
            (LabelledVehicle(1, (500.0, 400.0, 700.0, 520.0), False),),
            {"left": {row: 300.0 + (670 - row) for row in rows}, "right": {}},
        ),
        1: FrameLabels((), {"left": {}, "right": {}}),
    }
    framing = Framing("turned", roll=turn)
    box_picture, lane_picture = reframe_image(frame, framing), reframe_image(lane_only, framing)
    moved = turned_labels(labels, {0: turn, 1: 0.0}, (1280, 720))
    assert moved[1] is labels[1]
    (vehicle,) = moved[0].vehicles
    white = np.argwhere(box_picture[..., 0] > 127)
    (y0, x0), (y1, x1) = white.min(axis=0), white.max(axis=0) + 1
    bx0, by0, bx1, by1 = vehicle.box
    assert abs((bx0 + bx1) / 2 - (x0 + x1) / 2) < 1.5 and abs((by0 + by1) / 2 - (y0 + y1) / 2) < 1.5
    assert x0 - 1 <= bx0 and bx1 <= x1 + 1 and y0 - 1 <= by0 and by1 <= y1 + 1
    assert bx1 - bx0 >= 200 - 1 and by1 - by0 >= 120 - 1
    lane = moved[0].lane["left"]
    assert len(lane) >= 4, lane
    for row, x in lane.items():
        xs = np.flatnonzero(lane_picture[row, :, 0] > 127)
        assert abs(x - xs.mean()) < 1.5, (row, x, xs.mean())


@pytest.mark.slow
def test_roadview_holds_on_reframed_clips(data_dir: Path) -> None:
    """The labelled clips re-framed (horizon 10 % up and down, a narrower view, 4:3, 21:9,
    black side bars, 960x540, 1920x1080, 640x360, half and twice the frame rate, mirrored, mirrored
    with `--traffic left`, turned 3 degrees with `--roll 3`, and cut off-centre by a tenth of
    the width, as a camera turned 3 degrees sideways sees the road, and by a twentieth, as one
    turned 1.5 degrees) and run without calibration, as footage of an unknown camera: pooled
    over the three clips, the vehicles, their distances, the speed, the lane and the camera's
    place in it stay close to the clips as they are (cut off-centre, the offset moved 0.30 m
    with the picture's middle: now within 2 cm; cut a little, 0.15 m read straight down the
    view, which is not placed for so small a turn: now within 1 cm)."""
    clips = [
        (data_dir / "videos" / f"{c}.mp4", data_dir / "labels" / f"{c}.json")
        for c in ("test_video", "project_cut_1", "project_cut_2")
    ]
    table = framing_table(clips, load_calibration(default_calibration_path()))
    plain = table.pop("as is")
    for name, row in table.items():
        # The same lens cropped, padded, resized or sampled at another rate: each vehicle is as
        # far, and the car as fast, as in the clip as it is (a narrower view is another lens).
        if name != "narrower view":
            assert abs(row["distance_ratio"] - 1) <= DISTANCE_DRIFT, (name, row)
            assert abs(row["speed_ratio"] - 1) <= DISTANCE_DRIFT, (name, row)
        assert abs(row["offset_shift_m"]) <= OFFSET_DRIFT_M, (name, row)
        # Mirrored, the median barrier stands on the right, where the classifier's
        # non-vehicles never showed it (their crops of it are of the left): its windows are
        # not boxed as their mirror images are not vehicles (0.936 before; README).
        assert row["precision"] >= PRECISION, (name, row)
        assert row["recall"] >= plain["recall"] - RECALL_DROP, (name, row, plain)
        assert row["mean_iou"] >= MEAN_IOU, (name, row)
        assert row["lane_within_20px"] >= LANE_WITHIN, (name, row)


@pytest.mark.slow
def test_monochrome_footage_is_read_by_the_grey_models(data_dir: Path, tmp_path: Path) -> None:
    """The labelled clips without their colour, as an infrared night camera films: the colour
    models found no vehicle in them (recall 0.000 on each). The scene finds them monochrome
    from the third sample of their picture on (frame 10), and the models trained on grey copies
    of the patches read them: pooled precision at the issue's 0.95, recall within 0.2 of the
    clips in colour (0.70), the lanes as in colour."""
    calibration = load_calibration(default_calibration_path())
    scores = []
    for k, clip in enumerate(("test_video", "project_cut_1", "project_cut_2")):
        video, labels = data_dir / "videos" / f"{clip}.mp4", data_dir / "labels" / f"{clip}.json"
        folder = tmp_path / str(k)
        folder.mkdir()
        scores.append(framing_scores(video, labels, MONOCHROME_FRAMING, folder, calibration))
        frames = scores[-1]["frames"]
        assert [bool(r.get("monochrome")) for r in frames] == [i >= 10 for i in range(len(frames))]
    row = pooled(scores)
    assert row["precision"] >= PRECISION, row
    assert row["recall"] >= 0.5, row
    assert row["lane_within_20px"] >= LANE_WITHIN, row


def _oncoming_car_fits(
    data_dir: Path, tmp_path: Path, framing: Framing
) -> tuple[list[float], dict[str, Any]]:
    """project_cut_1 so framed: the IoU of each box over its oncoming car (label 13) with the
    car's label, moved as the framing moves it, and the clip's scores."""
    video = data_dir / "videos" / "project_cut_1.mp4"
    labels = data_dir / "labels" / "project_cut_1.json"
    info = probe_video(video)
    calibration = load_calibration(default_calibration_path())
    scores = framing_scores(video, labels, framing, tmp_path, calibration)
    document = reframe_labels(json.loads(labels.read_text()), framing, info.size)
    truth = retime_labels(load_labels_document(document), framing, info.n_frames)
    fits: list[float] = []
    for record in scores["frames"]:
        shown = truth.get(int(record["frame"]), FrameLabels((), {})).vehicles
        for car in (v.box for v in shown if v.id == 13):
            overlaps = [iou(v["box"], car) for v in record.get("vehicles") or []]
            fits.extend(o for o in overlaps if o > 0.1)
    return fits, scores


def test_an_oncoming_car_at_half_the_frame_rate_is_boxed_where_it_is(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_1 at 12.5 fps: the oncoming car (label 13) crosses 40-60 px a frame, and each
    box on it is where the labels have it (IoU >= 0.5: 0.51-0.71 in 7 frames), and no box is
    false. Before the tracker's weights forgot as much a second at any rate, its box trailed it
    by 12-23 px (IoU 0.40-0.47: 3 false boxes, the half-rate row's precision 0.965)."""
    size = probe_video(data_dir / "videos" / "project_cut_1.mp4").size
    (half,) = (f for f in standard_framings(size) if f.rate == 0.5)
    fits, scores = _oncoming_car_fits(data_dir, tmp_path, half)
    assert len(fits) >= 3 and min(fits) >= 0.5, fits
    assert scores["vehicles"]["iou_0.5"]["false_positives"] == 0, scores["vehicles"]


def test_a_receding_car_seen_by_a_rear_camera_is_boxed_where_it_is(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_1 played backwards and mirrored, told `--facing rear`: the oncoming car
    (label 13) enters at the side and recedes, ever slower towards the vanishing point. Each box
    on it is on it (IoU >= 0.45; 0.50-0.75 in frames 43-52) and at most one box is false. Before
    a receding track slowed between frames and the car's side, seen leaving the picture's edge,
    was taken for speed, its box ran up to 40 px ahead of it (IoU down to 0.14; 6 false
    boxes)."""
    told = REAR_FRAMINGS[1]
    assert told.facing == "rear"
    fits, scores = _oncoming_car_fits(data_dir, tmp_path, told)
    assert sum(f >= 0.5 for f in fits) >= 8 and min(fits) >= 0.45, fits
    assert scores["vehicles"]["iou_0.5"]["false_positives"] <= 1, scores["vehicles"]


@pytest.mark.slow
def test_roadview_holds_on_a_rear_cameras_footage(data_dir: Path) -> None:
    """The labelled clips played backwards, as a rear camera films the road moving away, run
    without calibration: mirrored too (its file as its lens sees the road, the sides swapped)
    or not (its file saved mirrored, as a rear-view mirror shows it). The speed (once the road
    is read as moving away) and the distances are as at the same moments ahead. Told which of
    the two it is (`--facing rear`, `--facing rear-mirrored`), the vehicle search sees traffic
    keeping right as it was trained to; unaided too, each meets the framings' aims (the lane's
    too, since the horizon is read ahead: test_video played backwards had waited 12 frames for
    it; the unaided precision since windows stand by their mirror images)."""
    clips = [
        (data_dir / "videos" / f"{c}.mp4", data_dir / "labels" / f"{c}.json")
        for c in ("test_video", "project_cut_1", "project_cut_2")
    ]
    unaided, told, _, told_mirrored = REAR_FRAMINGS
    framings = [Framing("as is"), unaided, told, told_mirrored]
    table = framing_table(clips, load_calibration(default_calibration_path()), framings)
    plain = table.pop("as is")
    for name, row in table.items():
        assert abs(row["distance_ratio"] - 1) <= DISTANCE_DRIFT, (name, row)
        assert abs(row["speed_ratio"] - 1) <= DISTANCE_DRIFT, (name, row)
        assert row["mean_iou"] >= MEAN_IOU, (name, row)
        assert row["lane_within_20px"] >= LANE_WITHIN, (name, row)
        # Unaided, the swapped sides read as traffic keeping left: as the mirrored row.
        assert row["precision"] >= PRECISION, (name, row)
        assert row["recall"] >= plain["recall"] - RECALL_DROP, (name, row, plain)


def test_offset_shifts_pair_the_same_moment_across_framings() -> None:
    """The lane offset's shift is taken at the source frame each re-framed frame shows, with the
    sign flipped where mirrored (the camera is as far the other way), and only where both have a
    lane; none for a clip played backwards."""
    reference: list[dict[str, Any]] = [
        {"frame": 0, "lane": {"offset_m": 0.5}},
        {"frame": 1, "lane": {"offset_m": -0.2}},
        {"frame": 2, "lane": None},
    ]
    frames = [{"frame": k, "lane": {"offset_m": 0.1 * k}} for k in range(6)]
    doubled = offset_shifts(reference, frames, Framing("twice", rate=2.0))
    np.testing.assert_allclose(doubled, [-0.5, -0.4, 0.4, 0.5])
    mirrored = offset_shifts(reference, frames[:2], Framing("mirrored", mirror=True))
    np.testing.assert_allclose(mirrored, [0.5, -0.1])
    assert len(offset_shifts(reference, frames[:3], Framing("back", reverse=True))) == 0


def test_distance_ratios_pair_the_same_vehicle_across_framings() -> None:
    """A vehicle boxed in both records is paired through the framing's affine map; one seen in
    only one record is not."""
    framing = Framing("half", size=(640, 360))
    reference = [
        {"frame": 0, "vehicles": [{"box": [100, 400, 300, 500], "distance_m": 20.0}]},
        {"frame": 1, "vehicles": [{"box": [900, 400, 1100, 500], "distance_m": 30.0}]},
    ]
    frames = [
        {"frame": 0, "vehicles": [{"box": [50, 200, 150, 250], "distance_m": 22.0}]},
        {"frame": 1, "vehicles": [{"box": [50, 200, 150, 250], "distance_m": 10.0}]},
    ]
    ratios = distance_ratios(reference, frames, framing, (1280, 720))
    np.testing.assert_allclose(ratios, [1.1])


@pytest.mark.parametrize(
    ("rate", "reverse", "shown"),
    [
        (0.5, False, [0, 2, 4, 6, 8]),
        (2.0, False, [0, 0, 1, 1, 2, 2]),
        (1.0, True, [9, 8, 7, 6, 5, 4, 3, 2, 1, 0]),
        (0.5, True, [9, 7, 5, 3, 1]),
    ],
)
def test_another_frame_rate_drops_or_repeats_frames_with_their_labels(
    tmp_path: Path, rate: float, reverse: bool, shown: list[int]
) -> None:
    """Half the frame rate keeps every other frame, twice the rate shows each frame twice,
    played backwards the last frame comes first; the copy's rate says so, and each copied frame
    carries the labels of the frame it shows."""
    source = tmp_path / "counting.mp4"
    with VideoSink(source, (64, 48), 25.0, preset="medium") as sink:
        for k in range(10):
            sink.write(np.full((48, 64, 3), 20 * k + 10, np.uint8))  # the frame's index as grey
    framing = Framing("rate", rate=rate, reverse=reverse)
    copy = tmp_path / "copy.mp4"
    write_reframed(source, framing, copy, None)
    info = probe_video(copy)
    assert info.fps == pytest.approx(25.0 * rate)
    grey = [float(frame.mean()) for frame in read_frames(copy, info)]
    assert len(grey) == framing.frame_count(10) == int(10 * rate)
    np.testing.assert_allclose(grey[: len(shown)], [20 * k + 10 for k in shown], atol=3)
    labels = {
        k: FrameLabels((LabelledVehicle(k, (k, 0.0, k + 10.0, 10.0), False),), {})
        for k in range(10)
    }
    moved = retime_labels(labels, framing, 10)
    assert sorted(moved) == list(range(len(grey)))
    assert [moved[j].vehicles[0].id for j in range(len(shown))] == shown
