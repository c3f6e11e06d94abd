"""The camera's roll read off the vehicles' rear edges (camera_cal/level.py), on synthetic rears
made here; the shared clips turned and levelled are in test_process_cli."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from camera_cal.level import LevelConfig, RollReading, edge_lean


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
