"""Cuts in edited footage: found where the picture jumps to another shot, not where a road
streams past or the light changes; a shot after a cut is processed as a clip of its own, and a
shot the footage comes back to (the same camera's bonnet) gets its scene back."""

from __future__ import annotations

from contextlib import closing
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from app.sinks import VideoSink
from app.sources import probe_video, read_frames
from camera_cal import SceneGeometry, ShotDetector, same_camera
from tests.helpers import moving_road, read_record, run_cli, zoomed_replay

SIZE = (320, 180)


def _cuts(frames: list[NDArray[np.uint8]]) -> list[int]:
    shots = ShotDetector()
    return [k for k, frame in enumerate(frames) if shots.update(frame)]


def _other_shot(frames: int) -> list[NDArray[np.uint8]]:
    """Another camera's picture: a blue sky over a dark road streaming past."""
    out = []
    for road in moving_road(SIZE, frames):
        frame = (road // 3).copy()
        frame[: SIZE[1] // 2] = (150, 190, 240)
        out.append(frame)
    return out


def test_a_cut_is_found_where_the_picture_jumps_to_another_shot() -> None:
    road, other = moving_road(SIZE, 20), _other_shot(10)
    assert _cuts(road) == []  # the road streams past: one shot
    assert _cuts(road + other) == [20]
    assert _cuts(road + other + road) == [20, 30]


def test_light_alone_is_no_cut() -> None:
    """A tunnel or a flash darkens or lightens the picture, and leaves its colours."""
    road = moving_road(SIZE, 20)
    darker = [(frame // 3).astype(np.uint8) for frame in road[10:]]
    assert _cuts(road[:10] + darker) == []


def _faded(
    frames: list[NDArray[np.uint8]], weights: NDArray[np.float64]
) -> list[NDArray[np.uint8]]:
    return [np.asarray(f * w, np.uint8) for f, w in zip(frames, weights, strict=True)]


def test_a_fade_through_black_to_another_shot_is_a_cut() -> None:
    """An edited video fading out to black and in to another shot over half a second each way
    moves no frame much, so no frame-to-frame cut is seen; the fade in is found, once, as it
    ends. A video that starts by fading in from black (a camera starting up) is one shot,
    and so is a road that darkens and lightens again (a tunnel: never all black)."""
    road, other = moving_road(SIZE, 20), _other_shot(20)
    ramp = np.linspace(1, 0, 12)
    out = _faded(road[8:], ramp)
    fading = road[:8] + out + [out[-1]] * 2 + _faded(other[:12], ramp[::-1]) + other[12:]
    cuts = _cuts(fading)
    assert len(cuts) == 1 and 30 <= cuts[0] <= 34, cuts
    assert _cuts(_faded(road[:12], ramp[::-1]) + road) == []
    dim = np.concatenate([np.linspace(1, 0.3, 10), np.linspace(0.3, 1, 10)])
    assert _cuts(_faded(road, dim)) == []


def test_the_same_camera_is_told_by_its_bonnet() -> None:
    """A shot the footage comes back to shows the same bonnet, whatever the road does."""
    first, later = moving_road(SIZE, 30, bonnet=150)[0], moving_road(SIZE, 30, bonnet=150)[29]
    scene = SceneGeometry(SIZE, 60.0, (0, 0, SIZE[0], 150), bonnet_y=150)
    assert same_camera(first, later, scene)
    other = later.copy()
    other[150:] = (60, 50, 40)  # another car's bonnet
    assert not same_camera(first, other, scene)
    # Without a bonnet or an overlay the picture does not tell.
    bare = SceneGeometry(SIZE, 60.0, (0, 0, SIZE[0], SIZE[1]))
    assert not same_camera(first, first, bare)


@pytest.mark.slow
def test_a_shot_after_a_cut_is_processed_as_a_clip_of_its_own(
    data_dir: Path, tmp_path: Path
) -> None:
    """test_video, then a zoomed replay of project_cut_1 (its lower left 70 %: the horizon 120
    rows higher, the road's vanishing point near the right edge). After the cut the second shot
    is what it is alone, processed frame by frame from the cut as a clip that `process` starts
    there is, its horizon read ahead off its own frames: the same horizon, lanes and boxes, its
    vehicle ids after the first shot's, and no frame waiting for the horizon (a shot after a
    cut waited 14 frames for it before its horizon was read ahead too). Before cuts were looked
    for, it kept the first shot's horizon and drew its lanes 162 px away from these."""
    from app.assembly import build_stages
    from app.pipeline import Pipeline
    from app.record import frame_record

    first, second = (
        data_dir / "videos" / "test_video.mp4",
        data_dir / "videos" / "project_cut_1.mp4",
    )
    info, zoomed = probe_video(first), probe_video(second)
    clip = tmp_path / "compilation.mp4"
    with VideoSink(clip, info.size, 25.0, preset="medium") as sink:
        count = 0
        for frame in read_frames(first, info):
            sink.write(frame)
            count += 1
        for frame in read_frames(second, zoomed):
            sink.write(zoomed_replay(frame))
    record = tmp_path / "all.jsonl"
    result = run_cli(
        "process", clip, "-o", tmp_path / "all.mp4", "--json", record, "--calibration", "none"
    )
    assert result.returncode == 0, result.stderr
    assert f"cuts to another shot at {count / 25:.1f} s" in result.stderr
    rows = read_record(record)
    assert [r["shot"] for r in rows] == [0] * count + [1] * (len(rows) - count)
    compiled = probe_video(clip)
    with Pipeline(None, *build_stages(), vehicles_in_worker=False) as pipeline:
        pipeline.prepare(compiled.size, compiled.fps, count)
        with closing(read_frames(clip, compiled, count)) as ahead:
            assert pipeline.look_ahead(ahead) is not None
        alone = [
            frame_record(count + k, (count + k) / compiled.fps, compiled.size, out.result)
            for k, out in enumerate(pipeline.stream(read_frames(clip, compiled, count)))
        ]
    after = rows[count:]
    assert len(after) == len(alone)
    assert [r["horizon_y"] for r in after] == [r["horizon_y"] for r in alone]
    assert [r["lane"] for r in after] == [r["lane"] for r in alone]
    assert [[v["box"] for v in r["vehicles"]] for r in after] == [
        [v["box"] for v in r["vehicles"]] for r in alone
    ]
    assert any(r["vehicles"] for r in alone)
    assert all(r["lane"] for r in after[:20])  # not one frame waiting for the horizon
    before = {v["id"] for r in rows[:count] for v in r["vehicles"]}
    later = {v["id"] for r in after for v in r["vehicles"]}
    assert before and later and min(later) > max(before)


@pytest.mark.slow
def test_the_la_clip_comes_back_from_its_zoomed_replay_with_its_scene(
    wild_dir: Path, tmp_path: Path
) -> None:
    """The LA clip cuts to a zoomed view of the car beside it at 12.1 s and back at 14.5 s. The
    zoomed shot no longer gets the first shot's lane (drawn over its first 26 frames before);
    back, the first shot's scene (horizon, mirror) returns at once, and the lane with it."""
    clip = wild_dir / "la_freeway_minidashcam_2.mp4"
    record = tmp_path / "r.jsonl"
    result = run_cli(
        "process", clip, "-o", tmp_path / "o.mp4", "--json", record, "--calibration", "none"
    )
    assert result.returncode == 0, result.stderr
    assert "cuts to another shot at 12.1 s, 14.5 s" in result.stderr
    rows = read_record(record)
    assert [r["shot"] for r in rows] == [0] * 363 + [1] * 71 + [2] * (len(rows) - 434)
    assert not any(r["lane"] for r in rows[363:373])
    assert rows[434]["horizon_y"] == rows[362]["horizon_y"]
    assert rows[434]["overlays"] == rows[362]["overlays"] != []
    back = rows[434:]
    assert sum(r["lane"] is not None for r in back) >= 0.9 * len(back)
