"""`roadview process` and the CLI's handling of bad input."""

from __future__ import annotations

import json
import re
import subprocess
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from tests.helpers import assert_one_line_error, count_frames, process_clip, read_record, run_cli


def test_help_lists_the_commands() -> None:
    result = run_cli("--help")
    assert result.returncode == 0
    for command in ("calibrate", "process", "evaluate"):
        assert command in result.stdout


def test_process_video_keeps_frames_size_rate_and_writes_a_record(
    test_video: Path, tmp_path: Path
) -> None:
    out, record = tmp_path / "out.mp4", tmp_path / "out.jsonl"
    result = run_cli("process", test_video, "-o", out, "--json", record)
    assert result.returncode == 0, result.stderr
    source_info, source_frames = count_frames(test_video)
    info, frames = count_frames(out)
    assert frames == source_frames == 38
    assert info.size == source_info.size and info.fps == source_info.fps
    assert info.has_audio == source_info.has_audio
    lines = read_record(record)
    assert [r["frame"] for r in lines] == list(range(38))
    assert lines[25]["time_s"] == 1.0
    assert all(set(r) >= {"frame", "time_s", "vehicles", "lane"} for r in lines)
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]


def test_process_video_undistorts(test_video: Path, tmp_path: Path) -> None:
    from app.sources import probe_video, read_frames
    from camera_cal import build_undistorter, default_calibration_path, load_calibration

    out = tmp_path / "undistorted.mp4"
    result = run_cli(
        "process", test_video, "-o", out, "--end", "0.2", "--no-lanes", "--no-vehicles"
    )
    assert result.returncode == 0, result.stderr
    source = next(read_frames(test_video, probe_video(test_video)))[150:]
    written = next(read_frames(out, probe_video(out))).astype(int)[150:]  # below the HUD panel
    undistort = build_undistorter(load_calibration(default_calibration_path()), (1280, 720))
    expected = undistort(next(read_frames(test_video, probe_video(test_video))))[150:]
    # The output is the undistorted frame up to codec noise, far from the raw frame.
    assert np.abs(written - expected.astype(int)).mean() < 2.5
    assert np.abs(written - source.astype(int)).mean() > 2 * np.abs(written - expected).mean()


def test_process_still(data_dir: Path, tmp_path: Path) -> None:
    out, record = tmp_path / "still.jpg", tmp_path / "still.jsonl"
    result = run_cli("process", data_dir / "test_images" / "test1.jpg", "-o", out, "--json", record)
    assert result.returncode == 0, result.stderr
    image = cv2.imread(str(out))
    assert image is not None and image.shape == (720, 1280, 3)
    assert json.loads(record.read_text())["frame"] == 0


def test_missing_input(tmp_path: Path) -> None:
    out = tmp_path / "out.mp4"
    result = run_cli("process", tmp_path / "nope.mp4", "-o", out)
    assert_one_line_error(result, "does not exist")
    assert not out.exists()


def test_not_a_video(tmp_path: Path) -> None:
    fake = tmp_path / "fake.mp4"
    fake.write_bytes(b"this is not a video at all" * 100)
    out = tmp_path / "out.mp4"
    result = run_cli("process", fake, "-o", out)
    assert_one_line_error(result, "not a video")
    assert not out.exists()


def test_a_recording_cut_off_before_its_index(test_video: Path, tmp_path: Path) -> None:
    """An MP4 whose index (written last) is missing, as a dashcam leaves it when it loses
    power: said so, and how it is mended, rather than "not a video"."""
    from app.sources import ffmpeg_binary

    whole, cut = tmp_path / "whole.mp4", tmp_path / "cut.mp4"
    subprocess.run(
        [ffmpeg_binary(), "-loglevel", "error", "-i", str(test_video), "-c", "copy", str(whole)],
        check=True,
    )  # the index at the end, as a camera writes it
    cut.write_bytes(whole.read_bytes()[:300_000])
    out = tmp_path / "out.mp4"
    assert_one_line_error(run_cli("process", cut, "-o", out), "moov atom", "untrunc")
    assert not out.exists()


def test_sound_without_a_picture(tmp_path: Path) -> None:
    """An audio file (a dashcam's sound exported alone) is told apart from a damaged video."""
    from app.sources import ffmpeg_binary

    sound = tmp_path / "sound.m4a"
    subprocess.run(
        [ffmpeg_binary(), "-loglevel", "error", "-f", "lavfi", "-i", "sine=d=1", str(sound)],
        check=True,
    )
    out = tmp_path / "out.mp4"
    assert_one_line_error(run_cli("process", sound, "-o", out), "sound but no picture")
    assert not out.exists()
    # With a cover picture, which ffmpeg lists as a video stream: it was processed as a
    # one-frame video at 90,000 frames a second.
    cover, song = tmp_path / "cover.png", tmp_path / "song.mp3"
    cv2.imwrite(str(cover), np.full((90, 160, 3), 128, np.uint8))
    subprocess.run(
        [ffmpeg_binary(), "-loglevel", "error", "-i", str(sound), "-i", str(cover),
         "-map", "0", "-map", "1", "-c:v", "mjpeg", "-disposition:v:0", "attached_pic",
         str(song)],
        check=True,
    )  # fmt: skip
    assert_one_line_error(run_cli("process", song, "-o", out), "sound but no picture")
    assert not out.exists()


def test_unwritable_output(test_video: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    out = blocker / "sub" / "out.mp4"
    result = run_cli("process", test_video, "-o", out)
    assert_one_line_error(result, "output folder")
    assert not out.exists()


def test_calibrate_empty_folder(tmp_path: Path) -> None:
    out = tmp_path / "cal.json"
    result = run_cli("calibrate", "--images", tmp_path, "--out", out)
    assert_one_line_error(result, "no chessboard images")
    assert not out.exists()


def test_calibrate_wrong_board(data_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "cal.json"
    result = run_cli(
        "calibrate", "--images", data_dir / "camera_cal", "--board", "12x9", "--out", out
    )
    assert_one_line_error(result, "12x9", "--board")
    assert not out.exists()


def test_calibrate_cli_writes_json(data_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "cal.json"
    result = run_cli("calibrate", "--images", data_dir / "camera_cal", "--out", out)
    assert result.returncode == 0, result.stderr
    assert "RMS reprojection error" in result.stdout
    assert json.loads(out.read_text())["image_size"] == [1280, 720]


def test_evaluate_classifier_cli(data_dir: Path, tmp_path: Path) -> None:
    import zipfile

    for kind in ("vehicles", "non-vehicles"):
        (tmp_path / kind).mkdir()
        with zipfile.ZipFile(data_dir / f"{kind}.zip") as archive:
            names = sorted(n for n in archive.namelist() if n.endswith(".png"))[::400]
            for name in names:
                image = cv2.imdecode(np.frombuffer(archive.read(name), np.uint8), cv2.IMREAD_COLOR)
                # Other sizes are resized to the model's patch size.
                cv2.imwrite(str(tmp_path / kind / Path(name).name), cv2.resize(image, (96, 96)))
    result = run_cli("evaluate-classifier", "--data", tmp_path, "--json")
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    assert scores["n_vehicles"] == 22 and scores["n_non_vehicles"] == 23
    assert scores["accuracy"] > 0.9


def test_corrupt_model_is_refused(test_video: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    result = run_cli("evaluate-classifier", "--data", tmp_path, "--model", bad)
    assert_one_line_error(result, "corrupt")


def test_a_missing_verifier_is_named(data_dir: Path, tmp_path: Path) -> None:
    still = data_dir / "test_images" / "test1.jpg"
    out = tmp_path / "o.jpg"
    result = run_cli("process", still, "-o", out, "--verifier", tmp_path / "none.npz")
    assert_one_line_error(result, "--verifier", "does not exist", "'none'")
    assert not out.exists()
    assert run_cli("process", still, "-o", out, "--verifier", "none").returncode == 0


def test_training_refuses_an_unknown_patch_size(tmp_path: Path) -> None:
    result = run_cli("train", "--patch", "48", "--out", tmp_path / "m.npz")
    assert_one_line_error(result, "--patch 48", "64 or 32")
    assert not (tmp_path / "m.npz").exists()


def test_camera_height_option(test_video: Path, tmp_path: Path) -> None:
    """--camera-height takes a dashcam's height in metres (it sizes the vehicle search: see
    test_vehicles); a height no dashcam has is refused in one line."""
    record = tmp_path / "r.jsonl"
    result = run_cli(
        "process",
        test_video,
        "-o",
        tmp_path / "o.mp4",
        "--json",
        record,
        "--end",
        "0.4",
        "--camera-height",
        "2.2",
    )
    assert result.returncode == 0, result.stderr
    assert len(record.read_text().splitlines()) == 10
    for height in ("0.1", "9"):
        bad = run_cli("process", test_video, "-o", tmp_path / "x.mp4", "--camera-height", height)
        assert_one_line_error(bad, f"--camera-height {height} m")
    assert not (tmp_path / "x.mp4").exists()


def test_lanes_read_from_another_height_suggest_the_camera_height(
    wild_dir: Path, test_video: Path, tmp_path: Path
) -> None:
    """The wet rural road's lanes read 0.67 of the tuned camera's width at a row (a camera
    1.5 times higher, or narrower lanes: the road does not tell): the vehicle windows stay sized
    for the tuned camera, and `process` says what height the lanes imply and how to state it.
    Told the height, or on the tuned camera's own footage, it says nothing of it."""
    from app.mounting import camera_height_note

    rural = wild_dir / "rural_2lane_wet.mp4"
    runs = {
        name: run_cli("process", video, "-o", tmp_path / f"{name}.mp4", "--end", "3", *extra)
        for name, video, extra in (
            ("untold", rural, ("--calibration", "none")),
            ("told", rural, ("--calibration", "none", "--camera-height", "1.9")),
            ("tuned", test_video, ()),
        )
    }
    assert all(r.returncode == 0 for r in runs.values()), {k: r.stderr for k, r in runs.items()}
    notes = {name: r.stdout + r.stderr for name, r in runs.items()}
    # The height its lanes imply (1.24 m over the scale they read, 0.67-0.69 in its first 3 s).
    implied = re.search(r"pass --camera-height ([\d.]+)", notes["untold"])
    assert implied and 1.7 <= float(implied.group(1)) <= 2.0, notes["untold"]
    assert "--camera-height" not in notes["told"] + notes["tuned"]
    # The note's direction and height follow the scale.
    assert camera_height_note(1.0, 1.24, 3.7) is None
    higher, lower = camera_height_note(0.62, 1.24, 3.7), camera_height_note(1.24, 1.24, 3.7)
    assert higher is not None and "2.0 m over" in higher and "mounted higher" in higher
    assert lower is not None and "1.0 m over" in lower and "mounted lower" in lower


def test_a_camera_looking_off_the_road_is_told_which_way(
    wild_dir: Path, test_video: Path, tmp_path: Path
) -> None:
    """The wet rural road vanishes 10 % of the width right of its picture's middle (its camera
    looks left of the road): `process` says so, and which side is seen less far. The shipped
    camera's clip (its road within 1.3 % of the middle) hears nothing of it."""
    from app.mounting import aim_note

    rural = wild_dir / "rural_2lane_wet.mp4"
    untold = run_cli(
        "process", rural, "-o", tmp_path / "r.mp4", "--end", "3", "--calibration", "none"
    )
    tuned = run_cli("process", test_video, "-o", tmp_path / "t.mp4")
    assert untold.returncode == 0 and tuned.returncode == 0, untold.stderr + tuned.stderr
    said = re.search(
        r"runs towards a point (\d+)% of the width (\w+) of", untold.stdout + untold.stderr
    )
    assert said and 8 <= int(said.group(1)) <= 13 and said.group(2) == "right", untold.stdout
    assert "camera looks left of the road" in untold.stdout + untold.stderr
    assert "runs towards a point" not in tuned.stdout + tuned.stderr
    # Within a bend's few per cent of the middle, or not found: nothing to say.
    assert aim_note(0.03) is None and aim_note(None) is None
    left = aim_note(-0.14)
    assert left is not None and "14% of the width left" in left and "looks right" in left


@pytest.mark.slow
def test_a_camera_mounted_askew_is_levelled_with_roll(data_dir: Path, tmp_path: Path) -> None:
    """project_cut_1 as a camera turned 3 degrees anticlockwise about its axis films it (each
    frame turned about the lens's principal point). Untold, the level vehicle bands cross the
    tilted road: fewer of its cars are found, and boxed worse (against the labels turned
    alike); with `--roll 3` the frames are levelled as they are undistorted, and the cars are
    found where the labels of the level clip have them (precision >= 0.95, recall as the
    clip's own), the lane too. A roll no mounted dashcam has is refused in one line, and
    nothing is written."""
    from app.evaluate import evaluate, load_labels
    from app.reframe import turned_labels
    from app.sinks import VideoSink
    from app.sources import probe_video, read_frames
    from camera_cal import default_calibration_path, load_calibration
    from camera_cal.undistort import scaled_camera_matrix

    video = data_dir / "videos" / "project_cut_1.mp4"
    info = probe_video(video)
    centre = scaled_camera_matrix(load_calibration(default_calibration_path()), info.size)[:2, 2]
    about = (float(centre[0]), float(centre[1]))
    turn = cv2.getRotationMatrix2D(about, 3.0, 1.0)
    clip = tmp_path / "askew.mp4"
    with VideoSink(clip, info.size, info.fps, preset="medium") as sink:
        for frame in read_frames(video, info):
            sink.write(np.ascontiguousarray(cv2.warpAffine(frame, turn, info.size)))
    level = load_labels(data_dir / "labels" / "project_cut_1.json")
    turned = turned_labels(level, dict.fromkeys(level, 3.0), info.size, about)
    scores = {}
    for roll, truth in (("0", turned), ("3", level)):
        folder = tmp_path / roll
        folder.mkdir()
        record = folder / "r.jsonl"
        result = run_cli("process", clip, "-o", folder / "o.mp4", "--json", record, "--roll", roll)
        assert result.returncode == 0, result.stderr
        scores[roll] = evaluate(truth, read_record(record))
    told, untold = scores["3"]["vehicles"]["iou_0.5"], scores["0"]["vehicles"]["iou_0.5"]
    assert told["precision"] >= 0.95 and told["recall"] >= 0.4, scores
    assert told["true_positives"] >= 1.4 * untold["true_positives"], scores
    assert told["mean_iou"] >= untold["mean_iou"] + 0.1, scores
    assert scores["3"]["lane"]["share_within_20px"] >= 0.99, scores
    out = tmp_path / "x.mp4"
    assert_one_line_error(run_cli("process", clip, "-o", out, "--roll", "90"), "--roll 90")
    assert not out.exists()


def _turned_runs(
    video: Path, folder: Path, turn: float
) -> dict[str, tuple[list[dict[str, Any]], str]]:
    """`video` undistorted and turned `turn` degrees anticlockwise about its centre, run without
    a calibration untold ("read") and told `--roll 0` ("left"), and undistorted level
    ("level"): each run's record and what `process` said."""
    from app.reframe import Framing, write_reframed
    from camera_cal import default_calibration_path, load_calibration

    calibration = load_calibration(default_calibration_path())
    runs: dict[str, tuple[list[dict[str, Any]], str]] = {}
    for name, angle, extra in (
        ("read", turn, ()),
        ("left", turn, ("--roll", "0")),
        ("level", 0.0, ()),
    ):
        clip = folder / f"{name}.mp4"
        write_reframed(video, Framing(name, roll=angle), clip, calibration)
        record = folder / f"{name}.jsonl"
        result = run_cli(
            "process", clip, "-o", folder / f"{name}_out.mp4", "--json", record,
            "--calibration", "none", *extra,
        )  # fmt: skip
        assert result.returncode == 0, result.stderr
        runs[name] = (read_record(record), result.stdout + result.stderr)
    return runs


def _levelled(runs: dict[str, tuple[list[dict[str, Any]], str]]) -> tuple[list[int], float]:
    """The frames of the untold run ("read") that were levelled, checked to run from one frame
    to the end, and the one turn they were levelled by."""
    rows = runs["read"][0]
    levelled = [r["frame"] for r in rows if "roll_deg" in r]
    assert levelled and levelled == list(range(levelled[0], len(rows))), levelled
    (roll,) = {r["roll_deg"] for r in rows if "roll_deg" in r}
    return levelled, roll


def _turned_scores(
    runs: dict[str, tuple[list[dict[str, Any]], str]], labels: Path, turn: float
) -> tuple[dict[str, float], dict[str, float]]:
    """The vehicles' scores at IoU 0.5 of the untold run and of the one told `--roll 0`, against
    the `labels` turned by what each frame kept of the `turn`."""
    from app.evaluate import evaluate, load_labels
    from app.reframe import turned_labels

    level = load_labels(labels)
    scores = []
    for name in ("read", "left"):
        frames = runs[name][0]
        left = {int(r["frame"]): turn - float(r.get("roll_deg", 0.0)) for r in frames}
        truth = turned_labels(level, left, (1280, 720))
        scores.append(evaluate(truth, frames)["vehicles"]["iou_0.5"])
    return scores[0], scores[1]


@pytest.mark.slow
def test_a_turned_picture_is_levelled_by_its_vehicles_rear_edges(
    data_dir: Path, tmp_path: Path
) -> None:
    """test_video turned 3 degrees about its centre and run without a calibration, untold: the
    rear edges of its two cars agree on the turn within a degree by 1 s, the frames from the
    next one on are levelled by it (the record's `roll_deg`, the same in every frame from there
    on) and `process` says so and how to state it. Levelled, the cars' distances are the level
    copy's within 5 % (left turned, as with `--roll 0`, they read a fifth farther), and against
    the labels turned as each frame was left, as many boxes are found, as precisely. Stated
    (`--roll 0`), the turn stands and `process` says what turn the edges read instead; the
    clip level reads no turn and is told nothing."""
    from vehicles.detections import iou_matrix

    runs = _turned_runs(data_dir / "videos" / "test_video.mp4", tmp_path, 3.0)
    said = runs["read"][1]
    levelled, roll = _levelled(runs)
    assert levelled[0] <= 25 and 2.0 <= roll <= 4.0, (levelled[0], roll)
    assert f"turned {roll:.1f} degrees anticlockwise" in said and f"--roll {roll:g}" in said, said

    def distance_ratio(name: str) -> float:
        """The median over the levelled frames' vehicles of their distance in run `name` over
        the same vehicle's in the level copy (boxes matched at IoU 0.5)."""
        ratios = []
        for framed, plain in zip(runs[name][0], runs["level"][0], strict=True):
            if framed["frame"] < levelled[0] or not framed["vehicles"] or not plain["vehicles"]:
                continue
            overlap = iou_matrix(
                np.array([v["box"] for v in framed["vehicles"]]),
                np.array([v["box"] for v in plain["vehicles"]]),
            )
            for i, j in enumerate(overlap.argmax(axis=1)):
                if overlap[i, j] >= 0.5:
                    d = framed["vehicles"][i]["distance_m"], plain["vehicles"][j]["distance_m"]
                    ratios.append(d[0] / d[1])
        assert len(ratios) >= 20, name
        return float(np.median(ratios))

    assert abs(distance_ratio("read") - 1) < 0.05 and distance_ratio("left") > 1.1
    read, untold = _turned_scores(runs, data_dir / "labels" / "test_video.json", 3.0)
    assert read["true_positives"] >= untold["true_positives"], (read, untold)
    assert read["precision"] >= untold["precision"] and read["mean_iou"] >= 0.75, read
    for name in ("left", "level"):
        frames, said = runs[name]
        assert not any("roll_deg" in r for r in frames) and "picture is turned" not in said
    said = runs["left"][1]
    read_instead = re.search(r"stated --roll 0, .* a turn of ([-\d.]+) degrees", said)
    assert read_instead and 2.0 <= float(read_instead.group(1)) <= 4.0, said
    assert "--roll" not in runs["level"][1]


@pytest.mark.slow
def test_a_turned_picture_is_levelled_by_its_lane_lines(data_dir: Path, tmp_path: Path) -> None:
    """project_cut_1 (four lanes: its car in the left one, dashed lines on its right) turned 3
    degrees clockwise and run without a calibration, untold: its cars give no lean (oncoming
    over the median, or cut by the picture's side), but its lane lines, spaced so that two
    threes of them agree on the turn, read it within a degree by 2 s; the frames from there on
    are levelled (the record's `roll_deg`), `process` says the lane lines read it, and more of
    its cars are found than left turned (`--roll 0`), as precisely. The clip level reads no
    turn and is told nothing."""
    runs = _turned_runs(data_dir / "videos" / "project_cut_1.mp4", tmp_path, -3.0)
    said = runs["read"][1]
    levelled, roll = _levelled(runs)
    assert levelled[0] <= 50 and -4.0 <= roll <= -2.0, (levelled[0], roll)
    assert f"turned {-roll:.1f} degrees clockwise (the lane lines" in said, said
    read, untold = _turned_scores(runs, data_dir / "labels" / "project_cut_1.json", -3.0)
    assert read["true_positives"] >= untold["true_positives"] + 5, (read, untold)
    assert read["precision"] >= 0.95 and read["mean_iou"] >= 0.75, read
    frames, said = runs["level"]
    assert not any("roll_deg" in r for r in frames) and "picture is turned" not in said


@pytest.mark.slow
def test_a_turned_picture_is_levelled_by_its_roads_motion(data_dir: Path, tmp_path: Path) -> None:
    """project_cut_1 turned 3 degrees anticlockwise and run without a calibration, untold: its
    cars give no lean and its lane lines beyond the next lane spread out of the picture, but
    its road moves faster on the side turned up: 50 frames' readings agree on the turn within a
    degree, the frames from there on are levelled (the record's `roll_deg`), `process` says
    the road read it, and more of its cars are found than left turned (`--roll 0`), as
    precisely. The clip level reads no turn and is told nothing."""
    runs = _turned_runs(data_dir / "videos" / "project_cut_1.mp4", tmp_path, 3.0)
    said = runs["read"][1]
    levelled, roll = _levelled(runs)
    assert levelled[0] <= 65 and 2.0 <= roll <= 4.5, (levelled[0], roll)
    assert f"turned {roll:.1f} degrees anticlockwise (the road moves faster" in said, said
    read, untold = _turned_scores(runs, data_dir / "labels" / "project_cut_1.json", 3.0)
    assert read["true_positives"] >= untold["true_positives"] + 10, (read, untold)
    assert read["precision"] >= untold["precision"] and read["mean_iou"] >= 0.75, read
    frames, said = runs["level"]
    assert not any("roll_deg" in r for r in frames) and "picture is turned" not in said


@pytest.fixture(scope="module")
def rear_copies(data_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """project_cut_2 undistorted as it is, and played backwards and mirrored: the road moving
    away with its sides swapped, as a rear camera films it."""
    from app.reframe import Framing, write_reframed
    from camera_cal import default_calibration_path, load_calibration

    folder = tmp_path_factory.mktemp("rear")
    calibration = load_calibration(default_calibration_path())
    video = data_dir / "videos" / "project_cut_2.mp4"
    copies = {"ahead": folder / "ahead.mp4", "rear": folder / "rear.mp4"}
    write_reframed(video, Framing("as is"), copies["ahead"], calibration)
    write_reframed(video, Framing("rear", reverse=True, mirror=True), copies["rear"], calibration)
    return copies


def _run(video: Path, folder: Path, *options: str) -> tuple[list[dict[str, Any]], str]:
    """`process` run without a calibration or vehicles: its record and what it said."""
    record = folder / f"{video.stem}{len(options)}.jsonl"
    result = run_cli(
        "process", video, "-o", folder / "o.mp4", "--json", record, "--calibration", "none",
        "--no-vehicles", *options,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return read_record(record), result.stdout + result.stderr


def test_a_rear_cameras_footage_reads_the_speed_of_the_road_moving_away(
    rear_copies: dict[str, Path], tmp_path: Path
) -> None:
    """Played backwards, the road moves away from the camera as from a rear one: after 0.4 s
    the record says so (`facing`), the speed is the road's, as at the same moment ahead, and
    `process` tells the user how to state it. Stated (`--facing rear`), it is so from the start
    and nothing needs saying; a way no camera looks is refused in one line. (The copy starts on
    the pale concrete the clip ends on: its first horizon stands at frame 10, where it took 39
    before edges were looked for at 0.6 of their strength; see test_scene.)"""
    ahead, _ = _run(rear_copies["ahead"], tmp_path)
    rows, said = _run(rear_copies["rear"], tmp_path)
    assert next(r["frame"] for r in rows if r["vanishing_x"] is not None) <= 15
    assert not any("facing" in r for r in ahead), "a front camera read as a rear one"
    facing = [r["frame"] for r in rows if r.get("facing") == "rear"]
    assert facing and facing[0] <= 20 and facing == list(range(facing[0], len(rows)))
    count = len(ahead)
    ratios = [
        r["speed_kmh"] / ahead[count - 1 - r["frame"]]["speed_kmh"]
        for r in rows
        if r.get("speed_kmh") and ahead[count - 1 - r["frame"]].get("speed_kmh")
    ]
    # Within 8 %: the facts read the horizon as estimated, and played backwards the same frames'
    # horizon reads 2.4-5.6 rows (of 720) higher than ahead (416-418 against 420-421).
    assert len(ratios) >= count - 25 and abs(float(np.median(ratios)) - 1) < 0.08, ratios
    assert "rear camera" in said and "--facing rear" in said, said
    stated, said = _run(rear_copies["rear"], tmp_path, "--facing", "rear")
    assert all(r.get("facing") == "rear" for r in stated)
    # Its speed as soon as the road's motion is read: 0.4 s sooner.
    first = next(r["frame"] for r in rows if r.get("speed_kmh"))
    assert next(r["frame"] for r in stated if r.get("speed_kmh")) <= first - 5
    assert "rear camera" not in said
    mirrored, _ = _run(rear_copies["rear"], tmp_path, "--facing", "rear-mirrored")
    assert all(r.get("facing") == "rear-mirrored" for r in mirrored)
    bad = run_cli("process", rear_copies["rear"], "-o", tmp_path / "x.mp4", "--facing", "up")
    assert_one_line_error(bad, "--facing up", "rear-mirrored")


def test_a_stated_facing_the_road_contradicts_is_told(
    rear_copies: dict[str, Path], tmp_path: Path
) -> None:
    """A rear camera's file stated to face forwards, or a front camera's stated to face
    backwards: the stated way stands (no speed is read against it), and `process` says that
    the road moves the other way and what to pass; told the right way, nothing is said."""
    for video, stated, moves in (
        (rear_copies["rear"], "front", "moves away"),
        (rear_copies["ahead"], "rear", "comes towards"),
    ):
        rows, said = _run(video, tmp_path, "--facing", stated)
        assert f"--facing {stated}" in said and moves in said, said
        assert sum(1 for r in rows if r.get("speed_kmh")) <= len(rows) // 10, rows
    _, said = _run(rear_copies["ahead"], tmp_path, "--facing", "front")
    assert "--facing" not in said, said


@pytest.fixture(scope="module")
def narrow_copies(data_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """project_cut_2 undistorted as it is, and its narrower view (the middle 80 % enlarged: a
    lens 1.25 times longer) as it is and tagged with that lens's focal length, as a phone tags
    its videos."""
    from app.reframe import Framing, tagged_lens_framing, write_reframed
    from camera_cal import default_calibration_path, load_calibration

    folder = tmp_path_factory.mktemp("lens")
    calibration = load_calibration(default_calibration_path())
    video = data_dir / "videos" / "project_cut_2.mp4"
    tagged = tagged_lens_framing((1280, 720), calibration)
    copies = {name: folder / f"{name}.mp4" for name in ("as is", "narrow", "tagged")}
    write_reframed(video, Framing("as is"), copies["as is"], calibration)
    write_reframed(video, replace(tagged, focal_mm=None), copies["narrow"], calibration)
    write_reframed(video, tagged, copies["tagged"], calibration)
    return copies


def test_a_lens_stated_or_tagged_gives_its_distances_and_speed(
    narrow_copies: dict[str, Path], tmp_path: Path
) -> None:
    """A lens 1.25 times longer than the shipped one's, not calibrated: taken for the shipped
    lens, its distances and speed read about 0.8 of the clip's. Its focal length in 35 mm
    terms, tagged as a phone tags its videos or stated (`--focal-length`), gives them within
    6 %; tagged or stated alike (the shipped calibration left out, as for another camera, and
    said so; the record's `focal_mm` says it). A lens no camera has, or one beside a
    calibration file, is refused in one line."""
    from app.reframe import distance_ratios, speed_ratios, tagged_lens_framing
    from app.sources import probe_video
    from camera_cal import default_calibration_path, load_calibration

    def run(video: Path, *options: str) -> tuple[list[dict[str, Any]], str]:
        record = tmp_path / f"{video.stem}{len(options)}.jsonl"
        result = run_cli("process", video, "-o", tmp_path / "o.mp4", "--json", record, *options)
        assert result.returncode == 0, result.stderr
        return read_record(record), result.stderr

    framing = tagged_lens_framing((1280, 720), load_calibration(default_calibration_path()))
    assert probe_video(narrow_copies["tagged"]).focal_mm == framing.focal_mm
    reference, _ = run(narrow_copies["as is"], "--calibration", "none")

    def ratios(rows: list[dict[str, Any]]) -> tuple[float, float]:
        distances = distance_ratios(reference, rows, framing, (1280, 720))
        speeds = speed_ratios(reference, rows, framing)
        assert len(distances) >= 30 and len(speeds) >= 40, (len(distances), len(speeds))
        return float(np.median(distances)), float(np.median(speeds))

    plain, _ = run(narrow_copies["narrow"], "--calibration", "none")
    assert all(r < 0.85 for r in ratios(plain)), ratios(plain)
    tagged, said = run(narrow_copies["tagged"])
    assert all(abs(r - 1) < 0.06 for r in ratios(tagged)), ratios(tagged)
    assert "as a phone tags it" in said and "without its calibration" in said, said
    stated, said = run(narrow_copies["narrow"], "--focal-length", str(framing.focal_mm))
    assert "--focal-length" in said and "without its calibration" in said, said
    assert [r["vehicles"] for r in stated] == [r["vehicles"] for r in tagged]
    assert [r["speed_kmh"] for r in stated] == [r["speed_kmh"] for r in tagged]
    # The record says which lens gave the distances (a report's thumbnails follow it).
    assert {r.get("focal_mm") for r in stated + tagged} == {framing.focal_mm}
    assert not any("focal_mm" in r for r in plain + reference)
    out = tmp_path / "x.mp4"
    bad = run_cli("process", narrow_copies["narrow"], "-o", out, "--focal-length", "3")
    assert_one_line_error(bad, "--focal-length 3", "35 mm")
    own = tmp_path / "own.json"
    own.write_text(default_calibration_path().read_text())
    bad = run_cli("process", narrow_copies["narrow"], "-o", out, "--focal-length", "30",
                  "--calibration", own)  # fmt: skip
    assert_one_line_error(bad, "--focal-length", "pass one")
    assert not out.exists()


def test_footage_that_never_shows_its_horizon_is_told(test_video: Path, tmp_path: Path) -> None:
    """An unknown camera's footage whose road never shows a vanishing point (here a grey, grainy
    picture): the stages wait for it and then work under the tuned camera's horizon, and
    `process` says so and what to pass; stated (`--horizon`), or found (test_video), nothing
    is said."""
    from app.sources import ffmpeg_binary

    grey = tmp_path / "grey.mp4"
    subprocess.run(
        [ffmpeg_binary(), "-loglevel", "error", "-f", "lavfi", "-i",
         "color=c=0x707070:s=640x360:d=4:r=25", "-vf", "noise=alls=10:allf=t", "-pix_fmt",
         "yuv420p", str(grey)],
        check=True,
    )  # fmt: skip
    out = tmp_path / "o.mp4"
    for video, options, told in (
        (grey, (), True),
        (grey, ("--horizon", "200"), False),
        (test_video, ("--no-vehicles",), False),
    ):
        result = run_cli("process", video, "-o", out, "--calibration", "none", *options)
        assert result.returncode == 0, result.stderr
        said = "vanishing point was never found" in result.stderr
        assert said == told and (not told or "--horizon Y" in result.stderr), result.stderr


def test_a_stills_exif_focal_length_sets_its_scale(data_dir: Path, tmp_path: Path) -> None:
    """A photo whose EXIF gives its lens's focal length in 35 mm terms (as a phone's does) is
    read as stated with `--focal-length`, with a note; untagged, the shipped lens is assumed
    and its vehicles read farther (26 mm is a wider lens than the shipped 31)."""
    from PIL import Image

    still = data_dir / "test_images" / "test1.jpg"
    tagged = tmp_path / "phone.jpg"
    with Image.open(still) as image:
        exif = Image.Exif()
        exif.get_ifd(0x8769)[0xA405] = 26
        image.save(tagged, exif=exif, quality=95)
    plain = tmp_path / "plain.jpg"
    with Image.open(still) as image:
        image.save(plain, quality=95)

    def run(image: Path, *options: str) -> tuple[list[float], str]:
        record = tmp_path / f"{image.stem}{len(options)}.jsonl"
        out = tmp_path / f"{image.stem}{len(options)}_out.jpg"
        result = run_cli("process", image, "-o", out, "--json", record, *options)
        assert result.returncode == 0, result.stderr
        (row,) = read_record(record)
        return [v["distance_m"] for v in row["vehicles"]], result.stderr

    read, said = run(tagged)
    assert "26 mm in 35 mm terms" in said and "without its calibration" in said, said
    assert read and run(plain, "--focal-length", "26")[0] == read
    assumed, said = run(plain, "--calibration", "none")
    assert "35 mm" not in said and len(assumed) == len(read)
    assert all(r < a for r, a in zip(sorted(read), sorted(assumed), strict=True)), (read, assumed)


def test_the_dashes_are_read_only_where_the_lens_is_not_known(
    test_video: Path, tmp_path: Path
) -> None:
    """The lane dashes give the road's length where the lens is assumed (the shipped camera's,
    its calibration applied by default, or none): not where a calibration the user named, a
    stated focal length or a phone's tag gives it, nor with `--dash-spacing none`. A spacing
    that is no number, or none a road has, is refused in one line; the record carries the
    scale and the spacing read (1 and null on a clip too short to read them)."""
    from app.drivers import lens_for
    from app.mounting import Mounting
    from camera_cal import default_calibration_path, load_calibration

    shipped = load_calibration(default_calibration_path())

    def read(calibration: Any, mounting: Mounting, tag: float | None, named: bool) -> Any:
        _, used = lens_for(calibration, mounting, (1280, 720), tag, "x", named, lambda m: None)
        return used.dash_spacing_m

    assert read(shipped, Mounting(), None, False) == 12.19  # the shipped lens, assumed
    assert read(None, Mounting(), None, True) == 12.19  # --calibration none
    assert read(None, Mounting(dash_spacing_m=9.0), None, True) == 9.0
    assert read(shipped, Mounting(), None, True) is None  # --calibration FILE
    assert read(shipped, Mounting(focal_mm=26.0), None, False) is None  # --focal-length
    assert read(shipped, Mounting(), 26.0, False) is None  # a phone's tag
    out = tmp_path / "o.mp4"
    for value, fragment in (("abc", "not a number"), ("100", "not a lane's dash spacing")):
        bad = run_cli("process", test_video, "-o", out, "--dash-spacing", value)
        assert_one_line_error(bad, f"--dash-spacing {value}", fragment)
        assert not out.exists()
    record = tmp_path / "r.jsonl"
    for option in ("none", "9"):
        result = run_cli("process", test_video, "-o", out, "--json", record, "--no-vehicles",
                         "--dash-spacing", option)  # fmt: skip
        assert result.returncode == 0, result.stderr
        rows = read_record(record)
        assert {(r["length_scale"], r["dash_m"]) for r in rows} == {(1.0, None)}


@pytest.mark.slow
def test_a_picture_stored_turned_is_stood_upright_with_rotate(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_2 stored turned a quarter clockwise (a phone's video that lost its tag), with
    the shipped calibration turned alike (the lens of the picture as stored): untold, it is
    read as a 720x1280 picture; with `--rotate 270` it is decoded upright, undistorted with the
    calibration turned back, and its cars and lane score against the clip's own labels as the
    clip does (precision >= 0.95, recall within 0.05, the lane within 20 px at 99 % of the
    points); the record says the turn. The same clip stored upside down (a camera mounted so),
    `--rotate 180`, alike. A turn that is no quarter turn is refused in one line."""
    from app.evaluate import evaluate, load_labels
    from app.sources import ffmpeg_binary
    from camera_cal import default_calibration_path, load_calibration, save_calibration, turned

    video = data_dir / "videos" / "project_cut_2.mp4"
    labels = load_labels(data_dir / "labels" / "project_cut_2.json")
    shipped = load_calibration(default_calibration_path())
    level = process_clip(video, tmp_path)
    own = evaluate(labels, level)["vehicles"]["iou_0.5"]
    for filters, stored_turn, rotate in (
        ("transpose=clock", 90, "270"),
        ("hflip,vflip", 180, "180"),
    ):
        clip = tmp_path / f"stored_{stored_turn}.mp4"
        command = [ffmpeg_binary(), "-loglevel", "error", "-i", str(video), "-vf", filters,
                   "-c:v", "libx264", "-crf", "16", str(clip)]  # fmt: skip
        subprocess.run(command, check=True)
        lens = tmp_path / f"lens_{stored_turn}.json"
        save_calibration(turned(shipped, stored_turn), lens)
        folder = tmp_path / rotate
        folder.mkdir()
        rows = process_clip(clip, folder, "--calibration", str(lens), "--rotate", rotate)
        assert {r["rotate_deg"] for r in rows} == {int(rotate)}
        assert {tuple(r["size"]) for r in rows} == {(1280, 720)}
        scores = evaluate(labels, rows)
        told = scores["vehicles"]["iou_0.5"]
        assert told["precision"] >= 0.95, scores
        assert told["recall"] >= own["recall"] - 0.05, scores
        assert scores["lane"]["share_within_20px"] >= 0.99, scores
    (tmp_path / "untold").mkdir()
    untold = process_clip(tmp_path / "stored_90.mp4", tmp_path / "untold", "--calibration", "none")
    assert {tuple(r["size"]) for r in untold} == {(720, 1280)}
    assert all("rotate_deg" not in r for r in untold)
    out = tmp_path / "x.mp4"
    result = run_cli("process", video, "-o", out, "--rotate", "45")
    assert_one_line_error(result, "--rotate 45", "quarter turn")
    assert not out.exists()


def test_a_still_stored_upside_down_is_stood_upright_with_rotate(
    data_dir: Path, tmp_path: Path
) -> None:
    """A still stored upside down, its lens's calibration turned alike, `--rotate 180`: the
    record is the upright still's (the same boxes and lane within a pixel) and says the turn."""
    from camera_cal import default_calibration_path, load_calibration, save_calibration, turned

    still = data_dir / "test_images" / "test6.jpg"
    stored = tmp_path / "upside_down.png"
    picture = cv2.imread(str(still))
    assert picture is not None
    cv2.imwrite(str(stored), picture[::-1, ::-1])
    lens = tmp_path / "lens.json"
    save_calibration(turned(load_calibration(default_calibration_path()), 180), lens)
    runs: dict[str, dict[str, Any]] = {}
    for name, source, options in (
        ("upright", still, ()),
        ("turned", stored, ("--calibration", lens, "--rotate", "180")),
    ):
        record = tmp_path / f"{name}.jsonl"
        out = tmp_path / f"{name}.png"
        result = run_cli("process", source, "-o", out, "--json", record, *options)
        assert result.returncode == 0, result.stderr
        (runs[name],) = read_record(record)
    upright, turned_row = runs["upright"], runs["turned"]
    assert turned_row["rotate_deg"] == 180 and "rotate_deg" not in upright
    assert turned_row["size"] == upright["size"]
    boxes = [np.array([v["box"] for v in r["vehicles"]]).reshape(-1, 4) for r in runs.values()]
    assert len(boxes[0]) >= 1 and boxes[0].shape == boxes[1].shape
    assert np.abs(boxes[0] - boxes[1]).max() <= 1.0
    for side in ("left", "right"):
        lines = [np.array(r["lane"][side]) for r in runs.values()]
        assert np.abs(lines[0] - lines[1]).max() <= 1.0
