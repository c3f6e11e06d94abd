"""The camera's roll read off the vehicles' rear edges (camera_cal/level.py), on synthetic rears
made here; the shared clips turned and levelled are in test_process_cli."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from camera_cal.level import LaneLattice, LevelConfig, RollReading, edge_lean


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
    it is not (lanes of unequal width read as a turn); read off the lines, `by_lines` says so."""
    box = np.array([[40.0, 50.0, 200.0, 190.0]])
    roads = [_road(FIVE_LANES, EDGES, -3.0, seed=seed) for seed in range(12)]
    none, no_ids = np.zeros((0, 4)), np.zeros(0, int)
    lines = RollReading()
    turns = [lines.update(road, none, no_ids, vanishing) for road, vanishing in roads]
    assert turns[-1] is not None and abs(turns[-1] + 3.0) < 0.4 and lines.by_lines, turns
    vetoed = RollReading()
    for seed in range(20):
        vetoed.update(_rear(0.0, seed), box, np.array([1 + seed % 2]))
    assert all(vetoed.update(road, none, no_ids, vanishing) is None for road, vanishing in roads)
    assert vetoed.lattice.turn_deg is not None
