"""The camera's roll read off the vehicles' rear edges, the lane lines' spacing and the road's
motion either side (camera_cal/level.py, lanes/motion.py), on synthetic rears, roads and
readings made here and on project_cut_2 turned; the shared clips turned and levelled end to end
are in test_process_cli."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from camera_cal.level import LaneLattice, LevelConfig, RollReading, edge_lean
from lanes.finder import LaneFinder
from lanes.motion import turn_from_advances


def _rear(turn_deg: float, seed: int = 0) -> np.ndarray:
    """A 240x240 RGB picture of a car's rear made up of level bars (roof, window, lights,
    plate, bumper) and a little grain, turned `turn_deg` anticlockwise about its centre."""
    rng = np.random.default_rng(seed)
    picture = np.full((240, 240, 3), 90, np.uint8)
    for top, bottom, grey in ((60, 70, 40), (70, 110, 20), (120, 135, 200), (140, 150, 230),
                              (160, 180, 60)):  # fmt: skip
        picture[top:bottom, 50:190] = grey
    picture = np.clip(picture + rng.normal(0, 4, picture.shape), 0, 255).astype(np.uint8)
    turn = cv2.getRotationMatrix2D((119.5, 119.5), turn_deg, 1.0)
    turned: np.ndarray = cv2.warpAffine(picture, turn, (240, 240), borderMode=cv2.BORDER_REPLICATE)
    return turned


@pytest.mark.parametrize("turn", [-6.0, -2.5, 0.0, 1.0, 3.0, 5.0])
def test_a_rears_edges_lean_as_the_picture_is_turned(turn: float) -> None:
    """The lean of a rear's level edges is the picture's turn (anticlockwise positive, as
    `--roll` counts), within a third of a degree, found from level as far as 6 degrees."""
    lean = edge_lean(_rear(turn), (40, 50, 200, 190), LevelConfig())
    assert lean is not None and abs(lean - turn) < 0.35, lean


def test_a_box_too_small_or_without_edges_gives_no_lean() -> None:
    """A box narrower than `min_box_px`, or one of flat grey, says nothing."""
    config = LevelConfig()
    assert edge_lean(_rear(3.0), (100, 100, 120, 140), config) is None
    flat = np.full((100, 100, 3), 120, np.uint8)
    assert edge_lean(flat, (10, 10, 90, 90), config) is None


def test_the_reading_waits_for_enough_leans_that_agree_on_a_turn() -> None:
    """Turned 3 degrees, the reading is None until `least` boxes of two vehicles are in, then
    the turn; a level picture reads None (level), as does one whose boxes lean every which way;
    a box cut by the picture's side is left out (its edge may be the picture's own)."""
    box = np.array([[40.0, 50.0, 200.0, 190.0]])

    def vehicle(k: int) -> np.ndarray:
        return np.array([1 + k % 2])  # two vehicles in turn

    turned = RollReading()
    readings = [turned.update(_rear(3.0, seed), box, vehicle(seed)) for seed in range(20)]
    assert readings[:-1] == [None] * 19
    assert readings[-1] is not None and abs(readings[-1] - 3.0) < 0.35, readings[-1]
    level = RollReading()
    assert all(level.update(_rear(0.0, seed), box, vehicle(seed)) is None for seed in range(30))
    assert level.readings == 30
    mixed = RollReading()
    assert all(mixed.update(_rear(4.0 * (-1) ** k, k), box, vehicle(k)) is None for k in range(30))
    cut = RollReading()
    for seed in range(25):
        cut.update(_rear(3.0, seed), np.array([[0.0, 50.0, 200.0, 190.0]]), vehicle(seed))
    assert cut.readings == 0 and cut.roll_deg is None


def test_one_vehicles_lean_is_not_the_pictures() -> None:
    """The leans of one vehicle alone, however many and however much they agree, are not read
    as the picture's turn (a car seen from its side, or turned on a bend, leans on its own);
    a second vehicle leaning with it is, one leaning otherwise is not."""
    box = np.array([[40.0, 50.0, 200.0, 190.0]])
    alone = RollReading()
    assert all(alone.update(_rear(3.0, k), box, np.array([1])) is None for k in range(40))
    joined = RollReading()
    for k in range(40):
        joined.update(_rear(3.0, k), box, np.array([1]))
    readings = [joined.update(_rear(2.5, k), box, np.array([2])) for k in range(5)]
    assert readings[:4] == [None] * 4 and readings[4] is not None
    assert abs(readings[4] - 3.0) < 0.35, readings[4]
    contradicted = RollReading()
    for k in range(40):
        contradicted.update(_rear(3.0, k), box, np.array([1]))
    assert all(contradicted.update(_rear(0.0, k), box, np.array([2])) is None for k in range(8))


def _road(
    lines_m: tuple[float, ...],
    solid: tuple[bool, ...],
    turn_deg: float = 0.0,
    size: tuple[int, int] = (1280, 720),
    vanishing: tuple[float, float] = (640.0, 400.0),
    height_m: float = 1.2,
    seed: int = 0,
) -> tuple[np.ndarray, tuple[float, float]]:
    """A road seen ahead as a pinhole camera `height_m` over it sees it (a focal length of
    1000 px): lines along it at `lines_m` aside (0.15 m wide; each solid or dashed as US lanes
    are, 3.05 m painted in every 12.19 m), the picture turned `turn_deg` anticlockwise about
    its centre, the car `seed` metres on; the RGB picture and where the road's vanishing point
    is in it."""
    w, h = size
    vx, vy = vanishing
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    below = np.maximum(ys - vy, 1e-6)
    t = (xs - vx) / below  # metres aside per metre of height, along each row
    distance = 1000.0 * height_m / below
    grey = np.where(ys > vy, 90.0, 170.0)
    for aside, whole in zip(lines_m, solid, strict=True):
        on = (np.abs(t - aside / height_m) < 0.075 / height_m) & (ys > vy + 2)
        if not whole:
            on &= np.mod(distance + seed, 12.19) < 3.05
        grey[on] = 220.0
    grey += rng.normal(0, 3, grey.shape)
    picture = np.repeat(np.clip(grey, 0, 255).astype(np.uint8)[:, :, None], 3, axis=2)
    turn = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), turn_deg, 1.0)
    turned = cv2.warpAffine(picture, turn, size, borderMode=cv2.BORDER_REPLICATE)
    moved = turn @ np.array([vx, vy, 1.0])
    return turned, (float(moved[0]), float(moved[1]))


def _lattice_turn(
    lines_m: tuple[float, ...], solid: tuple[bool, ...], turn_deg: float, frames: int = 12
) -> float | None:
    lattice = LaneLattice()
    for seed in range(frames):
        picture, vanishing = _road(lines_m, solid, turn_deg, seed=seed)
        lattice.update(picture, vanishing, (0, 0, 1280, 720))
    return lattice.turn_deg


# A carriageway of five 3.7 m lanes, the car in the middle one: a solid line at each edge,
# dashed ones between.
FIVE_LANES = (-9.25, -5.55, -1.85, 1.85, 5.55, 9.25)
EDGES = (True, False, False, False, False, True)


@pytest.mark.parametrize("turn", [-4.0, -2.0, 0.0, 2.0, 3.0])
def test_equally_wide_lanes_read_the_pictures_turn(turn: float) -> None:
    """Lanes of one width side by side, seen by a turned camera, read its turn within 0.4
    degrees, and a level one about level (which `RollReading` takes as no turn)."""
    read = _lattice_turn(FIVE_LANES, EDGES, turn)
    assert read is not None and abs(read - turn) < 0.4, read


def test_one_three_of_lines_or_lanes_of_unequal_width_read_no_turn() -> None:
    """Where only one three of lines is seen beyond the car's lane (a two-lane carriageway),
    or the lanes beside the car's are wider than it (as a bowing lens or a lane of another
    width makes them look), no turn is read: a turn spreads every three alike."""
    two_lanes = (-1.85, 1.85, 5.55)
    assert _lattice_turn(two_lanes, (True, False, True), -3.0) is None
    uneven = (-9.25 - 1.2, -5.55 - 0.6, -1.85, 1.85, 5.55 + 0.6, 9.25 + 1.2)
    assert _lattice_turn(uneven, EDGES, 0.0) is None
    # Solid lines between the lanes: the edges of another carriageway, not lanes of ours.
    assert _lattice_turn(FIVE_LANES, (True,) * 6, -3.0) is None


def test_the_vehicles_level_rears_outweigh_the_lines() -> None:
    """The lines' turn is taken where the vehicles say nothing; where their rears read level,
    it is not (lanes of unequal width read as a turn); read off the lines, `cue` says so."""
    box = np.array([[40.0, 50.0, 200.0, 190.0]])
    roads = [_road(FIVE_LANES, EDGES, -3.0, seed=seed) for seed in range(12)]
    none, no_ids = np.zeros((0, 4)), np.zeros(0, int)
    lines = RollReading()
    turns = [lines.update(road, none, no_ids, vanishing) for road, vanishing in roads]
    assert turns[-1] is not None and abs(turns[-1] + 3.0) < 0.4 and lines.cue == "lines", turns
    vetoed = RollReading()
    for seed in range(20):
        vetoed.update(_rear(0.0, seed), box, np.array([1 + seed % 2]))
    assert all(vetoed.update(road, none, no_ids, vanishing) is None for road, vanishing in roads)
    assert vetoed.lattice.turn_deg is not None


def test_the_roads_advance_either_side_gives_the_turn() -> None:
    """A road point seen at t (sideways over down from the vanishing point) in a picture
    turned by a lies on a row the view takes as (1 + t tan a) times its depth: advances made
    so read a back within a hundredth of a degree, from any pair of sides; a road standing
    still reads none."""
    for turn in (-4.0, 0.0, 2.5):
        for slopes in ((-2.5, 2.5), (-1.0, 3.0)):
            advances = tuple(1.2 * (1 + t * np.tan(np.radians(turn))) for t in slopes)
            read = turn_from_advances((advances[0], advances[1]), slopes)
            assert read is not None and abs(read - turn) < 0.01, (turn, slopes, read)
    assert turn_from_advances((0.01, 0.012), (-2.5, 2.5)) is None


def _turned_asphalt(turn_deg: float, frames: int = 30, step_m: float = 1.0) -> list[float]:
    """A flat textured road streaming past a camera 1.2 m over it at `step_m` a frame (the
    picture a pinhole camera of 1000 px sees at 1280x720, its horizon at row 400), turned
    `turn_deg` anticlockwise about the picture's centre: the road turns the lane stage reads
    off its advance either side (`read_turn`), frame by frame."""
    size, horizon = (1280, 720), 400.0
    rng = np.random.default_rng(0)
    asphalt = cv2.GaussianBlur((rng.random((2000, 1000)) * 255).astype(np.uint8), (5, 5), 0)
    asphalt = (asphalt // 4 + 80).astype(np.uint8)
    ys, xs = np.mgrid[0 : size[1], 0 : size[0]].astype(np.float32)
    below = np.maximum(ys - horizon, 1e-3)
    ahead = 1000.0 * 1.2 / below  # metres ahead of each pixel's road point
    aside = (xs - 640.0) * ahead / 1000.0
    finder, turns = LaneFinder(), []
    turn = cv2.getRotationMatrix2D(((size[0] - 1) / 2, (size[1] - 1) / 2), turn_deg, 1.0)
    for k in range(frames):
        # 10 texture pixels a metre; the texture's rows run away from the camera.
        map_x = np.where(ys > horizon + 2, aside * 10 + 500, 0).astype(np.float32)
        map_y = np.where(ys > horizon + 2, 1990 - (ahead + k * step_m) * 10, 0).astype(np.float32)
        grey = cv2.remap(asphalt, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        grey[ys <= horizon + 2] = 200
        turned = cv2.warpAffine(np.dstack([grey] * 3), turn, size, borderMode=cv2.BORDER_REPLICATE)
        read = finder.process(turned, horizon, read_turn=True).road_turn_deg
        if read is not None:
            turns.append(read)
    return turns


@pytest.mark.parametrize("turn", [-3.0, 0.0, 3.0])
def test_a_turned_pictures_road_moves_faster_on_the_side_turned_up(turn: float) -> None:
    """The synthetic road streaming past a turned camera reads its turn within half a degree
    in most frames once both sides' advances are in; without `read_turn` none is read."""
    turns = _turned_asphalt(turn)
    assert len(turns) >= 20 and abs(np.median(turns) - turn) < 0.5, turns
    assert np.mean(np.abs(np.asarray(turns) - turn) < 0.5) > 0.8, turns


def test_the_roads_turn_stands_in_for_a_second_vehicle_or_alone_for_none() -> None:
    """The road's turns, as the lane stage reads them a frame at a time: alone (no vehicle's
    leans in), 50 that agree read the turn, 49 do not, nor do ones that scatter or stay near
    level (50 of those end the road's reading: no rule takes them, and it costs the lane stage
    a few milliseconds a frame); with one vehicle's leans, the turn is the leans' where the
    road reads a turn too, within 1.5 degrees of them, and none where it reads level or near
    it."""
    rng = np.random.default_rng(0)
    none, no_ids = np.zeros((0, 4)), np.zeros(0, int)
    blank = np.zeros((120, 160, 3), np.uint8)

    def fed(turns: np.ndarray, reading: RollReading | None = None) -> RollReading:
        reading = reading if reading is not None else RollReading()
        for turn in turns:
            reading.update(blank, none, no_ids, road_turn=float(turn))
        return reading

    steady = 3.0 + rng.normal(0, 0.2, 50)
    assert fed(steady[:49]).roll_deg is None
    alone = fed(steady)
    assert alone.roll_deg is not None and abs(alone.roll_deg - 3.0) < 0.2 and alone.cue == "road"
    scattered = fed(3.0 + rng.normal(0, 2.0, 100))
    assert scattered.roll_deg is None and scattered.wants_road
    near_level = fed(1.2 + rng.normal(0, 0.2, 50))
    assert near_level.roll_deg is None and not near_level.wants_road  # no rule could take it
    assert fed(steady[:49]).wants_road
    box = np.array([[40.0, 50.0, 200.0, 190.0]])
    # The road within 1.5 degrees of the leans but itself under 1.5 off level says level.
    for road, read in ((3.6, True), (1.2, False), (-0.5, False)):
        one = RollReading()
        for k in range(30):  # one vehicle's leans: not the picture's on their own
            one.update(_rear(2.5, k), box, np.array([1]))
        assert one.roll_deg is None
        fed(road + rng.normal(0, 0.2, 50), one)
        if read:
            assert one.roll_deg is not None and abs(one.roll_deg - 2.5) < 0.35, one.roll_deg
            assert one.cue == "vehicle and road"
        else:
            assert one.roll_deg is None
    # A vehicle's leans saying level outweigh the road.
    level = RollReading()
    for k in range(30):
        level.update(_rear(0.0, k), box, np.array([1 + k % 2]))
    assert fed(steady, level).roll_deg is None


@pytest.mark.parametrize("turn", [-3.0, 0.0, 3.0])
def test_the_shared_clips_road_reads_its_turn(data_dir: Path, turn: float) -> None:
    """project_cut_2 undistorted and turned about its centre (its lane lines beyond the next
    lane spread out of the picture, and it has one car ahead: neither the lines nor the leans
    read 3 degrees anticlockwise): the road's turns that the lane stage reads over its frames
    agree within a degree a frame (their quartiles), their median within 0.8 of the turn."""
    from app.reframe import Framing, reframe_image
    from app.sources import probe_video, read_frames
    from camera_cal import build_undistorter, default_calibration_path, load_calibration

    video = data_dir / "videos" / "project_cut_2.mp4"
    info = probe_video(video)
    undistort = build_undistorter(load_calibration(default_calibration_path()), info.size)
    finder, turns = LaneFinder(), []
    for frame in read_frames(video, info):
        turned = reframe_image(undistort(frame), Framing("turned", roll=turn))
        read = finder.process(turned, read_turn=True).road_turn_deg
        if read is not None:
            turns.append(read)
    q1, median, q3 = np.quantile(turns, [0.25, 0.5, 0.75])
    assert len(turns) >= 60 and q3 - q1 < 1.0 and abs(median - turn) < 0.8, (q1, median, q3)
