"""`roadview process` and `debug` end to end: odd inputs, failures, composite, debug pictures."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.drivers import MONOCHROME_NOTE
from app.sources import ffmpeg_binary, probe_video, read_frames
from camera_cal import default_calibration_path
from tests.helpers import (
    assert_one_line_error,
    count_frames,
    interruptible,
    process_clip,
    read_record,
    run_cli,
)


@pytest.fixture(scope="module")
def clips(tmp_path_factory: pytest.TempPathFactory, test_video: Path) -> dict[str, Path]:
    """Short derived clips: other sizes, a grey one, a fade from black, a truncated file, an
    empty one."""
    folder = tmp_path_factory.mktemp("clips")
    out = {}
    # The 960x540 clip is longer: without a calibration the stages wait for the horizon first.
    # Square pixels throughout: scaled alone, 640x480 would keep the 16:9 picture in pixels
    # 4/3 as wide as tall (ffmpeg sets that), which is decoded back to 16:9.
    for name, size, seconds in (
        ("small", "640:360,setsar=1", "0.4"),
        ("wide960", "960:540,setsar=1", "1.2"),
        ("square", "640:480,setsar=1", "0.4"),
        ("grey", "640:360,setsar=1,hue=s=0", "0.4"),
        ("fade", "640:360,setsar=1,fade=in:0:8", "0.6"),
    ):
        out[name] = folder / f"{name}.mp4"
        subprocess.run(
            [
                ffmpeg_binary(),
                "-loglevel",
                "error",
                "-i",
                str(test_video),
                "-vf",
                f"scale={size}",
                "-t",
                seconds,
                str(out[name]),
            ],
            check=True,
        )
    whole = test_video.read_bytes()  # its index first, as a streaming copy has it
    out["truncated"] = folder / "truncated.mp4"
    out["truncated"].write_bytes(whole[:400_000])
    out["undecodable"] = folder / "undecodable.mp4"
    out["undecodable"].write_bytes(whole[:2_000])  # the index, no whole frame
    out["damaged"] = folder / "damaged.mp4"
    out["damaged"].write_bytes(whole[:400_000] + bytes(20_000) + whole[420_000:])
    out["empty"] = folder / "empty.mp4"
    out["empty"].write_bytes(b"")
    return out


def test_other_resolution_same_aspect_is_scaled(clips: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "o.mp4"
    result = run_cli("process", clips["small"], "-o", out)
    assert result.returncode == 0, result.stderr
    # Said, as most dashcams film 16:9: another camera's footage needs --calibration none.
    assert "1280x720 camera's calibration scaled" in result.stderr
    assert "--calibration none" in result.stderr
    assert "monochrome" not in result.stderr
    info, frames = count_frames(out)
    assert info.size == (640, 360) and frames == 10


def test_a_monochrome_video_is_told_of(clips: dict[str, Path], tmp_path: Path) -> None:
    """A grey copy (as an infrared night camera films): processed, with one note that its
    vehicles are read by the grey models; without the vehicle stage there is nothing to say."""
    result = run_cli("process", clips["grey"], "-o", tmp_path / "o.mp4")
    assert result.returncode == 0, result.stderr
    assert [line for line in result.stderr.splitlines() if "monochrome" in line] == [
        f"note: grey.mp4 is {MONOCHROME_NOTE}"
    ]
    quiet = run_cli("process", clips["grey"], "-o", tmp_path / "p.mp4", "--no-vehicles")
    assert quiet.returncode == 0 and "monochrome" not in quiet.stderr


def test_a_fade_from_black_is_not_monochrome(clips: dict[str, Path], tmp_path: Path) -> None:
    """A clip that fades in from black (a camera starting up, an edited video) has no colour
    in its first frames: it was told of as monochrome from its first frame."""
    result = run_cli("process", clips["fade"], "-o", tmp_path / "o.mp4")
    assert result.returncode == 0, result.stderr
    assert "monochrome" not in result.stderr


def test_other_camera_with_calibration_none(clips: dict[str, Path], tmp_path: Path) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli(
        "process", clips["wide960"], "-o", out, "--json", record, "--calibration", "none"
    )
    assert result.returncode == 0, result.stderr
    assert count_frames(out)[0].size == (960, 540)
    lanes = [r["lane"] for r in read_record(record)]
    # An unknown camera: the first frames wait for the footage's horizon (it stood in 10 here).
    found = [lane is not None for lane in lanes]
    assert True in found[:15] and all(found[found.index(True) :])
    # The lane is found at 960x540 as at 1280x720: left line in the left half, right in the right.
    assert lanes[-1]["left"][0][0] < 480 < lanes[-1]["right"][0][0]


def test_another_aspect_ratio_is_another_camera(clips: dict[str, Path], tmp_path: Path) -> None:
    """A 4:3 clip is not from the shipped 16:9 dashcam: by default it is processed without
    undistortion, with a note; a calibration the user names that does not fit is refused."""
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli("process", clips["square"], "-o", out, "--json", record)
    assert result.returncode == 0, result.stderr
    assert "not of the calibration's aspect ratio" in result.stderr
    assert "without undistortion" in result.stderr
    assert count_frames(out)[0].size == (640, 480)
    assert read_record(record)[0]["size"] == [640, 480]
    named = tmp_path / "named"
    named.mkdir()
    calibration = tmp_path / "dashcam.json"
    calibration.write_text(default_calibration_path().read_text())
    refused = run_cli(
        "process", clips["square"], "-o", named / "o.mp4", "--calibration", calibration
    )
    assert_one_line_error(refused, "aspect ratio", "--calibration none")
    assert not list(named.iterdir())


@pytest.mark.parametrize(
    ("clip", "fragment"), [("undecodable", "no frame of it decodes"), ("empty", "empty")]
)
def test_bad_videos(clips: dict[str, Path], tmp_path: Path, clip: str, fragment: str) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli("process", clips[clip], "-o", out, "--json", record)
    assert_one_line_error(result, fragment)
    assert not out.exists() and not record.exists()
    assert not list(tmp_path.iterdir())  # no temporary files left either


def test_a_file_cut_short_is_processed_up_to_the_cut(
    clips: dict[str, Path], test_video: Path, tmp_path: Path
) -> None:
    """A recording cut part-way (a dashcam losing power, a copy stopped) keeps its start: the
    frames that decode are processed as the whole file's are, and the note says what is lost."""
    record = tmp_path / "cut.jsonl"
    result = run_cli("process", clips["truncated"], "-o", tmp_path / "cut.mp4", "--json", record)
    assert result.returncode == 0, result.stderr
    assert "cut short (ffmpeg:" in result.stderr and "of the 1.5 s it states" in result.stderr
    cut = read_record(record)
    whole = process_clip(test_video, tmp_path, "--end", "1.0")
    assert 5 <= len(cut) < len(whole)
    assert cut == whole[: len(cut)]
    _, frames = count_frames(tmp_path / "cut.mp4")
    assert frames == len(cut)


def test_a_file_damaged_mid_way_is_processed_with_a_note(
    clips: dict[str, Path], test_video: Path, tmp_path: Path
) -> None:
    """Bytes lost in the middle: the frames are processed as ffmpeg decodes them, and the note
    says where lanes and vehicles may be misread."""
    record = tmp_path / "o.jsonl"
    result = run_cli("process", clips["damaged"], "-o", tmp_path / "o.mp4", "--json", record)
    assert result.returncode == 0, result.stderr
    assert "damaged (ffmpeg:" in result.stderr and "may be misread" in result.stderr
    assert "cut short" not in result.stderr
    # A frame that does not decode is filled with the one before: the frames keep their times.
    _, whole = count_frames(test_video)
    assert len(read_record(record)) == whole


def test_corrupt_calibration_and_model(clips: dict[str, Path], tmp_path: Path) -> None:
    bad_cal, bad_model = tmp_path / "cal.json", tmp_path / "model.npz"
    bad_cal.write_text('{"format_version": 1, "camera_matrix": "x"}')
    bad_model.write_bytes(b"PK\x03\x04 not really")
    out = tmp_path / "o.mp4"
    assert_one_line_error(
        run_cli("process", clips["small"], "-o", out, "--calibration", bad_cal), "calibration"
    )
    assert_one_line_error(
        run_cli("process", clips["small"], "-o", out, "--model", bad_model), "corrupt"
    )
    assert not out.exists()


def test_verbose_shows_the_traceback(tmp_path: Path) -> None:
    result = run_cli("--verbose", "process", tmp_path / "missing.mp4")
    assert result.returncode != 0 and "Traceback" in result.stderr


def test_ctrl_c_leaves_no_output(data_dir: Path, tmp_path: Path) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app",
            "process",
            str(data_dir / "videos" / "project_cut_2.mp4"),
            "-o",
            str(out),
            "--json",
            str(record),
        ],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=interruptible,
    )
    # Interrupt once frames are being written (a temporary record with some lines in it).
    deadline = time.time() + 60
    while time.time() < deadline and not any(
        p.stat().st_size > 0 for p in tmp_path.glob(".o.*.tmp.jsonl")
    ):
        time.sleep(0.01)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert not out.exists() and not record.exists()
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("kind", ["grey", "rgba", "odd", "tiny"])
def test_unusual_stills_are_processed(data_dir: Path, tmp_path: Path, kind: str) -> None:
    image = np.asarray(cv2.imread(str(data_dir / "test_images" / "test1.jpg")), np.uint8)
    made = {
        "grey": cv2.cvtColor(image, cv2.COLOR_BGR2GRAY),
        "rgba": cv2.cvtColor(image, cv2.COLOR_BGR2BGRA),
        "odd": cv2.resize(image, (641, 363)),
        "tiny": cv2.resize(image, (97, 61)),
    }[kind]
    source, out = tmp_path / f"{kind}.png", tmp_path / f"{kind}_out.png"
    cv2.imwrite(str(source), made)
    result = run_cli("process", source, "-o", out)
    assert result.returncode == 0, result.stderr
    written = cv2.imread(str(out))
    assert written is not None and written.shape[:2] == made.shape[:2]


def test_composite_draws_lane_and_boxes_where_the_record_says(
    data_dir: Path, tmp_path: Path
) -> None:
    source = data_dir / "test_images" / "test4.jpg"
    out, record = tmp_path / "o.png", tmp_path / "o.jsonl"
    assert run_cli("process", source, "-o", out, "--json", record).returncode == 0
    plain = tmp_path / "plain.png"
    assert run_cli("process", source, "-o", plain, "--no-lanes", "--no-vehicles").returncode == 0
    drawn = np.asarray(cv2.imread(str(out)), np.uint8)[:, :, ::-1].astype(int)
    base = np.asarray(cv2.imread(str(plain)), np.uint8)[:, :, ::-1].astype(int)
    r = json.loads(record.read_text())
    assert r["lane"] is not None and len(r["vehicles"]) >= 1
    # Inside the lane (between the boundaries, near the bottom) the fill turns pixels green.
    y = 650
    xl = np.interp(
        y, [p[1] for p in r["lane"]["left"]][::-1], [p[0] for p in r["lane"]["left"]][::-1]
    )
    xr = np.interp(
        y, [p[1] for p in r["lane"]["right"]][::-1], [p[0] for p in r["lane"]["right"]][::-1]
    )
    inside = (drawn[y, int(xl) + 40 : int(xr) - 40] - base[y, int(xl) + 40 : int(xr) - 40]).mean(0)
    assert inside[1] > 10 and inside[1] > inside[0]
    # Each box's edges are drawn in the box colour (red dominant) where the record puts them.
    for vehicle in r["vehicles"]:
        x1, y1, _, y2 = (round(v) for v in vehicle["box"])
        edge = drawn[(y1 + y2) // 2, x1 - 1 : x1 + 2]
        assert (edge[:, 0] > 200).any() and (edge[:, 0] > edge[:, 2] + 80).any()


def test_debug_writes_every_intermediate(test_video: Path, tmp_path: Path) -> None:
    result = run_cli("debug", test_video, "--frames", "12:14", "--out", tmp_path / "dbg")
    assert result.returncode == 0, result.stderr
    expected = [
        "undistorted",
        "scene",
        "lane_mask",
        "birdseye_fit",
        "window_hits",
        "heat_frame",
        "heat_history",
        "regions",
        "tracks",
        "composite",
    ]
    for frame in (12, 13):
        names = sorted(p.name for p in (tmp_path / "dbg" / f"frame_{frame:06d}").iterdir())
        assert [n.split("_", 1)[1].removesuffix(".png") for n in names] == expected
        for name in names:
            assert cv2.imread(str(tmp_path / "dbg" / f"frame_{frame:06d}" / name)) is not None
    sheet = (tmp_path / "dbg" / "index.html").read_text()
    assert '"frames": [12, 13]' in sheet and "ArrowRight" in sheet
    bad = run_cli("debug", test_video, "--frames", "9:3", "--out", tmp_path / "x")
    assert_one_line_error(bad, "--frames")


def test_start_end_and_frame_numbers(test_video: Path, tmp_path: Path) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli(
        "process", test_video, "-o", out, "--json", record, "--start", "0.4", "--end", "1.0"
    )
    assert result.returncode == 0, result.stderr
    assert "calibration scaled" not in result.stderr  # the shipped camera's own size
    frames = [r["frame"] for r in read_record(record)]
    assert frames == list(range(10, 25))
    assert count_frames(out)[1] == 15
    first = next(read_frames(out, probe_video(out)))
    assert first.shape == (720, 1280, 3)
