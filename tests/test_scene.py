"""Scene geometry read off the footage: black bars and the horizon, also on re-framed clips."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.sources import probe_video, read_frames
from camera_cal.scene import (
    DashScale,
    GroundScale,
    SceneGeometry,
    SceneTracker,
    bonnet_row,
    edge_gain,
    grain,
    live_box,
    monochrome,
    road_grey,
    road_segments,
    scale_height,
    vanishing_point,
)
from tests.helpers import assert_one_line_error, moving_road, process_clip, run_cli

Frame = np.ndarray


def _road(
    size: tuple[int, int],
    vp: tuple[float, float],
    bars: int = 0,
    ground: int = 90,
    paint: int = 240,
) -> Frame:
    """A synthetic road: grey asphalt (`ground` grey levels) below the horizon with four lines
    painted `paint` converging to `vp`, sky above, and black bars `bars` pixels wide at both
    sides."""
    w, h = size
    frame = np.zeros((h, w, 3), np.uint8)
    frame[: round(vp[1])] = (150, 180, 220)
    frame[round(vp[1]) :] = ground
    for foot in (-0.6, -0.1, 0.5, 1.2):  # where each line meets the bottom row, in widths
        x_bottom = vp[0] + foot * w
        top = vp[1] + 0.08 * h
        x_top = vp[0] + (x_bottom - vp[0]) * (top - vp[1]) / (h - 1 - vp[1])
        cv2.line(frame, (round(x_top), round(top)), (round(x_bottom), h - 1), (paint,) * 3, 6)
    if bars:
        frame[:, :bars] = 0
        frame[:, w - bars :] = 0
    return frame


def test_vanishing_point_and_bars_of_a_synthetic_road() -> None:
    size, vp = (960, 540), (500.0, 260.0)
    frame = _road(size, vp, bars=80)
    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    live = live_box(grey.max(axis=1), grey.max(axis=0))
    assert live == (80, 0, 880, 540)
    point = vanishing_point(road_segments(grey, live, 290), tolerance=10)
    assert point is not None and np.allclose(point, vp, atol=4)
    # One family of parallel edges fixes no point.
    one_way = road_segments(grey, (500, 0, 880, 540), 290)
    assert vanishing_point(one_way, tolerance=10) is None
    # The tracker: the default until enough frames agree, then the estimate; --horizon wins.
    tracker = SceneTracker(size, default_horizon=300.0, every=1)
    geometries = [tracker.update(frame) for _ in range(8)]
    assert geometries[0].horizon_y == 300.0 and not geometries[0].estimated
    assert geometries[-1].estimated and abs(geometries[-1].horizon_y - vp[1]) < 4
    column = geometries[-1].vanishing_x
    assert geometries[0].vanishing_x is None and column is not None and abs(column - vp[0]) < 4
    # The stages' placement takes a column 100 px off the live centre (a camera turned
    # sideways); one 20 px off (a bend ahead) leaves it as it was, so no new warp is built.
    for column, placed in ((580.0, 580.0), (500.0, None)):
        turned = SceneTracker(size, default_horizon=300.0, every=1)
        road = _road(size, (column, 260.0), bars=80)
        assert [turned.update(road).vanishing_x for _ in range(8)][-1] is not None
        x = turned.placement["vanishing_x"]
        assert x == placed if placed is None else abs(x - placed) < 4
    assert geometries[-1].live == live
    fixed = SceneTracker(size, default_horizon=300.0, fixed_horizon=222.0, every=1)
    assert all(fixed.update(frame).horizon_y == 222.0 for _ in range(8))


def test_the_vanishing_column_follows_a_road_that_turned() -> None:
    """Past a junction the road runs another way: once 8 estimates in a row agree on a column
    off the window's median, the older ones are dropped and the column (and the lanes' warp)
    follows at once; a turn of 7 estimates, or estimates that scatter, leave it. A median over
    the whole window of 60 would still read the old road (India's junction: about 7 s)."""
    size = (960, 540)

    def columns(tracker: SceneTracker, column: float, frames: int) -> list[float | None]:
        road = _road(size, (column, 260.0), bars=80)
        return [tracker.update(road).vanishing_x for _ in range(frames)]

    turned = SceneTracker(size, default_horizon=300.0, every=1)
    assert abs((columns(turned, 480.0, 60)[-1] or 0) - 480) < 4
    after = columns(turned, 640.0, 12)
    assert all(abs((x or 0) - 480) < 4 for x in after[:7])  # the old road's column ...
    assert abs((after[-1] or 0) - 640) < 4  # ... until the new one stands
    assert abs(turned.placement["vanishing_x"] - 640) < 4
    brief = SceneTracker(size, default_horizon=300.0, every=1)
    columns(brief, 480.0, 60)
    columns(brief, 640.0, 7)
    assert abs((columns(brief, 480.0, 20)[-1] or 0) - 480) < 4
    assert all(abs((x or 0) - 480) < 4 for x in columns(brief, 640.0, 7))
    scattered = SceneTracker(size, default_horizon=300.0, every=1)
    columns(scattered, 480.0, 60)
    for _ in range(10):  # two roads in turn: their estimates never agree
        columns(scattered, 600.0, 1)
        columns(scattered, 680.0, 1)
    assert abs((scattered.current.vanishing_x or 0) - 480) < 4


def test_a_picture_is_monochrome_after_three_samples_without_colour() -> None:
    """The live picture's colour is sampled every 5th frame: three samples in a row without any
    make the scene monochrome (a camera switching to infrared at night, read 0.4-0.6 s after);
    one sample with colour ends it."""
    size = (640, 360)
    colour = _road(size, (320.0, 150.0))
    grey = cv2.cvtColor(cv2.cvtColor(colour, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    tracker = SceneTracker(size, default_horizon=200.0)
    assert not any(tracker.update(colour).monochrome for _ in range(10))
    # Samples at frames 10, 15 and 20: monochrome from the third on.
    assert [tracker.update(grey).monochrome for _ in range(15)] == [k >= 10 for k in range(15)]
    assert not tracker.update(colour).monochrome  # frame 25, a sample with colour


def test_the_lines_of_a_dim_road_are_found_as_by_day() -> None:
    """A quarter and a sixth of the light (paint at 60 and 36 grey levels): the edge thresholds
    follow the picture's brightest paint, so its lines give the vanishing point of the bright
    picture; by day the thresholds are as they were."""
    size, vp = (960, 540), (500.0, 260.0)
    grey = cv2.cvtColor(_road(size, vp), cv2.COLOR_RGB2GRAY)
    assert edge_gain(grey) == 1.0
    for light in (0.25, 0.15):
        dim = (grey * light).astype(np.uint8)
        assert edge_gain(dim) < 0.7
        point = vanishing_point(road_segments(dim, (0, 0, *size), 290), tolerance=10)
        assert point is not None and np.allclose(point, vp, atol=4)


def test_faint_lines_on_a_pale_road_give_the_first_horizon() -> None:
    """Paint 30 grey levels lighter than a pale road (concrete in sunlight; the yellow line is
    as light as it in grey) gives edges too weak for the day's thresholds. While an unknown
    camera waits for its first horizon, a frame that gives no vanishing point is looked at
    again with edges 0.6 as strong: the horizon stands; without that it does not."""
    size, vp = (960, 540), (500.0, 260.0)
    pale = _road(size, vp, ground=150, paint=180)
    for weak, found in ((0.6, True), (1.0, False)):
        tracker = SceneTracker(
            size, default_horizon=300.0, every=1, full_size_first=True, weak_edges=weak
        )
        scene = [tracker.update(pale) for _ in range(8)][-1]
        assert scene.estimated == found
        assert not found or abs(scene.horizon_y - vp[1]) < 4


def test_a_black_night_sky_is_picture_and_a_black_band_above_a_sky_is_a_bar() -> None:
    """A sky as black as a bar down to the road's horizon: the road's lines meet at the band's
    bottom, where no bar would leave the horizon, so the band is sky: the live box keeps the
    whole picture and the horizon is estimated. Black padded above a picture with its own sky
    stays a bar."""
    size, vp = (960, 540), (500.0, 260.0)
    night = _road(size, vp)
    night[: round(vp[1])] = 0
    tracker = SceneTracker(size, default_horizon=300.0, every=1)
    geometries = [tracker.update(night) for _ in range(12)]
    assert geometries[1].live[1] == round(vp[1])  # a bar at first
    assert geometries[-1].estimated and abs(geometries[-1].horizon_y - vp[1]) < 4
    assert geometries[-1].live == (0, 0, *size)
    padded = np.vstack([np.zeros((60, 960, 3), np.uint8), _road((960, 480), (500.0, 200.0))])
    tracker = SceneTracker(size, default_horizon=300.0, every=1)
    geometries = [tracker.update(padded) for _ in range(12)]
    assert geometries[-1].live == (0, 60, *size)
    assert geometries[-1].estimated and abs(geometries[-1].horizon_y - 260) < 4


def test_the_horizon_of_a_darkened_night_clip(wild_dir: Path) -> None:
    """The night clip darkened further (gamma 0.55, 20 grey levels less: its sky as black as a
    bar, its paint at half the light): the same horizon as the clip as it is."""
    clip = wild_dir / "night_highway_istock.mp4"
    darker = np.clip(255 * (np.arange(256) / 255) ** (1 / 0.55) - 20, 0, 255).astype(np.uint8)
    plain = _final_horizon(clip, lambda f: f)
    assert abs(_final_horizon(clip, lambda f: darker[f]) - plain) <= 0.01 * 360


def test_a_picture_without_colour_is_monochrome() -> None:
    """Grey with the codec's rounding, even under a small coloured caption, is monochrome; a
    road in colour is not, nor a night picture whose only colour is a dark blue sky."""
    rng = np.random.default_rng(5)
    grey = np.repeat(rng.integers(0, 200, (360, 640, 1)), 3, axis=2)
    grey = np.clip(grey + rng.integers(-2, 3, grey.shape), 0, 255).astype(np.uint8)
    assert monochrome(grey)
    captioned = grey.copy()
    captioned[8:20, 8:60] = (255, 200, 0)
    assert monochrome(captioned)
    assert not monochrome(_road((640, 360), (320.0, 170.0)))
    night = np.zeros((360, 640, 3), np.uint8)
    night[:100] = (0, 0, 40)
    assert not monochrome(night)


def _final_horizon(video: Path, change: Callable[[Frame], Frame], frames: int = 90) -> float:
    info = probe_video(video)
    tracker: SceneTracker | None = None
    for k, frame in enumerate(read_frames(video, info)):
        if k >= frames:
            break
        picture = np.ascontiguousarray(change(frame))
        if tracker is None:
            h, w = picture.shape[:2]
            tracker = SceneTracker((w, h), default_horizon=0.5 * h)  # a poor default on purpose
        tracker.update(picture)
    assert tracker is not None and tracker.current.estimated
    return tracker.current.horizon_y


@pytest.mark.slow
@pytest.mark.parametrize("clip", ["test_video", "project_cut_2"])
def test_the_horizon_follows_a_reframed_clip(data_dir: Path, clip: str) -> None:
    """Cropping, padding, scaling or barring the picture moves the estimated horizon exactly as
    it moves the road: within 1 % of the height of the original's, transformed the same way."""
    video = data_dir / "videos" / f"{clip}.mp4"
    plain = _final_horizon(video, lambda f: f)
    assert abs(plain - 420.8) < 0.015 * 720  # the calibrated warp's horizon on this camera
    cut = 72  # 10 % of the height
    black = np.zeros((cut, 1280, 3), np.uint8)
    side = np.zeros((720, 160, 3), np.uint8)
    cases: list[tuple[Callable[[Frame], Frame], float, int]] = [
        (lambda f: f[cut:], plain - cut, 648),  # horizon 10 % higher in the picture
        (lambda f: np.vstack([black, f[:-cut]]), plain + cut, 720),  # 10 % lower
        (lambda f: f[:, 160:1120], plain, 720),  # 4:3 crop
        (lambda f: np.hstack([side, f[:, 160:1120], side]), plain, 720),  # black side bars
        (lambda f: cv2.resize(f, (960, 540), interpolation=cv2.INTER_AREA), plain * 0.75, 540),
        (lambda f: cv2.resize(f, (1920, 1080)), plain * 1.5, 1080),
    ]
    for change, expected, height in cases:
        found = _final_horizon(video, change)
        assert abs(found - expected) <= 0.01 * height, (expected, found)


def test_horizon_in_the_record_and_the_override(test_video: Path, tmp_path: Path) -> None:
    rows = process_clip(test_video, tmp_path, "--end", "0.8")
    horizons = [r["horizon_y"] for r in rows]
    assert all(400 < h < 440 for h in horizons)
    # The shipped camera looks along the road: its vanishing point is near the centre column.
    columns = [r["vanishing_x"] for r in rows if r["vanishing_x"] is not None]
    assert columns and all(600 < x < 680 for x in columns)
    # The road's lightness from the first frame: daylight asphalt.
    assert all(60 <= r["road_grey"] <= 160 for r in rows)
    fixed = process_clip(test_video, tmp_path, "--end", "0.4", "--horizon", "380")
    assert {r["horizon_y"] for r in fixed} == {380.0}
    assert {r["vanishing_x"] for r in fixed} == {None}
    assert_one_line_error(
        run_cli("process", test_video, "-o", tmp_path / "x.mp4", "--horizon", "720"),
        "--horizon 720 is outside the frame (720 rows)",
    )


def test_the_stages_placement_follows_the_scene_in_steps() -> None:
    """The placement jumps to the estimate once it is far from the default, then ignores a
    wobble smaller than 1.5 % of the height and follows a larger move."""
    size = (960, 540)
    tracker = SceneTracker(size, default_horizon=300.0, every=1, window=5, min_estimates=3)
    for _ in range(6):
        tracker.update(_road(size, (500.0, 260.0), bars=80))
    placement = tracker.placement
    horizon = placement["horizon_y"]
    assert abs(horizon - 260) < 4 and placement["live"] == (80, 0, 880, 540)
    # The bars cut the sides of a 16:9 picture: the scale is still that of its height.
    assert placement["scale_height"] == 540
    for _ in range(6):
        tracker.update(_road(size, (500.0, 264.0), bars=80))  # 4 px: within 8.1 px
    assert tracker.placement["horizon_y"] == horizon and tracker.current.horizon_y > horizon + 2
    for _ in range(6):
        tracker.update(_road(size, (500.0, 290.0), bars=80))
    assert abs(tracker.placement["horizon_y"] - 290) < 4


def test_the_ground_scale_moves_only_where_the_tuned_one_fails() -> None:
    """Nothing before `least` samples; then the median, but only when lanes read outside the
    plausible widths at the current scale and the lane finder believed few of them (narrow
    lanes and a higher camera look alike: 2.8 m lanes of the tuned camera, or a road the tuned
    scale already finds its lanes on, stay as they are). Frames without a sample (None)
    neither count nor move it."""
    higher = [0.625 + 0.01 * (k % 3 - 1) for k in range(60)]  # a camera 1.6 times higher
    scale = GroundScale(least=20, window=40, plausible=(0.7, 1.5), believed=0.5)
    assert {scale.add(v) for v in higher[:19]} == {1.0}
    assert scale.add(None) == 1.0
    assert scale.add(higher[19]) == 0.625
    assert {scale.add(v * 1.3, True) for v in higher} == {0.625}  # lanes 30 % wider: plausible
    narrow = GroundScale(least=20, window=40, plausible=(0.7, 1.5), believed=0.5)
    assert {narrow.add(v * 1.2) for v in higher} == {1.0}  # 2.8 m lanes of the tuned camera
    found = GroundScale(least=20, window=40, plausible=(0.7, 1.5), believed=0.5)
    assert {found.add(v, k % 3 > 0) for k, v in enumerate(higher)} == {1.0}  # 2/3 believed
    lower = GroundScale(least=20, window=40, plausible=(0.7, 1.5), believed=0.5)
    assert [lower.add(v * 2.6) for v in higher][-1] == pytest.approx(1.625, abs=0.01)


def test_the_road_length_follows_the_dashes_only_where_they_read_another_lens() -> None:
    """Nothing before `least` spacings; then their spacing (the median near the median: a dash
    missed reads twice, a broken one half, and both are left out) moves the scale where it is
    more than 15 % off 12.19 m and within a lens's reach, and then follows it within 5 %.
    Spacings 4 % off (the shipped camera's clips read theirs 0.96-1.04 of it) keep it at 1; a
    spacing no lens explains (India's 4.9 m) keeps it too, for the note; readings that do not
    agree read nothing."""
    rng = np.random.default_rng(0)
    wide = list(15.85 * (1 + 0.05 * rng.standard_normal(60)))  # a lens 1.3 times wider
    junk = [31.7, 7.0, 2.5, 33.0, 6.1]  # a dash missed, a dash broken, a marker (out of span)
    scale = DashScale(least=30)
    assert {scale.add(wide[k : k + 2]) for k in range(0, 28, 2)} == {1.0}
    assert scale.read_m is None
    assert scale.add(wide[28:30] + junk) == pytest.approx(12.19 / 15.85, rel=0.03)
    assert scale.read_m == pytest.approx(15.85, rel=0.03)
    moved = scale.value
    assert scale.add([15.85 * 1.02] * 5) == moved  # within 5 %: as it was
    assert scale.add([15.85 * 1.15] * 120) == pytest.approx(12.19 / (15.85 * 1.15), rel=0.03)
    assert scale.add([]) == scale.value  # a frame without spacings changes nothing
    near = DashScale(least=30)
    assert {near.add([12.19 * f]) for f in np.linspace(0.96, 1.04, 80)} == {1.0}
    assert near.read_m == pytest.approx(12.19, rel=0.01)
    india = DashScale(least=30)
    assert {india.add([4.9 + 0.1 * (k % 3)]) for k in range(60)} == {1.0}
    assert india.implausible_m == pytest.approx(5.0, abs=0.1)
    assert {india.add([12.5]) for _ in range(200)} == {1.0}  # then US dashes: no note is left
    assert india.implausible_m is None and india.read_m == 12.5
    scattered = DashScale(least=30)
    assert {scattered.add([s]) for s in rng.uniform(4, 40, 80)} == {1.0}
    assert scattered.read_m is None


def test_a_ground_scale_that_moves_reads_the_dashes_afresh() -> None:
    """The view's metres change with the ground scale (a higher camera's view covers more road),
    so the dash spacings read before it moved, and the scale they gave, are forgotten."""
    scene = SceneTracker(
        (1280, 720), 420.0, ground=GroundScale(least=5, window=10), dashes=DashScale(least=30)
    )
    for _ in range(30):
        scene.observe_dashes((15.85,))
    scale, read = scene.length
    assert scale == pytest.approx(12.19 / 15.85, rel=0.01) and read == 15.85
    for _ in range(4):
        scene.observe_lane_width(1.0)  # the tuned width: the ground scale stays
    assert scene.length[1] == 15.85
    for _ in range(10):
        scene.observe_lane_width(0.6)  # a higher camera: the ground scale moves
    assert scene.ground.value == 0.6 and scene.length == (1.0, None)


def test_a_lane_width_is_known_once_measured_at_the_scale() -> None:
    """A side made up at the standard width needs the lanes' width in pixels: known from the
    start where it is `assumed` (a camera calibrated at the frames' size), else once `confirm`
    samples read a plausible median at the current scale, or once the scale moved to theirs.
    Frames without a sample, or samples the current scale cannot account for, leave it
    unknown."""
    assumed = GroundScale(least=20, window=40, confirm=5, assumed=True)
    assert assumed.known
    tuned = GroundScale(least=20, window=40, confirm=5)
    known = []
    for sample in (None, None, 1.02, 0.98, 1.0, 1.01, 0.99):
        tuned.add(sample)
        known.append(tuned.known)
    assert known == [False] * 6 + [True]
    higher = GroundScale(least=20, window=40, confirm=5)  # a camera 1.6 times higher
    known = []
    for k in range(20):
        higher.add(0.625 + 0.01 * (k % 3 - 1))
        known.append(higher.known)
    assert known == [False] * 19 + [True] and higher.value == 0.625


@pytest.mark.parametrize(
    ("live", "expected"),
    [
        ((1280, 720), 720),  # 16:9 as it is
        ((1280, 648), 720),  # its top cut off
        ((960, 720), 720),  # its sides cut off (4:3)
        ((1920, 1080), 1080),  # scaled
        ((1080, 1920), 1080),  # upright phone video
        ((640, 640), 640),  # square: the height is the short side
    ],
)
def test_a_crop_keeps_the_scale_of_the_picture_it_was_cut_from(
    live: tuple[int, int], expected: float
) -> None:
    assert scale_height(live) == expected


def test_an_unknown_camera_reads_its_horizon_ahead(wild_dir: Path, tmp_path: Path) -> None:
    """Started mid-clip on the night highway without a calibration, the default horizon sits far
    below the road's. Processed frame by frame, the stages wait for the footage's own estimate
    rather than draw a lane and box dark road by the default; `process` reads the horizon off
    the first frames before it processes them (`Pipeline.look_ahead`), so that every frame is
    placed by the footage's horizon and the lane is found from the first frame on."""
    from app.pipeline import Pipeline
    from app.record import frame_record
    from lanes.finder import LaneFinder

    clip = wild_dir / "night_highway_istock.mp4"
    rows = process_clip(clip, tmp_path, "--calibration", "none", "--start", "11.7", "--end", "16")
    info = probe_video(clip)
    first = round(11.7 * info.fps)
    frames = list(read_frames(clip, info, first, first + 40))
    with Pipeline(None, LaneFinder(), None) as pipeline:
        pipeline.prepare(info.size, info.fps, first)
        waiting = [frame_record(0, 0.0, info.size, pipeline.run(f).result) for f in frames]
    default = waiting[0]["horizon_y"]
    waited = [r for r in waiting if r["horizon_y"] == default]
    assert 5 <= len(waited) < 40  # the 5 estimates it needs at least
    assert not any(r["lane"] for r in waited)
    # Read ahead: no frame is placed by the default, and the first frames have their lane.
    assert all(abs(r["horizon_y"] - default) > 0.2 * default for r in rows)
    assert sum(1 for r in rows[:5] if r["lane"]) >= 4
    # (A run of the whole clip draws the same 87 of these 129 frames: none where the car
    # straddles the centre dashes with a side made up; 121 before that was refused.)
    assert sum(1 for r in rows if r["lane"]) >= 0.6 * len(rows)
    # The horizon read ahead is the one the frames then read themselves.
    assert abs(rows[0]["horizon_y"] - waiting[-1]["horizon_y"]) < 0.02 * info.size[1]


def test_the_horizon_is_read_ahead_only_for_an_unknown_camera_and_off_its_own_shot(
    data_dir: Path, wild_dir: Path
) -> None:
    """`look_ahead` reads the horizon of the shot the clip starts with: a cut before it is found
    leaves the first shot's stages to wait (the shot after the cut reads its own as it comes,
    see test_shots); a known camera's frames are not even decoded."""
    from app.pipeline import Pipeline
    from camera_cal import default_calibration_path, load_calibration
    from lanes.finder import LaneFinder

    def frames(video: Path, count: int) -> list[np.ndarray]:
        return [
            cv2.resize(f, (1280, 720)) for f in read_frames(video, probe_video(video), 0, count)
        ]

    def unread() -> Iterator[np.ndarray]:
        raise AssertionError("a known camera's frames were read")
        yield np.zeros((720, 1280, 3), np.uint8)

    ahead = frames(data_dir / "videos" / "test_video.mp4", 20)
    other = frames(wild_dir / "night_highway_istock.mp4", 20)  # another camera's shot
    with Pipeline(None, LaneFinder(), None) as pipeline:
        pipeline.prepare((1280, 720), 25.0)
        assert pipeline.look_ahead(ahead[:3] + other) is None  # a cut at the 4th frame
        waiting = pipeline.run(ahead[0]).result
        assert waiting.scene is not None and not waiting.scene.estimated  # it waits
        pipeline.prepare((1280, 720), 25.0)
        horizon = pipeline.look_ahead(ahead)
        assert horizon is not None and 0.5 * 720 < horizon < 0.7 * 720
        first = pipeline.run(ahead[0]).result
        assert first.scene is not None and first.scene.estimated
        assert first.scene.horizon_y == horizon
        assert first.lane is not None and first.lane.lane is not None
    calibrated = load_calibration(default_calibration_path())
    with Pipeline(calibrated, LaneFinder(), None) as pipeline:
        pipeline.prepare((1280, 720), 25.0)
        assert pipeline.look_ahead(unread()) is None


def test_a_bonnet_ends_the_live_picture_and_a_moving_road_does_not() -> None:
    size = (320, 240)
    motion = np.r_[np.full(200, 8.0), np.full(40, 0.5)]
    assert bonnet_row(motion) in range(197, 203)
    assert bonnet_row(np.full(240, 8.0)) is None  # all road
    assert bonnet_row(np.full(240, 0.2)) is None  # a still road (stopped): no evidence
    assert bonnet_row(np.r_[np.full(200, 8.0), np.linspace(8.0, 3.0, 40)]) is None  # smooth asphalt
    for bonnet in (190, None):
        tracker = SceneTracker(size, default_horizon=120.0)
        for frame in moving_road(size, 90, bonnet):
            scene = tracker.update(frame)
        if bonnet is None:
            assert scene.bonnet_y is None and scene.live[3] == 240
        else:
            assert scene.bonnet_y is not None and abs(scene.bonnet_y - bonnet) <= 3
            assert scene.live[3] == scene.bonnet_y
        # The scale stays the picture's: a bonnet hides road, not lens.
        assert tracker.placement["scale_height"] == scale_height((320, 240))


@pytest.mark.parametrize(
    ("clip", "rows"),
    [("la_freeway_minidashcam_2", range(400, 426)), ("india_highway_wildfilms", None)],
)
def test_the_bonnet_of_a_wild_clip(wild_dir: Path, clip: str, rows: range | None) -> None:
    """The LA dashcam shows its white bonnet from about row 415 of 480 (seen by eye); the Indian
    highway clip shows none, and its smooth asphalt at the bottom is not taken for one."""
    video = wild_dir / f"{clip}.mp4"
    info = probe_video(video)
    tracker = SceneTracker(info.size, default_horizon=0.55 * info.size[1])
    for frame in read_frames(video, info, 0, 240):
        scene = tracker.update(frame)
    if rows is None:
        assert scene.bonnet_y is None
    else:
        assert scene.bonnet_y in rows and scene.live[3] == scene.bonnet_y


def test_debug_of_an_unknown_camera_runs_long_enough_to_place_its_stages(
    wild_dir: Path, tmp_path: Path
) -> None:
    """Stepping to a frame of a camera without calibration warms up past the wait for its
    horizon: the frame gets the lane and vehicle intermediates, and the scene its bonnet."""
    out = tmp_path / "dbg"
    video = wild_dir / "la_freeway_minidashcam_2.mp4"
    result = run_cli("debug", video, "--frames", "200", "--out", out, "--calibration", "none")
    assert result.returncode == 0, result.stderr
    names = sorted(p.name for p in (out / "frame_000200").iterdir())
    assert any("birdseye_fit" in n for n in names) and any("window_hits" in n for n in names)
    scene = cv2.imread(str(next((out / "frame_000200").glob("*_scene.png"))))
    assert scene is not None
    # The live box's bottom edge (green) is drawn at the bonnet's top, not at the frame's bottom.
    green = (scene[:, :, 1] > 200) & (scene[:, :, 0] < 60) & (scene[:, :, 2] < 60)
    rows = np.flatnonzero(green[:, 100:750].mean(axis=1) > 0.9)
    assert any(400 <= r <= 426 for r in rows)


@pytest.mark.slow
def test_debug_from_the_start_steps_to_a_frame_as_process_made_it(
    wild_dir: Path, tmp_path: Path
) -> None:
    """India's ground scale is learned at 10.5 s from 10 s of lane widths: stepping to frame 400
    (16 s) after the usual 6 s run-in starts another history, but `--from-start` runs the clip
    from its first frame, so the lane it logs is the one the record has there, read at the
    same ground scale."""
    import re

    video = wild_dir / "india_highway_wildfilms.mp4"
    rows = process_clip(video, tmp_path, "--calibration", "none", "--end", "16.1")
    result = run_cli(
        "debug",
        video,
        "--frames",
        "400:402",
        "--out",
        tmp_path / "dbg",
        "--calibration",
        "none",
        "--from-start",
    )
    assert result.returncode == 0, result.stderr
    logged = re.findall(
        r"frame (\d+): .*lane ([\d.]+) m wide, the camera ([\d.]+) m (left|right) of "
        r"centre; ground scale ([\d.]+)",
        result.stderr,
    )
    assert [int(f[0]) for f in logged] == [400, 401], result.stderr
    for frame, width, apart, side, scale in logged:
        lane = rows[int(frame)]["lane"]
        assert lane is not None
        assert float(width) == pytest.approx(lane["width_m"], abs=0.006)
        offset = float(apart) * (1 if side == "right" else -1)
        assert offset == pytest.approx(lane["offset_m"], abs=0.006)
        assert float(scale) == pytest.approx(rows[int(frame)]["ground_scale"], abs=0.0006)


def test_the_debug_scene_picture_labels_a_learned_ground_scale() -> None:
    """The ground scale is drawn with the horizon once it moved from the tuned camera's 1, and
    so is a turn the frame was levelled by; the dashes' spacing and length scale once read;
    the road line under the camera once the vanishing point is."""
    from dataclasses import replace

    from app.debug import scene_picture

    frame = np.zeros((360, 640, 3), np.uint8)
    scene = SceneGeometry((640, 360), 150.0, (0, 0, 640, 360), estimated=True)
    tuned = scene_picture(frame, scene)
    higher = scene_picture(frame, replace(scene, ground_scale=0.67))
    label = (slice(100, 150), slice(0, 640))  # the text above the horizon row
    assert (higher[label] > 0).sum() > 1.3 * (tuned[label] > 0).sum()
    levelled = scene_picture(frame, scene, 2.5)
    assert (levelled[label] > 0).sum() > 1.3 * (tuned[label] > 0).sum()
    # The lane dashes' spacing and the length scale it gives, once read, under the live top.
    top = (slice(35, 70), slice(5, 600))  # inside the live box's green sides
    assert not tuned[top].any()
    read = scene_picture(frame, scene, 0.0, (0.79, 15.5))
    assert read[top].any() and np.array_equal(read[label], tuned[label])
    # The road line under the camera: dashed, upright below the vanishing point, once read.
    below = (slice(180, 300), slice(5, 635))  # inside the live box's green sides
    assert not tuned[below].any()
    pointed = scene_picture(frame, replace(scene, vanishing_x=250.0))[below]
    columns = 5 + np.flatnonzero(pointed.any(axis=(0, 2)))
    assert columns.min() >= 248 and columns.max() <= 252
    assert 0.3 < pointed[:, 245].any(axis=1).mean() < 0.7  # dashed


def test_the_road_ahead_is_measured_for_its_lightness_not_the_sky_or_bonnet() -> None:
    # Bright sky above the horizon, asphalt of grey 30 below it, a bright bonnet at the bottom
    # (outside the live box): the road's grey, whatever the live box's size.
    frame = np.full((360, 640), 30, np.uint8)
    frame[:150] = 220
    frame[330:] = 250
    assert road_grey(frame, (0, 0, 640, 330), 150.0) == 30.0
    assert road_grey(frame, (80, 20, 560, 330), 150.0) == 30.0


def test_grain_is_the_noise_on_the_road_not_its_paint_or_edges() -> None:
    """Noise of deviation 2 on a road with lane lines and a car's dark outline reads 2; the
    same road without noise reads under 0.1: the lines' and the outline's edges do not count."""
    rng = np.random.default_rng(3)
    road = np.full((360, 640), 90.0)
    road[:150] = 200
    for x in (200, 330, 460):
        road[150:, x : x + 8] = 230  # lines across the patch
    road[220:280, 280:360] = 30  # a dark car body
    live = (0, 0, 640, 360)
    clean = grain(road.astype(np.uint8), live, 150.0)
    noisy = grain(
        np.clip(road + rng.normal(0, 2, road.shape), 0, 255).astype(np.uint8), live, 150.0
    )
    assert clean < 0.1 and noisy == pytest.approx(2.0, rel=0.15), (clean, noisy)


def test_the_scene_says_how_light_the_road_is_at_dusk(data_dir: Path) -> None:
    clip = data_dir / "videos" / "project_cut_1.mp4"
    info = probe_video(clip)
    greys = []
    for light in (1.0, 0.4):
        tracker = SceneTracker(info.size, 0.58 * info.size[1])
        assert tracker.current.road_grey is None
        for frame in list(read_frames(clip, info))[:20]:
            scene = tracker.update(np.asarray(frame * np.float32(light), np.uint8))
        assert scene.road_grey is not None
        greys.append(scene.road_grey)
    # Daylight asphalt reads 70-80 there; 0.4 of the light, 0.4 of the grey.
    assert 65 <= greys[0] <= 85 and greys[1] == pytest.approx(0.4 * greys[0], abs=2)


@pytest.mark.slow
def test_a_camera_pitched_up_gets_its_horizon_soon(data_dir: Path, tmp_path: Path) -> None:
    """test_video as a camera pitched up by a fifth of the height sees it (padded at the top and
    cut at the bottom): only the road's far part is left, whose dashes, shrunk to the measuring
    width, are too short for segments, and the first horizon took 21 frames. A frame whose
    shrunk picture gives no vanishing point while the first horizon waits is measured at full
    size: it stands within half a second, 144 rows below the clip's own."""
    from app.reframe import Framing, write_reframed
    from camera_cal import default_calibration_path, load_calibration

    video = data_dir / "videos" / "test_video.mp4"
    calibration = load_calibration(default_calibration_path())  # undistorted, as the table
    w, h = probe_video(video).size
    cut = h // 5
    firsts = []
    for name, framing in (
        ("as is", Framing("as is")),
        ("pitched", Framing("pitched", crop=(0, 0, w, h - cut), pad=(0, cut, 0, 0))),
    ):
        copy = tmp_path / f"{name}.mp4"
        write_reframed(video, framing, copy, calibration)
        rows = process_clip(copy, tmp_path, "--calibration", "none", "--no-vehicles")
        firsts.append(next(r for r in rows if r["vanishing_x"] is not None))
    plain, pitched = firsts
    assert pitched["frame"] <= 12, pitched["frame"]
    assert abs(pitched["horizon_y"] - (plain["horizon_y"] + cut)) < 0.015 * h, (plain, pitched)
