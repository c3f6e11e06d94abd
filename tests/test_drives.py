"""A drive a dashcam split into files: a part processed after the one before it (`--after`,
`batch --drives`) starts with the history the stages had at that one's end."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest

from app.batch import BatchInput, in_drives
from app.drivers import within_part
from app.events import Event
from app.sources import ffmpeg_binary
from tests.helpers import assert_one_line_error, process_clip, read_record, run_cli

SPLIT = 44  # project_cut_2's 88 frames: the first part's


def _encode(source: Path, target: Path, select: str, scale: str = "iw:ih") -> None:
    """Frames of `source` chosen by an ffmpeg `select` expression, as a file of their own."""
    subprocess.run(
        [
            ffmpeg_binary(),
            "-loglevel",
            "error",
            "-i",
            str(source),
            "-vf",
            f"select={select},setpts=N/FRAME_RATE/TB,scale={scale}",
            "-an",
            str(target),
        ],
        check=True,
    )


@pytest.fixture(scope="module")
def parts(tmp_path_factory: pytest.TempPathFactory, data_dir: Path) -> dict[str, Path]:
    """project_cut_2 as a drive of two files, the two joined without re-encoding (the same
    frames), and the first part at another size."""
    folder = tmp_path_factory.mktemp("drive")
    clip = data_dir / "videos" / "project_cut_2.mp4"
    out = {name: folder / f"{name}.mp4" for name in ("part1", "part2", "joined", "small")}
    _encode(clip, out["part1"], f"lt(n\\,{SPLIT})")
    _encode(clip, out["part2"], f"gte(n\\,{SPLIT})")
    _encode(clip, out["small"], f"lt(n\\,{SPLIT})", "640:360")
    listing = folder / "parts.txt"
    listing.write_text(f"file '{out['part1']}'\nfile '{out['part2']}'\n")
    joined = ["-f", "concat", "-safe", "0", "-i", str(listing), "-c", "copy", str(out["joined"])]
    subprocess.run([ffmpeg_binary(), "-loglevel", "error", *joined], check=True)
    return out


def _seen(record: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """What a record says of each frame, whatever the frame's number and time."""
    return [{k: v for k, v in row.items() if k not in ("frame", "time_s")} for row in record]


def _first_boxed(record: list[dict[str, Any]]) -> int:
    return next(k for k, row in enumerate(record) if row["vehicles"])


def _after(part: Path, before: Path, folder: Path) -> subprocess.CompletedProcess[str]:
    """`roadview process PART --after BEFORE`, its video and record `o.*` in `folder`."""
    return run_cli(
        "process", part, "--after", before, "-o", folder / "o.mp4", "--json", folder / "o.jsonl"
    )


def test_a_part_after_the_one_before_is_recorded_as_the_whole_drive(
    parts: dict[str, Path], tmp_path: Path
) -> None:
    whole = process_clip(parts["joined"], tmp_path / "whole")
    result = _after(parts["part2"], parts["part1"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert "part2.mp4 goes on from part1.mp4" in result.stderr
    after = read_record(tmp_path / "o.jsonl")
    alone = process_clip(parts["part2"], tmp_path / "alone")
    assert len(after) == len(alone) == len(whole) - SPLIT
    assert [row["frame"] for row in after] == list(range(len(after)))
    assert _seen(after) == _seen(whole[SPLIT:])  # every field, to the byte
    # Alone, the part starts afresh: the car ahead is boxed only once the tracker saw it again.
    assert _seen(alone) != _seen(whole[SPLIT:])
    assert _first_boxed(after) == 0 < _first_boxed(alone)


def test_debug_after_shows_the_frames_process_after_made(
    parts: dict[str, Path], tmp_path: Path
) -> None:
    """The debug mode goes on from the part before as `process --after` does: its first
    frame's lane is the one that run recorded, not the one the part alone gives."""
    assert _after(parts["part2"], parts["part1"], tmp_path).returncode == 0
    after = read_record(tmp_path / "o.jsonl")[0]["lane"]
    alone = process_clip(parts["part2"], tmp_path / "alone")[0]["lane"]
    said = {}
    for name, extra in (("after", ["--after", str(parts["part1"])]), ("alone", [])):
        result = run_cli("debug", parts["part2"], "--frames", "0", "--out", tmp_path / name, *extra)
        assert result.returncode == 0, result.stderr
        said[name] = result.stderr
    assert f"lane {after['width_m']:.2f} m wide" in said["after"]
    assert "goes on from part1.mp4" in said["after"]
    assert f"lane {alone['width_m']:.2f} m wide" in said["alone"]
    assert f"{after['width_m']:.2f}" != f"{alone['width_m']:.2f}"


def test_a_part_of_another_camera_is_not_run_first(parts: dict[str, Path], tmp_path: Path) -> None:
    result = _after(parts["part2"], parts["small"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert "small.mp4 (640x360, 25 fps) is not of the camera" in result.stderr
    alone = process_clip(parts["part2"], tmp_path / "alone")
    assert _seen(read_record(tmp_path / "o.jsonl")) == _seen(alone)


def test_after_is_refused_where_it_makes_no_sense(parts: dict[str, Path], tmp_path: Path) -> None:
    part1, part2 = parts["part1"], parts["part2"]
    out = tmp_path / "o.mp4"
    assert_one_line_error(
        run_cli("process", part2, "--after", part1, "--start", "1", "-o", out), "--start"
    )
    assert_one_line_error(run_cli("process", part2, "--after", part2, "-o", out), "the input")
    assert_one_line_error(
        run_cli("process", part2, "--after", part1, "-o", part1), "the --after video"
    )
    assert_one_line_error(
        run_cli("process", part2, "--after", tmp_path / "none.mp4", "-o", out), "does not exist"
    )
    assert not out.exists()


def test_an_event_under_way_at_the_start_starts_there() -> None:
    fps = 25.0
    events = [
        Event("lane_departure", 10, 30, 0.4, 1.2, None, 1.1),  # over before the part
        Event("lane_change_left", 40, 70, 1.6, 2.8, None, 1.5),  # under way at its start
        Event("close_following", 60, 90, 2.4, 3.6, 7, 0.7),  # inside it
    ]
    kept = within_part(events, 50, fps)
    assert [(e.kind, e.start_frame, e.start_s, e.end_frame) for e in kept] == [
        ("lane_change_left", 50, 2.0, 70),
        ("close_following", 60, 2.4, 90),
    ]


def test_batch_drives_run_each_part_after_the_one_before(
    parts: dict[str, Path], tmp_path: Path
) -> None:
    folder = tmp_path / "camera"
    folder.mkdir()
    for name in ("part1", "part2"):
        (folder / f"{name}.mp4").write_bytes(parts[name].read_bytes())
    out = tmp_path / "out"
    result = run_cli("batch", folder, "--out", out, "--workers", "1", "--no-video", "--drives")
    assert result.returncode == 0, result.stdout + result.stderr
    single = _after(folder / "part2.mp4", folder / "part1.mp4", tmp_path)
    assert single.returncode == 0, single.stderr
    assert read_record(out / "part2.jsonl") == read_record(tmp_path / "o.jsonl")
    rows = {
        Path(str(r["path"])).name: r
        for r in pq.read_table(out / "table/manifest.parquet").to_pylist()
    }
    assert "goes on from part1.mp4" in str(rows["part2.mp4"]["notes"])
    assert "goes on from" not in str(rows["part1.mp4"]["notes"])


def test_drives_chain_each_folder_in_name_order() -> None:
    """Each video goes on from the one before it in name order in its own folder (a dashcam's
    names sort by time); the first of a folder starts afresh."""
    paths = [Path(p) for p in ("b/0900.mp4", "a/0801.mp4", "b/0859.mp4", "a/0800.mp4")]
    entries = [BatchInput(p, p) for p in paths]
    chained = {str(e.path): None if e.after is None else str(e.after) for e in in_drives(entries)}
    assert chained == {
        "a/0800.mp4": None,
        "a/0801.mp4": "a/0800.mp4",
        "b/0859.mp4": None,
        "b/0900.mp4": "b/0859.mp4",
    }
