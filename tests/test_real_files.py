"""The kinds of files users have: rotated phone video, odd sizes, other containers, audio of any
length; outputs that must never overwrite the input or each other; the record's schema."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from numpy.typing import NDArray

from app import sources
from app.evaluate import evaluate, load_labels
from app.sinks import VideoWriter
from app.sources import ffmpeg_binary, parse_probe, probe_video, read_frames
from camera_cal import default_calibration_path
from tests.helpers import assert_one_line_error, count_frames, read_record, run_cli

SCHEMA = json.loads((Path(__file__).parents[1] / "app" / "record.schema.json").read_text())


def ffmpeg(*args: str | Path) -> None:
    """Run ffmpeg quietly; the test fails if it does."""
    subprocess.run([ffmpeg_binary(), "-y", "-loglevel", "error", *map(str, args)], check=True)


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory, test_video: Path) -> dict[str, Path]:
    """Files a user might have, each made from the 38-frame test clip."""
    d = tmp_path_factory.mktemp("made")
    clip = test_video
    files = {name: d / name for name in ("rotated.mp4", "odd.mp4", "clip.webm", "clip.ts")}
    ffmpeg("-display_rotation:v:0", "90", "-i", clip, "-c", "copy", files["rotated.mp4"])
    # x264 takes odd sizes in 4:4:4 only; roadview must still write its 4:2:0 output.
    ffmpeg(
        "-i", clip, "-vf", "scale=1279:719", "-t", "0.4", "-pix_fmt", "yuv444p", files["odd.mp4"]
    )
    ffmpeg(
        "-i",
        clip,
        "-t",
        "0.4",
        "-c:v",
        "libvpx-vp9",
        "-deadline",
        "realtime",
        "-cpu-used",
        "8",
        "-c:a",
        "libopus",
        files["clip.webm"],
    )
    ffmpeg("-i", clip, "-t", "0.4", "-c:v", "libx264", "-c:a", "aac", files["clip.ts"])
    audio = {
        "short": ("sine=d=0.5", []),
        "long": ("sine=d=6", []),
        "rate8k": ("sine=d=1.52:sample_rate=8000", []),
        "rate44k": ("sine=d=1.2:sample_rate=44100", ["-ac", "2"]),
    }
    for name, (source, extra) in audio.items():
        files[name] = d / f"audio_{name}.mp4"
        ffmpeg(
            "-i",
            clip,
            "-f",
            "lavfi",
            "-i",
            source,
            "-map",
            "0:v",
            "-map",
            "1:a",
            "-c:v",
            "copy",
            "-c:a",
            "aac",
            *extra,
            files[name],
        )
    files["silent"] = d / "silent.mp4"
    ffmpeg("-i", clip, "-an", "-c:v", "copy", files["silent"])
    # Anamorphic: the 16:9 picture stored 960x720 in pixels 4/3 as wide as tall (a camera or
    # an editor that saves bits so), and the same tagged as a phone's upright video.
    files["anamorphic"] = d / "anamorphic.mp4"
    ffmpeg("-i", clip, "-an", "-vf", "scale=960:720,setsar=4/3", files["anamorphic"])
    files["anamorphic_upright"] = d / "anamorphic_upright.mp4"
    ffmpeg(
        "-display_rotation:v:0", "90", "-i", files["anamorphic"], "-c", "copy",
        files["anamorphic_upright"],
    )  # fmt: skip
    # A phone's HDR video: 10-bit HEVC in BT.2020 with the PQ or HLG curve, the clip's white at
    # HDR's reference white (203 nits).
    for name, curve, seconds in (("pq", "smpte2084", "2"), ("hlg", "arib-std-b67", "0.2")):
        files[name] = d / f"{name}.mov"
        ffmpeg(
            "-i", clip, "-t", seconds, "-an", "-vf",
            f"zscale=tin=bt709:min=bt709:pin=bt709:t={curve}:m=bt2020nc:p=bt2020:npl=203,"
            "format=yuv420p10le",
            "-c:v", "libx265", "-preset", "ultrafast", "-x265-params",
            f"colorprim=bt2020:transfer={curve}:colormatrix=bt2020nc:log-level=error",
            files[name],
        )  # fmt: skip
    return files


def test_hdr_video_is_tone_mapped_to_the_picture_the_stages_know(
    made: dict[str, Path], tmp_path: Path, data_dir: Path
) -> None:
    """PQ and HLG video decode to the SDR picture (decoded as they were, PQ's mean level was 74
    against the clip's 106 and its recall 0.589): close to the clip, and the clip's labels score
    as on the clip itself."""
    plain = next(read_frames(made["silent"], probe_video(made["silent"]))).astype(int)
    for name, curve in (("pq", "smpte2084"), ("hlg", "arib-std-b67")):
        info = probe_video(made[name])
        assert info.hdr == curve and info.size == (1280, 720)
        first = next(read_frames(made[name], info)).astype(int)
        assert np.abs(first - plain).mean() < 8.0
        assert abs(first.mean() - plain.mean()) < 5.0
    assert probe_video(made["silent"]).hdr is None
    record = tmp_path / "o.jsonl"
    result = run_cli("process", made["pq"], "-o", tmp_path / "o.mp4", "--json", record)
    assert result.returncode == 0, result.stderr
    assert "HDR video (PQ): tone-mapped to SDR" in result.stderr
    scores = evaluate(load_labels(data_dir / "labels" / "test_video.json"), read_record(record))
    vehicles = scores["vehicles"]["iou_0.5"]
    assert vehicles["precision"] >= 0.95 and vehicles["recall"] >= 0.95
    assert vehicles["mean_iou"] >= 0.75
    assert scores["lane"]["share_within_20px"] >= 0.99


def test_hdr_video_without_the_tone_map_filters_is_decoded_and_says_so(
    made: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An ffmpeg without zscale and tonemap (one a user names) still decodes HDR video, as it
    is: darker than the tone-mapped picture, and the note says why."""
    info = probe_video(made["pq"])
    mapped = next(read_frames(made["pq"], info)).astype(float).mean()
    monkeypatch.setattr(sources, "can_tone_map", lambda: False)
    plain = next(read_frames(made["pq"], info)).astype(float).mean()
    assert plain < mapped - 15
    assert "no zscale and tonemap filters" in " ".join(sources.decoding_notes(info))


def test_a_pixel_aspect_near_one_is_told_to_four_digits() -> None:
    """A rescale tagged with pixels 1.0025 times as wide as tall (853x481 shown as 856x481) is
    told as 1.002 or 1.003, not "1 times"; an anamorphic 4:3 as 1.33; square pixels not."""

    def note(aspect: float) -> str:
        info = sources.VideoInfo((856, 481), 25.0, 25, 1.0, False, pixel_aspect=aspect)
        return " ".join(sources.decoding_notes(info))

    assert re.search(r"stored 1\.00[23] times as wide", note(7696 / 7677))
    assert "stored 1.33 times as wide" in note(4 / 3)
    assert "times as wide" not in note(1.0)


def test_anamorphic_video_is_seen_with_square_pixels(
    made: dict[str, Path], tmp_path: Path, data_dir: Path
) -> None:
    """Pixels stored wider than tall are decoded square (rotation applied first): the picture
    and its size are the clip's own, so the shipped calibration fits it (it was refused as
    another aspect ratio) and the clip's labels score as on the clip itself."""
    info = probe_video(made["anamorphic"])
    assert info.size == (1280, 720) and info.pixel_aspect == pytest.approx(4 / 3)
    square = next(read_frames(made["anamorphic"], info)).astype(int)
    plain = next(read_frames(made["silent"], probe_video(made["silent"]))).astype(int)
    assert np.abs(square - plain).mean() < 4.0
    upright_info = probe_video(made["anamorphic_upright"])
    assert upright_info.size == (720, 1280) and upright_info.rotation == 90
    upright = next(read_frames(made["anamorphic_upright"], upright_info)).astype(int)
    assert min(np.abs(np.rot90(square, k) - upright).mean() for k in (1, 3)) < 2.0
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli("process", made["anamorphic"], "-o", out, "--json", record)
    assert result.returncode == 0, result.stderr
    assert "1.33 times as wide as tall: stretched square, 1280x720" in result.stderr
    assert count_frames(out)[0].size == (1280, 720)
    scores = evaluate(load_labels(data_dir / "labels" / "test_video.json"), read_record(record))
    vehicles = scores["vehicles"]["iou_0.5"]
    assert vehicles["precision"] >= 0.95 and vehicles["recall"] >= 0.95
    assert vehicles["mean_iou"] >= 0.8
    assert scores["lane"]["share_within_20px"] >= 0.99


def test_rotated_video_is_processed_upright(made: dict[str, Path], tmp_path: Path) -> None:
    info = probe_video(made["rotated.mp4"])
    assert info.rotation == 90 and info.size == (720, 1280)
    upright = next(read_frames(made["rotated.mp4"], info))
    plain = next(read_frames(made["silent"], probe_video(made["silent"])))
    # The decoded frame is the stored one turned a quarter: no scrambled rows.
    turned = [np.abs(np.rot90(plain, k).astype(int) - upright).mean() for k in (1, 3)]
    assert min(turned) < 2.0, turned
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli(
        "process",
        made["rotated.mp4"],
        "-o",
        out,
        "--json",
        record,
        "--calibration",
        "none",
        "--no-lanes",
        "--no-vehicles",
    )
    assert result.returncode == 0, result.stderr
    out_info, frames = count_frames(out)
    assert out_info.size == (720, 1280) and frames == 38
    written = next(read_frames(out, out_info)).astype(int)
    assert np.abs(written[100:] - upright[100:]).mean() < 3.0  # below the panel: same picture
    rows = read_record(record)
    assert len(rows) == 38 and all(r["size"] == [720, 1280] for r in rows)


def test_rotated_video_with_the_landscape_calibration_says_why(
    made: dict[str, Path], tmp_path: Path
) -> None:
    """Upright, the picture is 720x1280: not the shipped 16:9 calibration's. By default it is
    processed without undistortion and a note says why; the calibration named is refused."""
    result = run_cli("process", made["rotated.mp4"], "-o", tmp_path / "o.mp4")
    assert result.returncode == 0, result.stderr
    assert "720x1280" in result.stderr and "without undistortion" in result.stderr
    named = tmp_path / "dashcam.json"
    named.write_text(default_calibration_path().read_text())
    refused = run_cli(
        "process", made["rotated.mp4"], "-o", tmp_path / "n.mp4", "--calibration", named
    )
    assert_one_line_error(refused, "720x1280", "--calibration none")


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize(
    ("options", "fragment"),
    [
        (["-o", "{out}/y.mp4", "--json", "{input}"], "is the input"),
        (["-o", "{out}/x.mp4", "--json", "{out}/x.mp4"], "also the -o output"),
        (["-o", "{input}"], "is the input"),
        (["-o", "{out}/x.flv"], "one of .avi"),
        (["-o", "{out}/x.png"], "image name"),
        (["-o", "/proc/roadview/x.mp4"], "/proc/roadview"),
        (["--json", "{out}"], "is a folder"),
    ],
)
def test_outputs_never_overwrite_the_input_or_each_other(
    made: dict[str, Path], tmp_path: Path, options: list[str], fragment: str
) -> None:
    source = tmp_path / "clip.mp4"
    source.write_bytes(made["silent"].read_bytes())
    before = _digest(source)
    out = tmp_path / "out"
    out.mkdir()
    args = [o.format(input=source, out=out) for o in options]
    assert_one_line_error(run_cli("process", source, *args), fragment)
    assert _digest(source) == before
    assert not list(out.iterdir())


def test_output_folder_gets_the_default_name(made: dict[str, Path], tmp_path: Path) -> None:
    result = run_cli("process", made["odd.mp4"], "-o", tmp_path, "--no-vehicles")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "odd_roadview.mp4").exists()


def test_still_to_a_video_name_and_debug_onto_the_input(
    data_dir: Path, made: dict[str, Path], tmp_path: Path
) -> None:
    still = data_dir / "test_images" / "test1.jpg"
    assert_one_line_error(run_cli("process", still, "-o", tmp_path / "x.mp4"), "x.mp4", ".png")
    source = tmp_path / "clip.mp4"
    source.write_bytes(made["silent"].read_bytes())
    result = run_cli("debug", source, "--frames", "0:1", "--out", source)
    assert_one_line_error(result, "is the input")
    assert _digest(source) == _digest(made["silent"])


@pytest.mark.parametrize(
    ("size", "max_side", "expected"),
    [
        ((3840, 2160), 1080, (1920, 1080)),
        ((2160, 3840), 1080, (1080, 1920)),  # a phone held upright: its shorter side
        ((2560, 1081), 1080, (2558, 1080)),  # even sides
        ((1920, 1080), 1080, (1920, 1080)),
        ((3840, 2160), 0, (3840, 2160)),
    ],
)
def test_video_is_decoded_at_most_max_size_on_its_shorter_side(
    size: tuple[int, int], max_side: int, expected: tuple[int, int]
) -> None:
    info = sources.VideoInfo(size, 25.0, 10, 0.4, False)
    reduced = sources.within_size(info, max_side)
    assert reduced.size == expected
    assert reduced.reduced_from == (None if expected == size else size)
    assert sources.reduced_row(1000.0, reduced) == pytest.approx(1000.0 * expected[1] / size[1])


def test_video_larger_than_the_max_size_is_processed_at_it(
    test_video: Path, tmp_path: Path
) -> None:
    big = tmp_path / "big.mp4"
    ffmpeg("-i", test_video, "-t", "0.4", "-vf", "scale=2560:1440", "-an", big)
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    args: list[str | Path] = ["--calibration", "none", "--json", record, "-o", out]
    result = run_cli("process", big, *args, "--max-size", "720", "--horizon", "840")
    assert result.returncode == 0, result.stderr
    assert "2560x1440 is processed and written at 1280x720" in result.stderr
    info, frames = count_frames(out)
    assert info.size == (1280, 720) and frames == 10
    rows = read_record(record)
    # The user's horizon is a row of the video as stored: 840 of 1440 rows is 420 of 720.
    assert all(r["size"] == [1280, 720] and r["horizon_y"] == pytest.approx(420) for r in rows)
    # The whole picture, shrunk (not cut): between the caption panel and the horizon (no lane
    # or box drawn there) it is the input's.
    source = next(read_frames(test_video, probe_video(test_video))).astype(int)
    written = next(read_frames(out, info)).astype(int)
    assert np.abs(written[160:380] - source[160:380]).mean() < 3.0
    result = run_cli("process", big, *args, "--max-size", "0", "--end", "0.08", "--no-vehicles")
    assert result.returncode == 0, result.stderr
    assert (
        count_frames(out)[0].size == (2560, 1440) and "processed and written" not in result.stderr
    )
    assert_one_line_error(run_cli("process", big, *args, "--max-size", "100"), "--max-size 100")


def test_odd_frame_size_is_encoded_with_input_coordinates(
    made: dict[str, Path], tmp_path: Path
) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    result = run_cli("process", made["odd.mp4"], "-o", out, "--json", record)
    assert result.returncode == 0, result.stderr
    info, frames = count_frames(out)
    assert info.size == (1280, 720) and frames == probe_video(made["odd.mp4"]).n_frames
    for row in read_record(record):
        assert row["size"] == [1279, 719]
        for vehicle in row.get("vehicles", []):
            x1, y1, x2, y2 = vehicle["box"]
            assert 0 <= x1 < x2 <= 1279 and 0 <= y1 < y2 <= 719


@pytest.mark.parametrize(
    ("suffix", "ffmpeg_converts"), [(".mp4", False), (".webm", False), (".mp4", True)]
)
def test_written_colours_are_the_frames_colours_at_any_size(
    tmp_path: Path, suffix: str, ffmpeg_converts: bool
) -> None:
    # Blocks of pure and mixed colours, the darkest and lightest values among them, in a frame
    # of odd width and height: what is read back is what was written, up to the codec.
    colours = np.array(
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [0, 0, 0], [255, 255, 255], [200, 120, 40]],
        np.uint8,
    )
    frame = np.repeat(np.repeat(colours[None, :], 2, axis=0), 16, axis=0)
    frame = np.ascontiguousarray(np.repeat(frame, 16, axis=1)[:31, :95])  # 95 x 31 pixels
    out = tmp_path / f"colours{suffix}"
    writer = VideoWriter(out, (95, 31), 25.0, ffmpeg_converts=ffmpeg_converts)
    for _ in range(5):
        writer.write(frame)
    writer.close()
    info = probe_video(out)
    assert info.size == (96, 32) and info.n_frames == 5
    # The matrix the frames were converted with is named (players show untagged HD as BT.709).
    header = subprocess.run(
        [ffmpeg_binary(), "-hide_banner", "-i", str(out)], capture_output=True, text=True
    ).stderr
    assert "smpte170m" in header or "bt470bg" in header, header
    read = next(read_frames(out, info)).astype(int)
    for k, colour in enumerate(colours):
        inner = read[4:12, 16 * k + 4 : 16 * k + 12]
        assert np.abs(inner - colour.astype(int)).max() <= 12, (colour, inner.mean(axis=(0, 1)))


def test_webm_in_webm_out_and_other_containers_default_to_mp4(
    made: dict[str, Path], tmp_path: Path
) -> None:
    source = tmp_path / "clip.webm"
    source.write_bytes(made["clip.webm"].read_bytes())
    result = run_cli("process", source, "--no-vehicles")
    assert result.returncode == 0, result.stderr
    written = tmp_path / "clip_roadview.webm"
    assert count_frames(written)[1] == 10
    header = subprocess.run(
        [ffmpeg_binary(), "-hide_banner", "-i", str(written)], capture_output=True, text=True
    ).stderr
    assert "vp9" in header and "opus" in header
    ts = tmp_path / "clip.ts"
    ts.write_bytes(made["clip.ts"].read_bytes())
    result = run_cli("process", ts, "--no-vehicles")
    assert result.returncode == 0, result.stderr
    assert "writing .mp4" in result.stderr
    assert count_frames(tmp_path / "clip_roadview.mp4")[1] == probe_video(ts).n_frames


def test_a_frame_sought_is_the_frame_of_that_number(test_video: Path, tmp_path: Path) -> None:
    """`--start` and `debug --frames` seek: in a file whose video starts after its audio (3
    frames here; the LA clip's 2, the night clip's 1.4) frame k was sought at k / fps of the
    file's time and came out 3 frames early, so the record numbered frame k - 3 as k."""
    late = tmp_path / "late.mp4"
    ffmpeg(
        "-f", "lavfi", "-i", "sine=d=2", "-itsoffset", "0.12", "-i", test_video,
        "-map", "1:v", "-map", "0:a", "-c:v", "copy", "-c:a", "aac", late,
    )  # fmt: skip
    info = probe_video(late)
    assert info.video_start_s == pytest.approx(0.12)
    in_order = list(read_frames(late, info))
    for k in (1, 4, 20, 37):
        sought = next(iter(read_frames(late, info, k)))
        assert np.array_equal(sought, in_order[k]), k
    assert probe_video(test_video).video_start_s == 0.0


def test_steady_rates_are_told_from_variable_ones() -> None:
    """A phone's video slowing to 15 fps reads at its usual 30; a steady 29.97 fps in
    millisecond steps over ten minutes, or a frame dropped now and then, is left alone."""
    thirty = np.arange(30) / 30
    halves = np.concatenate([thirty, 1 + np.arange(15) * 2 / 30])
    assert sources.variable_rate(halves) == pytest.approx(30)
    assert sources.variable_rate(np.round(np.arange(18000) / 29.97, 3)) is None
    assert sources.variable_rate(np.delete(np.arange(300) / 30, [50, 200])) is None
    shown = sources.steady_sources(halves, 30)
    assert len(shown) == 59 and np.all(np.abs(halves[shown] - np.arange(59) / 30) <= 1 / 30 + 1e-9)


def test_variable_rate_video_is_read_as_it_plays(tmp_path: Path) -> None:
    """Each frame of a variable-rate file (30 fps for 1 s, then 15) is the picture that plays
    at its time, read in order or sought: frame k's grey is 4 k. Read as decoded, the 15 fps
    second went by in half a second (45 frames, frame 40's grey 200 instead of 160)."""
    vfr = tmp_path / "vfr.mkv"
    ffmpeg(
        "-f", "lavfi", "-i", "color=c=black:s=64x48:r=30:d=2,format=gray,geq=lum='4*N'",
        "-vf", "select='lt(n,30)+not(mod(n,2))'", "-fps_mode", "vfr", "-c:v", "ffv1", vfr,
    )  # fmt: skip
    info = probe_video(vfr)
    assert info.fps == pytest.approx(30) and info.n_frames == 59 and info.frame_times
    frames = list(read_frames(vfr, info))
    greys = np.array([float(f.mean()) for f in frames])
    assert len(frames) == 59 and np.all(np.abs(greys - 4 * np.arange(59)) <= 4.5), greys
    for k in (31, 44, 45, 58):
        assert np.array_equal(next(iter(read_frames(vfr, info, k))), frames[k]), k
    assert len(list(read_frames(vfr, info, 40, 50))) == 10
    assert any("variable frame rate (15-30 fps)" in n for n in sources.decoding_notes(info))


def test_variable_rate_video_keeps_time_with_its_sound(test_video: Path, tmp_path: Path) -> None:
    """test_video with every other frame of its last 18 left out (a phone slowing down): the
    output keeps pace with the sound to its last frame (1.44 s in, the 37th), frame k of the
    record at k / 25 s. Written as decoded, it had 29 frames and ended 0.36 s early."""
    vfr = tmp_path / "vfr.mp4"
    ffmpeg(
        "-i", test_video, "-f", "lavfi", "-i", "sine=d=1.52", "-map", "0:v", "-map", "1:a",
        "-vf", "select='lt(n,20)+not(mod(n,2))'", "-fps_mode", "vfr", "-c:a", "aac", vfr,
    )  # fmt: skip
    out, record = tmp_path / "out.mp4", tmp_path / "out.jsonl"
    result = run_cli("process", vfr, "-o", out, "--json", record, "--no-vehicles")
    assert result.returncode == 0, result.stderr
    assert "variable frame rate" in result.stderr
    rows = read_record(record)
    assert len(rows) == count_frames(out)[1] == 37
    assert rows[30]["time_s"] == pytest.approx(30 / 25)


def test_interlaced_video_is_deinterlaced(tmp_path: Path) -> None:
    """A white bar crossing the picture fast, stored as fields (25i of 50 moments a second):
    decoded as stored, its rows alternate between two places (combing: neighbouring rows
    differ at its edges by most of the white); deinterlaced, they agree."""
    fields = tmp_path / "interlaced.mp4"
    ffmpeg(
        "-f", "lavfi", "-i", "color=c=black:s=320x240:r=50:d=1",
        "-f", "lavfi", "-i", "color=c=white:s=30x160:r=50", "-filter_complex",
        "[0][1]overlay=x='mod(t*600,280)':y=40:shortest=1,"
        "tinterlace=mode=interleave_top,setfield=tff",
        "-c:v", "libx264", "-flags", "+ildct+ilme", "-x264-params", "tff=1", fields,
    )  # fmt: skip
    info = probe_video(fields)
    assert info.interlaced and info.fps == pytest.approx(25)
    assert "interlaced video: deinterlaced while decoding" in sources.decoding_notes(info)

    def combing(frames: list[NDArray[np.uint8]]) -> float:
        rows = np.stack(frames)[:, 40:200].astype(np.float64)
        return float(np.abs(rows[:, 1:] - rows[:, :-1]).mean())

    stored = list(read_frames(fields, replace(info, interlaced=False)))
    deinterlaced = list(read_frames(fields, info))
    assert len(deinterlaced) == len(stored) == 25
    assert combing(deinterlaced) < 0.3 * combing(stored), (combing(deinterlaced), combing(stored))


def test_the_starts_ffmpeg_reports_are_read_even_at_zero_or_below() -> None:
    """The file's start (the earliest track's) and the video's, as ffmpeg's log gives them: a
    video at 0 in a file starting at -0.04 s (an audio track's priming) starts 0.04 s in."""
    log = (
        "Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'x.mp4':\n"
        "  Duration: 00:00:02.00, start: -0.040000, bitrate: 3276 kb/s\n"
        "  Stream #0:0[0x1](und): Video: h264 (High) (avc1 / 0x31637661), yuv420p, "
        "1280x720 [SAR 1:1 DAR 16:9], 4204 kb/s, 25 fps, 25 tbr, 12800 tbn, start 0.000000\n"
        "  Stream #0:1[0x2](und): Audio: aac (LC), 48000 Hz, mono, fltp, start -0.040000\n"
    )
    facts = parse_probe(log)
    assert facts.file_start == -0.04 and facts.video_start == 0.0 and facts.audio


def test_a_phones_lens_tag_is_read() -> None:
    """The focal length an iPhone tags its videos with, as ffmpeg lists the file's metadata;
    a file without it has none."""
    header = (
        "Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'IMG_0001.MOV':\n"
        "  Metadata:\n"
        "    major_brand     : qt\n"
        "    com.apple.quicktime.make: Apple\n"
        "    com.apple.quicktime.camera.focal_length.35mm_equivalent: 26\n"
        "  Duration: 00:00:02.00, start: 0.000000, bitrate: 3276 kb/s\n"
    )
    stream = (
        "  Stream #0:0[0x1](und): Video: hevc (Main 10), yuv420p10le, 1920x1080, 30 fps, "
        "30 tbr, 600 tbn\n"
    )
    assert parse_probe(header + stream).focal_mm == 26.0
    assert (
        parse_probe(header.replace("35mm_equivalent: 26", "lens_model: Back") + stream).focal_mm
        is None
    )


def test_the_sound_stays_with_the_picture_when_the_video_starts_late(
    test_video: Path, tmp_path: Path
) -> None:
    """A file whose sound starts 0.2 s before its first frame (silence, then a tone from the
    first frame on): the output's sound starts with its first frame, as it played with it.
    It was copied from the file's start: 0.2 s of silence, the sound late by as much."""
    late = tmp_path / "late.mp4"
    ffmpeg(
        "-f", "lavfi", "-i", "aevalsrc='if(lt(t,0.2),0,0.5*sin(2*PI*440*t))':d=2:s=48000",
        "-itsoffset", "0.2", "-i", test_video, "-map", "1:v", "-map", "0:a", "-c:v", "copy",
        "-c:a", "aac", late,
    )  # fmt: skip
    out = tmp_path / "out.mp4"
    result = run_cli("process", late, "-o", out, "--no-lanes", "--no-vehicles")
    assert result.returncode == 0, result.stderr
    pcm = subprocess.run(
        [ffmpeg_binary(), "-loglevel", "error", "-i", str(out), "-map", "0:a", "-f", "f32le",
         "-ac", "1", "-ar", "48000", "-"],
        capture_output=True, check=True,
    ).stdout  # fmt: skip
    sound = np.frombuffer(pcm, np.float32)
    loudness = [float(np.sqrt(np.mean(sound[a:b] ** 2))) for a, b in ((0, 4800), (4800, 9600))]
    assert min(loudness) > 0.2, loudness  # the tone from the start: no silence first


@pytest.mark.parametrize("audio", ["short", "long", "rate8k", "rate44k", "silent"])
def test_every_frame_is_written_whatever_the_audio(
    made: dict[str, Path], tmp_path: Path, audio: str
) -> None:
    out, record = tmp_path / "o.mp4", tmp_path / "o.jsonl"
    # run_cli's timeout ends a hang; 38 frames take a few seconds.
    result = run_cli("process", made[audio], "-o", out, "--json", record, "--no-vehicles")
    assert result.returncode == 0, result.stderr
    info, frames = count_frames(out)
    assert frames == len(read_record(record)) == 38
    assert info.has_audio == (audio != "silent")
    header = subprocess.run(
        [ffmpeg_binary(), "-hide_banner", "-i", str(out)], capture_output=True, text=True
    ).stderr
    duration = header.split("Duration: ")[1].split(",")[0]
    h, m, s = duration.split(":")
    # A longer audio track is cut to the video; a shorter one never cuts the video.
    assert abs(int(h) * 3600 + int(m) * 60 + float(s) - 1.52) < 0.1


def test_data_without_source_or_network_lists_missing_parts(tmp_path: Path) -> None:
    env = {**os.environ, "http_proxy": "http://127.0.0.1:9", "https_proxy": "http://127.0.0.1:9"}
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "app",
            "data",
            "--source",
            str(tmp_path / "none"),
            "--dest",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert result.returncode != 0
    missing = [line for line in result.stderr.splitlines() if line.startswith("missing ")]
    assert {line.split(":")[0] for line in missing} >= {
        "missing vehicles.zip",
        "missing camera_cal/",
        "missing labels/",
    }
    assert all(len(line) < 160 for line in result.stderr.splitlines())
    assert "Traceback" not in result.stderr


def test_help_has_no_type_tags() -> None:
    for command in ("process", "debug", "train", "evaluate", "data"):
        result = run_cli(command, "--help")
        assert result.returncode == 0
        assert "<bool>" not in result.stdout and "╭" not in result.stdout


def test_records_follow_the_shipped_schema(
    test_video: Path, data_dir: Path, tmp_path: Path
) -> None:
    validator = jsonschema.Draft202012Validator(SCHEMA)
    runs: dict[str, list[str | Path]] = {
        "both": ["process", test_video, "-o", tmp_path / "a.mp4", "--json", tmp_path / "a.jsonl"],
        "lanes": [
            "process",
            test_video,
            "-o",
            tmp_path / "b.mp4",
            "--json",
            tmp_path / "b.jsonl",
            "--no-vehicles",
            "--end",
            "0.4",
        ],
        "still": [
            "process",
            data_dir / "test_images" / "test1.jpg",
            "-o",
            tmp_path / "c.png",
            "--json",
            tmp_path / "c.jsonl",
        ],
        "turned still": [
            "process",
            data_dir / "test_images" / "test1.jpg",
            "-o",
            tmp_path / "d.png",
            "--json",
            tmp_path / "d.jsonl",
            "--rotate",
            "90",
        ],
    }
    for name, args in runs.items():
        result = run_cli(*args)
        assert result.returncode == 0, result.stderr
        rows = read_record(Path(str(args[args.index("--json") + 1])))
        for row in rows:
            validator.validate(row)
            width, height = row["size"]
            for vehicle in row.get("vehicles", []):
                x1, y1, x2, y2 = vehicle["box"]
                assert 0 <= x1 < x2 <= width and 0 <= y1 < y2 <= height
        if name == "lanes":
            assert all("vehicles" not in r and "lane" in r for r in rows)
        else:
            assert all("vehicles" in r for r in rows)
    # The schema rejects what the README says a record never holds.
    bad = dict(read_record(tmp_path / "a.jsonl")[20])
    assert bad["vehicles"], "the clip has vehicles at frame 20"
    bad["vehicles"] = [{**bad["vehicles"][0], "box": [1, 2, 3]}]
    assert not validator.is_valid(bad)
    assert not validator.is_valid({**bad, "lane": {"curvature_m": 10000}})
    (turned,) = read_record(tmp_path / "d.jsonl")
    assert turned["rotate_deg"] == 90 and turned["size"] == [720, 1280]
    assert not validator.is_valid({**turned, "rotate_deg": 45})


def test_evaluate_refuses_a_record_that_does_not_cover_the_labels(
    data_dir: Path, test_video: Path, tmp_path: Path
) -> None:
    labels = data_dir / "labels" / "test_video.json"
    part = tmp_path / "part.jsonl"
    result = run_cli(
        "process",
        test_video,
        "-o",
        tmp_path / "p.mp4",
        "--json",
        part,
        "--start",
        "1",
        "--end",
        "2",
    )
    assert result.returncode == 0, result.stderr
    assert_one_line_error(run_cli("evaluate", "--labels", labels, "--record", part), "--start")
    # A record of another clip: longer than the labelled one, or of another frame size.
    other = tmp_path / "other.jsonl"
    rows = [{"frame": i, "time_s": i / 25, "size": [1280, 720], "vehicles": []} for i in range(88)]
    other.write_text("\n".join(json.dumps(r) for r in rows))
    assert_one_line_error(
        run_cli("evaluate", "--labels", labels, "--record", other), "another video"
    )
    small = tmp_path / "small.jsonl"
    rows = [{**r, "size": [640, 360]} for r in rows[:38]]
    small.write_text("\n".join(json.dumps(r) for r in rows))
    assert_one_line_error(run_cli("evaluate", "--labels", labels, "--record", small), "640x360")
