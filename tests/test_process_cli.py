"""`roadview process` and the CLI's handling of bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from tests.helpers import assert_one_line_error, count_frames, read_record, run_cli


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
