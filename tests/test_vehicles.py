"""Vehicle detector: dense scoring, pasted vehicles, Heatmap history, tracker ids, real clips."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from app.evaluate import FrameLabels, evaluate, iou, load_labels
from app.record import vehicles_record
from app.sources import probe_video, read_frames
from app.traffic import mirrored_detections
from camera_cal import build_undistorter, default_calibration_path, load_calibration
from tests.helpers import process_clip, raised_camera
from vehicles.config import Band, DetectorConfig, HeatConfig, TrackConfig
from vehicles.detections import Detections, cut_edges
from vehicles.detector import (
    Scorer,
    VehicleDetector,
    chroma_smoothed,
    mirror_backed,
    parts_of_larger,
    seen_picture,
)
from vehicles.features import feature_maps, patch_features
from vehicles.heatmap import Heatmap
from vehicles.model import (
    VehicleModel,
    default_lowres_path,
    default_model_path,
    default_small_paths,
    default_verifier_path,
    load_model,
)
from vehicles.refine import reach_toward, snap_bottoms, snap_tops
from vehicles.search import (
    BandHits,
    LinearWeights,
    View,
    score_windows,
    score_windows_at,
    search_band,
)
from vehicles.tracker import Tracker, entering_sides, road_velocity


def plain_heat(**settings: Any) -> HeatConfig:
    """Heat settings with every side rule and box correction off unless asked for."""
    return HeatConfig(**{"edge_peak_fraction": None, **settings})


def plain_tracking(**settings: Any) -> TrackConfig:
    """Tracking without velocity or frame-side rules unless asked for."""
    return TrackConfig(**{"velocity_gain": 0.0, "min_inside": 0.0, **settings})


@pytest.fixture(scope="module")
def model() -> VehicleModel:
    return load_model(default_model_path())


def _rgb(path: Path) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(cv2.imread(str(path)), np.uint8)[:, :, ::-1])


def test_dense_scores_equal_window_by_window(model: VehicleModel, data_dir: Path) -> None:
    frame = _rgb(data_dir / "test_images" / "test4.jpg")
    band = Band(window=96 / 720, top=390 / 720, bottom=540 / 720, left=0.5, right=1.0)
    view = View((1280, 720), 420.8, (0, 0, 1280, 720), 720.0)
    hits = search_band(frame, band, LinearWeights.from_model(model), view, 420.8 / 720)
    assert hits is not None
    # The same windows cut out of the same scaled band and scored one by one.
    x0, y0, scale = 640, 390, 1.5
    crop = frame[390:540, 640:1280]
    size = (round(640 / scale), round(150 / scale))
    scaled = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
    rng = np.random.default_rng(0)
    for k in rng.choice(len(hits.decisions), 25, replace=False):
        bx, by = hits.boxes[k, 0], hits.boxes[k, 1]
        px = round((bx - x0) / (640 / size[0]))
        py = round((by - y0) / (150 / size[1]))
        patch = np.ascontiguousarray(scaled[py : py + 64, px : px + 64])
        one = model.decision_function(patch_features(patch, model.config)[None])[0]
        assert hits.decisions[k] == pytest.approx(one, abs=1e-4)


def test_the_verifier_reads_only_the_windows_that_could_heat(
    model: VehicleModel, data_dir: Path
) -> None:
    """A band's verifier and mirror-image scores are taken at the windows whose own decision
    reaches `heats_from` alone, and there they are what scoring the whole band gives."""
    frame = _rgb(data_dir / "test_images" / "test1.jpg")
    band = Band(window=96 / 720, top=390 / 720, bottom=540 / 720, left=0.5, right=1.0)
    view = View((1280, 720), 420.8, (0, 0, 1280, 720), 720.0)
    weights, verifier = LinearWeights.from_model(model), load_model(default_verifier_path())
    checks = LinearWeights.from_model(verifier), weights.mirrored()
    every = search_band(frame, band, weights, view, 420.8 / 720, *checks, heats_from=-np.inf)
    least = model.decision_at(0.5)
    hits = search_band(frame, band, weights, view, 420.8 / 720, *checks, heats_from=least)
    assert every is not None and hits is not None
    due = hits.decisions >= least
    assert 0 < due.sum() < len(due) / 4  # test1's two cars; most of the band is road
    for part in ("verified", "mirrored"):
        some, all_of = getattr(hits, part), getattr(every, part)
        assert not np.isnan(all_of).any() and np.isnan(some[~due]).all()
        np.testing.assert_allclose(some[due], all_of[due], atol=1e-4)


def test_mirrored_weights_score_each_windows_mirror_image(
    model: VehicleModel, data_dir: Path
) -> None:
    """The mirrored weights read a band as the weights read the band flipped left to right (at
    the mirrored window), and scoring chosen windows gives what scoring the whole band does."""
    band = _rgb(data_dir / "test_images" / "test1.jpg")[384:528, 200:1000]
    weights = LinearWeights.from_model(model)
    maps = feature_maps(band, model.config)
    plain = score_windows(maps, weights)
    mirrored = score_windows(maps, weights.mirrored())
    flipped_maps = feature_maps(np.ascontiguousarray(band[:, ::-1]), model.config)
    flipped = score_windows(flipped_maps, weights)
    np.testing.assert_allclose(mirrored, flipped[:, ::-1], atol=1e-4)
    assert np.abs(mirrored - plain).max() > 1.0  # a road's windows are no mirror images
    rows, cols = np.nonzero(plain > -np.inf)
    at = score_windows_at(maps, weights, rows, cols)
    np.testing.assert_allclose(at, plain.ravel(), atol=1e-4)
    pick = np.array([0, 5, len(rows) - 1])
    np.testing.assert_allclose(
        score_windows_at(maps, weights.mirrored(), rows[pick], cols[pick]),
        mirrored.ravel()[pick],
        atol=1e-4,
    )


def test_a_window_stands_by_its_mirror_image_or_one_around_it() -> None:
    """A window whose mirror image is no vehicle heats only where its centre lies in a window
    sure of itself and of its mirror image (a car's corner seen partly from its side)."""
    boxes = np.array(
        [
            [100.0, 100.0, 164.0, 164.0],  # backing
            [130.0, 110.0, 194.0, 174.0],  # not symmetric, its centre (162, 142) in the first
            [300.0, 100.0, 364.0, 164.0],  # not symmetric, alone
            [500.0, 100.0, 564.0, 164.0],  # symmetric, not backing
            [520.0, 110.0, 584.0, 174.0],  # not symmetric, its centre only in that one
        ]
    )
    symmetric = np.array([True, False, False, True, False])
    backing = np.array([True, False, False, False, False])
    assert mirror_backed(boxes, symmetric, backing).tolist() == [True, True, False, True, False]
    alone = mirror_backed(boxes, symmetric, np.zeros(5, bool))
    assert alone.tolist() == symmetric.tolist()


def _vehicle_patch(data_dir: Path) -> np.ndarray:
    with zipfile.ZipFile(data_dir / "vehicles.zip") as archive:
        data = archive.read("vehicles/KITTI_extracted/5.png")
    return np.asarray(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))[:, :, ::-1]


@pytest.mark.parametrize(("size", "x", "y"), [(64, 300, 400), (96, 500, 410), (128, 880, 420)])
def test_pasted_vehicle_is_found(
    model: VehicleModel, data_dir: Path, size: int, x: int, y: int
) -> None:
    road = _rgb(data_dir / "test_images" / "straight_lines1.jpg").copy()
    patch = cv2.resize(_vehicle_patch(data_dir), (size, size), interpolation=cv2.INTER_CUBIC)
    road[y : y + size, x : x + size] = patch
    detector = VehicleDetector(model, DetectorConfig().for_still())
    found = detector.process(road).detections
    truth = (x, y, x + size, y + size)
    assert len(found) >= 1
    assert max(iou(box, truth) for box in found.boxes) >= 0.5


def test_the_verifier_vetoes_windows_but_the_model_places_them(
    model: VehicleModel, data_dir: Path
) -> None:
    """A pasted car: with the shipped verifier the same box as without one; a verifier that
    accepts nothing leaves nothing; one trained on other features is refused."""
    from dataclasses import replace

    from vehicles.features import FeatureConfig
    from vehicles.model import ModelError, default_verifier_path

    road = _rgb(data_dir / "test_images" / "straight_lines1.jpg").copy()
    road[400:496, 300:396] = cv2.resize(_vehicle_patch(data_dir), (96, 96))
    still = DetectorConfig().for_still()
    alone = VehicleDetector(model, still).process(road).detections
    verifier = load_model(default_verifier_path())
    checked = VehicleDetector(model, still, verifier=verifier).process(road).detections
    assert len(alone) >= 1 and np.allclose(checked.boxes, alone.boxes, atol=8)
    never = replace(verifier, intercept=-1e6)
    assert len(VehicleDetector(model, still, verifier=never).process(road).detections) == 0
    other = replace(verifier, config=FeatureConfig(color_space="LUV"))
    with pytest.raises(ModelError, match="other features"):
        VehicleDetector(model, still, verifier=other)


def test_on_a_dark_road_the_dark_verifier_checks_the_windows(
    model: VehicleModel, data_dir: Path
) -> None:
    """A pasted car: a dark verifier that accepts nothing leaves it boxed where the road reads
    as daylight (or is not measured) and unboxed where it reads as dusk; the 64 px bands of
    either model, sharp or low-resolution, are checked by it there, the 32 px bands keep their
    own verifier; without a dark verifier the verifier checks every road."""
    from dataclasses import replace

    road = _rgb(data_dir / "test_images" / "straight_lines1.jpg").copy()
    road[400:496, 300:396] = cv2.resize(_vehicle_patch(data_dir), (96, 96))
    still = DetectorConfig().for_still()
    verifier = load_model(default_verifier_path())
    never = replace(verifier, intercept=-1e6)
    lowres, small = load_model(default_lowres_path()), _small()
    dusk = still.dark_road[2] - 1
    # (The 32 px bands, checked by their own verifier, would find it at dusk: left out here.)
    for grey, boxed in ((None, True), (still.dark_road[2], True), (dusk, False)):
        sharp = VehicleDetector(model, still, verifier=verifier, dark_verifier=never)
        found = sharp.process(road, road_grey=grey).detections
        assert (len(found) >= 1) == boxed, grey
    detector = VehicleDetector(
        model, still, verifier=verifier, small=small, lowres=lowres, dark_verifier=never
    )
    for size in ((640, 360), (1280, 720)):
        scorers = detector.scorers_for(detector.view(size), dark=True)
        assert scorers[64].verifier is never and scorers[32] is small, size
        assert detector.scorers_for(detector.view(size))[64].verifier is verifier
    plain = VehicleDetector(model, still, verifier=verifier)
    assert len(plain.process(road, road_grey=dusk).detections) >= 1
    assert plain.scorers_for(plain.view((1280, 720)), dark=True)[64].verifier is verifier


def test_a_monochrome_picture_is_read_by_the_grey_models() -> None:
    """The shipped stage reads a monochrome picture with the models trained on grey patches
    (64 and 32 px, each with its grey verifier) whatever its size or light, from P(vehicle)
    0.98; a colour one as before. A model of the user's own reads every picture."""
    from app.assembly import build_stages

    detector = build_stages(lanes=False).vehicles
    assert isinstance(detector, VehicleDetector)
    for size in ((640, 360), (1280, 720)):
        view = detector.view(size)
        for dark in (False, True):
            grey = detector.scorers_for(view, dark, monochrome=True)
            assert sorted(grey) == [32, 64], size
            assert all(s.model.report["grey"] and s.verifier is not None for s in grey.values())
            assert all(s.verifier.report["grey"] for s in grey.values() if s.verifier)
            colour = detector.scorers_for(view, dark)
            assert not any(s.model.report.get("grey") for s in colour.values())
    config = detector.config
    assert config.min_probability_at(30.0, monochrome=True) == config.monochrome_min_probability
    assert config.min_probability_at(None) == config.min_probability
    own = build_stages(lanes=False, model=default_model_path()).vehicles
    assert isinstance(own, VehicleDetector)
    assert own.scorers_for(own.view((1280, 720)), monochrome=True)[64].model is own.model


def test_a_stage_without_grey_models_reads_a_monochrome_picture_as_any(
    model: VehicleModel, data_dir: Path
) -> None:
    """Told a picture is monochrome, a stage without grey scorers (a model of the user's own)
    reads it with its models at their own bound, not the grey models' stricter one."""
    frame = _rgb(data_dir / "test_images" / "test1.jpg")
    still = DetectorConfig().for_still()
    told, untold = (
        VehicleDetector(model, still).process(frame, monochrome=m) for m in (True, False)
    )
    assert len(untold.detections) >= 2
    np.testing.assert_array_equal(told.detections.boxes, untold.detections.boxes)


def _small() -> Scorer:
    model, verifier = default_small_paths()
    return Scorer.of(load_model(model), load_model(verifier))


@pytest.mark.parametrize(
    ("rows", "size", "least", "gain"),
    [(720, 22, 12, 8), (720, 28, 12, 6), (540, 16, 10, 8), (480, 15, 10, 8), (360, 11, 8, 8)],
)
def test_cars_3_to_4_percent_tall_are_found_by_the_small_model(
    model: VehicleModel, data_dir: Path, rows: int, size: int, least: int, gain: int
) -> None:
    """Twenty cars of the training set shrunk to 3-4 % of the height (22 and 28 px at 720 rows,
    16 at 540, 15 at 480, 11 at 360) and pasted where a car that size meets the road: the 32 px
    model's windows of 24 px at 720 rows (12 at 360) find most (at 360 rows about half), the
    64 px model's bands alone hardly any. (The model
    knows these cars: this tests the search, its band, heat, part rule and smallest box; the
    clips measure the classifier.)"""
    with zipfile.ZipFile(data_dir / "vehicles.zip") as archive:
        names = sorted(n for n in archive.namelist() if n.endswith(".png"))
        cars = [
            np.asarray(cv2.imdecode(np.frombuffer(archive.read(n), np.uint8), 1))[:, :, ::-1]
            for n in names[:: len(names) // 20][:20]
        ]
    road = _rgb(data_dir / "test_images" / "straight_lines1.jpg")
    if rows != 720:
        shape = (round(rows * 16 / 9), rows)
        road = np.ascontiguousarray(cv2.resize(road, shape, interpolation=cv2.INTER_AREA))
    still = DetectorConfig().for_still()
    verifier = load_model(default_verifier_path())
    found = {"with": 0, "without": 0}
    for car in cars:
        frame = road.copy()
        x0, y1 = round(560 * rows / 720), round(421 * rows / 720) + round(1.2 * size)
        frame[y1 - size : y1, x0 : x0 + size] = cv2.resize(
            car, (size, size), interpolation=cv2.INTER_AREA
        )
        truth = (x0, y1 - size, x0 + size, y1)
        for name, small in (("with", _small()), ("without", None)):
            boxes = VehicleDetector(model, still, verifier=verifier, small=small).process(frame)
            if any(iou(box, truth) >= 0.5 for box in boxes.detections.boxes):
                found[name] += 1
    assert found["with"] >= least, found
    assert found["with"] >= found["without"] + gain, found


def test_a_camera_mounted_higher_finds_cars_when_told_its_height(
    model: VehicleModel, data_dir: Path
) -> None:
    """A camera 1.6 times higher (a lorry's) sees a car 1/1.6 the size where it meets the road.
    Twenty training-set cars pasted so on the raised road (30 and 70 px): the windows sized for
    the tuned camera find none; told the camera's height (--camera-height), the pipeline sizes
    them for it and finds most. The lanes' width alone does not move them (see the pipeline)."""
    from app.mounting import Mounting
    from app.pipeline import Pipeline

    with zipfile.ZipFile(data_dir / "vehicles.zip") as archive:
        names = sorted(n for n in archive.namelist() if n.endswith(".png"))
        cars = [
            np.asarray(cv2.imdecode(np.frombuffer(archive.read(n), np.uint8), 1))[:, :, ::-1]
            for n in names[:: len(names) // 20][:20]
        ]
    horizon, factor = 421.0, 1.6
    road = raised_camera(_rgb(data_dir / "test_images" / "straight_lines1.jpg"), horizon, factor)
    still = DetectorConfig().for_still()
    verifier = load_model(default_verifier_path())
    for size, least in ((30, 14), (70, 14)):
        found = {None: 0, 1.236 * factor: 0}
        for car in cars:
            frame = road.copy()
            x0, y1 = 560, round(horizon + 1.2 * size * factor)
            frame[y1 - size : y1, x0 : x0 + size] = cv2.resize(
                car, (size, size), interpolation=cv2.INTER_AREA
            )
            truth = (x0, y1 - size, x0 + size, y1)
            for height in found:
                detector = VehicleDetector(model, still, verifier=verifier, small=_small())
                with Pipeline(None, None, detector, mounting=Mounting(horizon, height)) as p:
                    p.prepare((frame.shape[1], frame.shape[0]))
                    result = p.run(frame).result.vehicles
                assert result is not None
                if any(iou(box, truth) >= 0.5 for box in result.detections.boxes):
                    found[height] += 1
        assert found[None] <= 2 and found[1.236 * factor] >= least, (size, found)


def test_the_small_band_is_searched_only_where_its_windows_have_11_pixels(
    model: VehicleModel, data_dir: Path
) -> None:
    """24 px windows at 720 rows are 12 px at 360 and 8 px at 240: too few pixels for the
    32 px model's 8 px cells (a car 3 % of 240 rows is 7 px), so that band is not searched
    there."""
    frame = _rgb(data_dir / "test_images" / "test1.jpg")
    detector = VehicleDetector(model, small=_small())
    for size, searched in (((1280, 720), True), ((640, 360), True), ((427, 240), False)):
        scaled = np.ascontiguousarray(cv2.resize(frame, size, interpolation=cv2.INTER_AREA))
        hits = detector.search(scaled, view=detector.view(size))
        assert any(hit.band.patch == 32 for hit in hits) == searched
    # Without a small model the band is skipped.
    plain = VehicleDetector(model).search(frame)
    assert not any(hit.band.patch == 32 for hit in plain) and plain


def test_a_small_window_inside_a_larger_hit_is_a_part_of_that_car() -> None:
    """A 24 px window firing on a near car's tail light is no car of its own; one beside it is."""
    small = Band(window=0.1, top=0.5, bottom=0.7, part_ratio=2.0, patch=32)
    large = Band(window=0.2, top=0.5, bottom=0.9)
    hits = (
        BandHits(
            small, 24.0, np.array([[100.0, 100, 124, 124], [300, 100, 324, 124]]), np.zeros(2)
        ),
        BandHits(large, 64.0, np.array([[80.0, 80, 144, 144]]), np.zeros(1)),
    )
    boxes = np.concatenate([h.boxes for h in hits])
    strong = np.array([True, True, True])
    assert parts_of_larger(hits, boxes, strong).tolist() == [True, False, False]
    # A larger window that did not fire makes nothing a part.
    assert not parts_of_larger(hits, boxes, np.array([True, True, False])).any()


@pytest.mark.parametrize(("size", "side"), [(96, "right"), (128, "right"), (128, "left")])
def test_vehicle_cut_by_the_frame_edge_is_found(
    model: VehicleModel, data_dir: Path, size: int, side: str
) -> None:
    # A car entering the frame: a bit under half of it is in the picture.
    road = _rgb(data_dir / "test_images" / "straight_lines1.jpg").copy()
    patch = cv2.resize(_vehicle_patch(data_dir), (size, size), interpolation=cv2.INTER_CUBIC)
    visible, y = round(0.45 * size), 420
    if side == "right":
        road[y : y + size, -visible:] = patch[:, :visible]
        truth = (1280 - visible, y, 1280, y + size)
    else:
        road[y : y + size, :visible] = patch[:, -visible:]
        truth = (0, y, visible, y + size)
    detector = VehicleDetector(model, DetectorConfig().for_still())
    found = detector.process(road).detections
    assert len(found) >= 1
    assert max(iou(box, truth) for box in found.boxes) >= 0.5


def test_heatmap_suppresses_a_one_frame_false_alarm() -> None:
    heatmap = Heatmap(plain_heat(history=8))
    steady = np.array([[400.0, 400, 496, 496]] * 4)  # four overlapping windows every frame
    alarm = np.array([[100.0, 420, 164, 484]] * 4)
    for frame in range(8):
        boxes = np.vstack([steady, alarm]) if frame == 5 else steady
        heatmap.add((1280, 720), boxes, np.ones(len(boxes)))
        found, _ = heatmap.regions()
        assert not any(b[2] < 300 for b in found)  # the single-frame alarm never shows
    assert len(found) == 1 and iou(found[0], steady[0]) > 0.8


def test_heatmap_places_a_moving_vehicle_where_it_is_now() -> None:
    heatmap = Heatmap(plain_heat(history=8, recent=1))
    for frame in range(8):  # a strongly detected car crossing the image at 20 px per frame
        x = 600 - 20 * frame
        windows = np.array(
            [[x - 8.0, 420, x + 56, 468], [x, 420, x + 64, 468], [x + 8, 420, x + 72, 468]]
        )
        heatmap.add((1280, 720), windows, np.full(3, 8.0))
    found, _ = heatmap.regions()
    assert len(found) == 1
    assert iou(found[0], [460, 420, 524, 468]) > 0.8  # its last place, not its trail


def _regions_of(windows: np.ndarray, **settings: Any) -> np.ndarray:
    """Region boxes of one frame of equally weighted windows under the given heat settings."""
    heatmap = Heatmap(plain_heat(history=1, **settings))
    heatmap.add((1280, 720), windows, np.ones(len(windows)) * 3)
    return heatmap.regions()[0]


def test_heatmap_splits_two_touching_vehicles() -> None:
    windows = []
    for cx in (400, 528):  # two cars side by side: their heat touches above the threshold
        for dx in (-16, 0, 16):
            windows.append([cx - 48 + dx, 400, cx + 48 + dx, 480])
    boxes = np.array(windows, float)
    assert len(_regions_of(boxes, split_valley=0.0)) == 1  # never splitting: one merged box
    found = _regions_of(boxes)
    assert len(found) == 2
    assert max(iou(found[0], [352, 400, 448, 480]), iou(found[1], [352, 400, 448, 480])) > 0.6


def test_heatmap_box_of_a_vehicle_at_the_frame_side_covers_its_inner_part() -> None:
    # A car at x 1168-1280: windows past the side (seeing it and its mirror image) pile heat on
    # its outer part; one inside the frame covers all of it.
    windows = np.array([[1216.0, 420, 1344, 540]] * 4 + [[1168.0, 420, 1296, 540]])
    narrow = _regions_of(windows)
    found = _regions_of(windows, edge_peak_fraction=0.15)
    assert len(narrow) == len(found) == 1
    assert narrow[0][0] >= 1200  # the usual cut-off keeps only the piled-up part
    assert iou(found[0], [1168, 420, 1280, 540]) > 0.9


def test_boxes_reach_towards_the_vanishing_column_but_not_past_it_nor_at_the_sides() -> None:
    live = (0, 0, 1280, 720)
    boxes = np.array(
        [
            [800.0, 400, 900, 470],  # right of the column: its side faces left
            [300.0, 400, 400, 470],  # left of it: its side faces right
            [600.0, 400, 700, 470],  # astride it: no side shows
            [645.0, 400, 745, 470],  # 5 px right of it: reaches the column only
            [0.0, 400, 100, 470],  # at the picture's sides: kept
            [1180.0, 400, 1280, 470],
        ]
    )
    reached = reach_toward(boxes, 640.0, 0.08, live, tolerance=2)
    assert reached.tolist() == [
        [792.0, 400, 900, 470],
        [300.0, 400, 408, 470],
        [600.0, 400, 700, 470],
        [640.0, 400, 745, 470],
        [0.0, 400, 100, 470],
        [1180.0, 400, 1280, 470],
    ]
    assert reach_toward(boxes, 640.0, 0.0, live).tolist() == boxes.tolist()


def test_a_box_crossing_the_picture_quickly_reaches_the_way_it_moves() -> None:
    # An oncoming car left of the column moving left 20 px a frame (a fifth of its width): its
    # heat trails it, so its box reaches half a frame's motion left, not right; one moving right
    # as fast reaches right; a slow one reaches the column.
    live = (0, 0, 1280, 720)
    boxes = np.array([[300.0, 400, 400, 470], [300.0, 400, 400, 470], [800.0, 400, 900, 470]])
    motion = np.array([-20.0, 20.0, 2.0])
    moved = reach_toward(boxes, 640.0, 0.08, live, motion=motion, fast=0.12, lead=0.5)
    assert moved.tolist() == [
        [290.0, 400, 400, 470],
        [300.0, 400, 410, 470],
        [792.0, 400, 900, 470],
    ]


def test_box_bottoms_move_to_where_the_shadow_meets_the_road() -> None:
    # A grey road, a pale car body over rows 200-260 and its dark shadow and tyres to row 272.
    frame = np.full((400, 600, 3), 120, np.uint8)
    frame[200:260, 250:350] = 200
    frame[260:272, 245:355] = 30
    live = (0, 0, 600, 400)
    heat = np.array([[250.0, 195.0, 350.0, 290.0], [250.0, 195.0, 350.0, 262.0]])
    snapped = snap_bottoms(frame, heat, live)
    # Both bottoms (18 px too low, 10 px too high) land on the shadow's lower edge.
    assert np.abs(snapped[:, 3] - 272).max() <= 1
    assert (snapped[:, :3] == heat[:, :3]).all()
    # On an even road (a dark night) nothing brightens: the heat's bottom stays.
    night = np.full((400, 600, 3), 25, np.uint8)
    assert (snap_bottoms(night, heat, live) == heat).all()


def test_box_tops_move_to_the_roof() -> None:
    # A pale car (rows 200-260, its roof narrower: columns 270-330 from row 200, the body from
    # row 215) before darker trees; heat reaching 12 px above the roof and 4 px short of it.
    frame = np.full((400, 600, 3), 70, np.uint8)
    frame[200:215, 270:330] = 210
    frame[215:260, 250:350] = 200
    live = (0, 0, 600, 400)
    heat = np.array([[250.0, 188.0, 350.0, 262.0], [250.0, 204.0, 350.0, 262.0]])
    snapped = snap_tops(frame, heat, live)
    assert np.abs(snapped[:, 1] - 200).max() <= 1
    assert (snapped[:, [0, 2, 3]] == heat[:, [0, 2, 3]]).all()
    # Nothing changes across an even picture, and a box cut by the picture's side (its middle
    # is not the car's) keeps its top.
    assert (snap_tops(np.full_like(frame, 70), heat, live) == heat).all()
    cut = np.array([[0.0, 188.0, 100.0, 262.0]])
    side = frame.copy()
    side[200:260, 0:100] = 200
    assert (snap_tops(side, cut, live) == cut).all()


@pytest.mark.slow
def test_snapped_tops_fit_the_labelled_cars_better(data_dir: Path) -> None:
    """project_cut_2, whose cars' heat reaches above their roofs (the white car's box stood 10-20
    px above it): with the tops snapped the matched boxes overlap the labels more, and as many
    cars are matched."""
    snapped = _clip_scores(data_dir, "project_cut_2")
    heat = _clip_scores(data_dir, "project_cut_2", top_reach=None)
    assert snapped["true_positives"] >= heat["true_positives"]
    assert snapped["false_positives"] <= heat["false_positives"]
    assert snapped["mean_iou"] >= heat["mean_iou"] + 0.015, (snapped, heat)


def test_track_ids_stay_constant_on_a_moving_box() -> None:
    tracker = Tracker(plain_tracking(confirm_frames=3, max_missed=5, show_missed=2))
    ids = []
    for frame in range(30):
        x = 300 + 6 * frame
        boxes = np.array([[x, 400, x + 100, 470], [900 - 4 * frame, 410, 1000 - 4 * frame, 480]])
        if frame in (12, 13):  # a short miss of the second car
            boxes = boxes[:1]
        shown = tracker.update(Detections.from_boxes(boxes, np.ones(len(boxes))))
        ids.append(sorted(shown.ids.tolist()))
    assert ids[0] == [] and ids[1] == []  # not shown until confirmed
    assert all(i == [1, 2] for i in ids[2:])  # same ids throughout, kept through the miss
    for _ in range(6):
        shown = tracker.update(Detections.from_boxes(np.zeros((0, 4)), np.zeros(0)))
    assert len(shown) == 0 and not tracker.tracks  # dropped after several frames unseen


def test_track_ids_count_shown_vehicles_only() -> None:
    tracker = Tracker(plain_tracking(confirm_frames=3, max_missed=2, show_missed=1))
    car = np.array([[400.0, 400, 500, 470]])
    blips = [np.array([[100.0 + 150 * k, 420, 160 + 150 * k, 460]]) for k in range(3)]
    shown = tracker.update(Detections.from_boxes(car, np.ones(1)))
    for blip in blips:  # three one-frame alarms in different places: none is ever shown
        boxes = np.vstack([car, blip])
        shown = tracker.update(Detections.from_boxes(boxes, np.ones(2)))
        assert len(shown) <= 1
    later = np.array([[800.0, 400, 900, 470]])
    for _ in range(3):
        shown = tracker.update(Detections.from_boxes(np.vstack([car, later]), np.ones(2)))
    assert sorted(shown.ids.tolist()) == [1, 2]  # the second vehicle shown is 2, not 5


def test_a_vehicle_lost_for_a_while_keeps_its_id_where_it_would_have_driven() -> None:
    """A car unseen longer than a track coasts (dropped) is given its id back when found again
    where its motion could have brought it, within `forget_missed` frames; a car found
    elsewhere, found later, or one coming in where another left the picture gets a new id."""
    picture = (0.0, 0.0, 1280.0, 720.0)

    def tracker() -> Tracker:
        return Tracker(
            plain_tracking(
                confirm_frames=3,
                max_missed=4,
                show_missed=2,
                forget_missed=20,
                velocity_gain=0.3,
                min_inside=0.9,
            )
        )

    def ids_after(gap: int, found_off: float = 0.0, speed_up: float = 1.0) -> list[list[int]]:
        """A car we pass, 8 px a frame to the left, hidden from frame 10 for `gap` frames and
        found `found_off` px right of where it is, moving `speed_up` times as fast since."""
        follow = tracker()
        seen = []
        for frame in range(40):
            hidden = max(0, min(frame, 10 + gap) - 10)
            x = 600.0 - 8 * (frame - hidden) - 8 * speed_up * hidden
            x += found_off if frame >= 10 + gap else 0.0
            box = np.array([[x, 400, x + 90, 460]])
            if 10 <= frame < 10 + gap:
                box = np.zeros((0, 4))  # behind glare
            shown = follow.update(Detections.from_boxes(box, np.ones(len(box))), picture)
            seen.append(sorted(shown.ids.tolist()))
        return seen

    rejoined = ids_after(12)
    assert rejoined[9] == [1] and rejoined[14] == []  # not shown while unseen
    assert rejoined[-1] == [1] and all(i in ([], [1]) for i in rejoined)
    assert ids_after(12, found_off=-25.0)[-1] == [1]  # the heat's reach a little off
    assert ids_after(12, speed_up=1.8)[-1] == [1]  # nearing us, it crossed faster
    assert ids_after(12, speed_up=0.0)[-1] == [1]  # held back: found where it was lost
    assert ids_after(12, found_off=300.0)[-1] == [2]  # another car, elsewhere
    assert ids_after(19)[-1] == [2]  # found after it was forgotten
    assert ids_after(3)[-1] == [1]  # a short gap: coasted through, as before

    # A car stopping at the picture's side, its track's box run past it (dropped while seen)
    # and found there again at once: the same car.
    follow = tracker()
    for frame in range(16):
        x = 1000.0 + 30 * min(frame, 6)
        box = np.array([[x, 400, min(x + 100, 1280), 460]])
        shown = follow.update(Detections.from_boxes(box, np.ones(1)), picture)
        assert shown.ids.tolist() in ([], [1]), frame
        if frame == 7:
            assert not follow.tracks  # dropped as it reached past the side
    assert shown.ids.tolist() == [1]

    # A car leaves at the picture's side; one coming in there later is another.
    follow = tracker()
    for frame in range(40):
        x = 300.0 - 20 * frame if frame < 30 else 0.0
        box = np.clip(np.array([[x, 400, x + 90, 460]]), 0, None)
        box = box[(box[:, 2] - box[:, 0]) > 10]
        shown = follow.update(Detections.from_boxes(box, np.ones(len(box))), picture)
        if frame == 10:
            assert shown.ids.tolist() == [1]
    assert shown.ids.tolist() == [2]


def test_a_track_coasting_beside_its_found_again_car_gives_it_its_id() -> None:
    """The same car found again while its old track still coasts (its predicted box spread
    apart from it): the new track takes the id and the old one goes, so no id is shown twice."""
    tracker = Tracker(plain_tracking(confirm_frames=3, max_missed=12, show_missed=12))
    for _ in range(10):
        tracker.update(Detections.from_boxes(np.array([[500.0, 400, 600, 460]]), np.ones(1)))
    tracker.tracks[0].velocity = np.array([-30.0, 0, 30, 0])  # the coasting box spreads
    for _ in range(6):
        tracker.update(Detections())
    for _ in range(3):
        shown = tracker.update(
            Detections.from_boxes(np.array([[505.0, 405, 595, 455]]), np.ones(1))
        )
    assert shown.ids.tolist() == [1] and len(tracker.tracks) == 1


def test_track_moves_a_lagging_measurement_to_where_the_car_is_now() -> None:
    # Heat averaged over two frames boxes a car crossing at 20 px per frame 10 px behind it.
    def last_x1(lag: float) -> float:
        tracker = Tracker(plain_tracking(confirm_frames=3, velocity_gain=0.3), lag=lag)
        for frame in range(25):
            x = 900.0 - 20 * frame + 10
            box = np.array([[x, 420, x + 70, 460]])
            shown = tracker.update(Detections.from_boxes(box, np.ones(1)))
        return float(shown.boxes[0, 0])

    truth_x1 = 900.0 - 20 * 24
    assert abs(last_x1(0.0) - truth_x1) >= 8  # trails the car
    assert abs(last_x1(0.5) - truth_x1) <= 2


def test_a_track_reports_its_velocity_while_measured_and_none_while_coasting() -> None:
    tracker = Tracker(
        plain_tracking(confirm_frames=3, max_missed=5, show_missed=2, velocity_gain=0.3)
    )
    for frame in range(20):
        box = np.array([[400.0 - 15 * frame, 420, 470 - 15 * frame, 460]])
        shown = tracker.update(Detections.from_boxes(box, np.ones(1)))
    (velocity,) = tracker.measured_velocities(shown.ids)
    np.testing.assert_allclose(velocity, [-15, 0, -15, 0], atol=1.0)
    coasting = tracker.update(Detections())
    assert len(coasting) == 1 and not tracker.measured_velocities(coasting.ids).any()


def test_track_follows_a_fast_car_and_drops_it_when_it_leaves() -> None:
    tracker = Tracker(plain_tracking(confirm_frames=3, velocity_gain=0.3, min_inside=0.3))
    boxes = []
    for frame in range(40):  # oncoming: 25 px per frame to the left, 70 px wide
        x = 900 - 25 * frame
        truth = np.array([[x, 420, x + 70, 460]], float)
        seen = truth if x + 70 > 0 else np.zeros((0, 4))
        shown = tracker.update(Detections.from_boxes(seen, np.ones(len(seen))), (0, 0, 1280, 720))
        if 10 <= frame <= 30:
            assert len(shown) == 1 and shown.ids[0] == 1
            assert iou(shown.boxes[0], truth[0]) > 0.8  # on the car, not trailing behind it
        boxes.append(len(shown))
    # Gone from the frame after frame 36: the track leaves with it instead of coasting on.
    assert boxes[36] == 1 and boxes[38] == 0 and not tracker.tracks


@pytest.mark.slow
def test_test_video_vehicles(data_dir: Path, tmp_path: Path) -> None:
    records = process_clip(data_dir / "videos" / "test_video.mp4", tmp_path, "--no-lanes")
    scores = evaluate(load_labels(data_dir / "labels" / "test_video.json"), records)
    v = scores["vehicles"]["iou_0.5"]
    assert v["precision"] >= 0.95 and v["recall"] >= 0.90
    assert v["false_positives_per_frame"] <= 0.05
    assert v["mean_iou"] >= 0.75  # boxes as tight as the labels, not just overlapping
    ids = {d["id"] for r in records[10:] for d in r["vehicles"]}
    assert len(ids) == 2  # the two cars keep one id each through the clip


def _frames_found(
    records: list[dict[str, Any]], labels: dict[int, FrameLabels], vehicle_id: int
) -> tuple[int, int]:
    """(frames where the labelled vehicle is matched at IoU >= 0.5, frames where it is required)."""
    found = required = 0
    for index, frame in labels.items():
        for vehicle in frame.vehicles:
            if vehicle.id != vehicle_id or vehicle.ignore or index < 10:
                continue
            required += 1
            boxes = [d["box"] for d in records[index]["vehicles"]]
            found += any(iou(box, vehicle.box) >= 0.5 for box in boxes)
    return found, required


@pytest.mark.slow
def test_project_cut_2_vehicles(data_dir: Path, tmp_path: Path) -> None:
    records = process_clip(data_dir / "videos" / "project_cut_2.mp4", tmp_path, "--no-lanes")
    labels = load_labels(data_dir / "labels" / "project_cut_2.json")
    v = evaluate(labels, records)["vehicles"]["iou_0.5"]
    assert v["precision"] >= 0.95 and v["false_positives_per_frame"] <= 0.05
    assert v["mean_iou"] >= 0.75  # the target; 0.75 pooled over moved copies too
    # The car ahead is held in every frame; the recall target is not met here because the small
    # oncoming cars behind the railing (ids 3, 4, 6) are not recognised by the classifier.
    found, required = _frames_found(records, labels, 1)
    assert found >= 0.97 * required


@pytest.mark.slow
def test_project_cut_1_vehicles(data_dir: Path, tmp_path: Path) -> None:
    records = process_clip(data_dir / "videos" / "project_cut_1.mp4", tmp_path, "--no-lanes")
    labels = load_labels(data_dir / "labels" / "project_cut_1.json")
    # The white car overtaking on the right is at most half in the frame until frame 45.
    # Over copies moved by a few pixels it is matched in 27-30 of its 41 required frames.
    found, required = _frames_found(records, labels, 1)
    assert found >= 0.62 * required
    # No box trails a car leaving at the side; the small oncoming cars are mostly missed (recall).
    # Over moved copies precision is 0.95-1.00 (see the test on moved copies).
    v = evaluate(labels, records)["vehicles"]["iou_0.5"]
    assert v["false_positives_per_frame"] <= 0.05 and v["precision"] >= 0.93
    assert v["mean_iou"] >= 0.75  # the target (0.76); 0.75 pooled over moved copies


def _moved_records(
    video: Path, model: VehicleModel, scale: float = 1.0, dx: int = 0, dy: int = 0
) -> list[dict[str, Any]]:
    """Records of the vehicle stage on the clip's undistorted frames resized by `scale` and moved
    by (dx, dy) pixels, with the boxes mapped back to the clip's frame."""
    info = probe_video(video)
    undistort = build_undistorter(load_calibration(default_calibration_path()), info.size)
    detector = VehicleDetector(model)
    size = (round(info.size[0] * scale), round(info.size[1] * scale))
    shift = np.array([[1, 0, dx], [0, 1, dy]], dtype=np.float32)
    records = []
    for index, frame in enumerate(read_frames(video, info)):
        moved = undistort(frame)
        if scale != 1.0:
            shrink = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
            moved = np.asarray(cv2.resize(moved, size, interpolation=shrink))
        if dx or dy:
            moved = cv2.warpAffine(moved, shift, size, borderMode=cv2.BORDER_REPLICATE)
        found = detector.process(np.asarray(moved)).detections
        boxes = (found.boxes - [dx, dy, dx, dy]) / scale
        back = Detections.from_boxes(boxes, found.scores, found.ids)
        records.append({"frame": index, "vehicles": vehicles_record(back), "lane": None})
    return records


@pytest.mark.slow
def test_windows_whose_mirror_image_is_no_vehicle_box_no_barrier(
    model: VehicleModel, data_dir: Path
) -> None:
    """project_cut_2 mirrored (its median barrier on the right, where the model, which knows it
    on the left, takes some of it for a car): windows that do not stand by their mirror image
    heat nothing, so fewer false boxes, and the same cars are found."""
    from dataclasses import replace

    video = data_dir / "videos" / "project_cut_2.mp4"
    info = probe_video(video)
    undistort = build_undistorter(load_calibration(default_calibration_path()), info.size)
    frames = [np.ascontiguousarray(undistort(f)[:, ::-1]) for f in read_frames(video, info)]
    labels = load_labels(data_dir / "labels" / "project_cut_2.json")
    verifier = load_model(default_verifier_path())
    scores = {}
    for check in (None, 0.5):
        detector = VehicleDetector(
            model, replace(DetectorConfig(), min_mirrored=check), verifier=verifier
        )
        records = []
        for index, frame in enumerate(frames):
            back = mirrored_detections(detector.process(frame).detections, info.size[0])
            records.append({"frame": index, "vehicles": vehicles_record(back), "lane": None})
        scores[check] = evaluate(labels, records)["vehicles"]["iou_0.5"]
    checked, unchecked = scores[0.5], scores[None]
    assert checked["false_positives"] < unchecked["false_positives"], scores
    assert checked["true_positives"] >= unchecked["true_positives"], scores


@pytest.mark.slow
@pytest.mark.parametrize("scale", [0.75, 1.5])
def test_vehicles_are_found_at_960x540_and_1920x1080(
    model: VehicleModel, data_dir: Path, scale: float
) -> None:
    # Bands and windows are fractions of the frame: the same clip at another size gives the same
    # vehicles.
    records = _moved_records(data_dir / "videos" / "test_video.mp4", model, scale=scale)
    labels = load_labels(data_dir / "labels" / "test_video.json")
    v = evaluate(labels, records)["vehicles"]["iou_0.5"]
    assert v["precision"] >= 0.95 and v["recall"] >= 0.9 and v["mean_iou"] >= 0.75


@pytest.mark.slow
@pytest.mark.parametrize("clip", ["project_cut_1", "project_cut_2"])
def test_precision_holds_when_the_frame_moves_by_a_few_pixels(
    model: VehicleModel, data_dir: Path, clip: str
) -> None:
    # A detector whose false alarms depend on where the window grid happens to fall would pass on
    # the clip as it is and fail on a copy moved by 3 px; pooled over two such copies it holds.
    labels = load_labels(data_dir / "labels" / f"{clip}.json")
    tp = fp = frames = 0
    for dx, dy in ((3, 0), (0, 3)):
        records = _moved_records(data_dir / "videos" / f"{clip}.mp4", model, dx=dx, dy=dy)
        v = evaluate(labels, records)
        scores = v["vehicles"]["iou_0.5"]
        tp += scores["true_positives"]
        fp += scores["false_positives"]
        frames += v["frames_scored"]
    assert tp / (tp + fp) >= 0.95 and fp / frames <= 0.05


@pytest.mark.slow
def test_a_car_leaving_at_the_side_is_not_shown_as_a_sliver(data_dir: Path, tmp_path: Path) -> None:
    """project_cut_1 re-encoded blocky (x264 ultrafast, as `make bench`'s blocky row): an
    oncoming car leaves at the left edge, and its track coasted out with its left edge held at
    the picture's edge, a box 27, 15, then 2 px wide. Nothing thinner than the smallest box
    found (2.5 % of the height) is shown, and nothing sits at the edge once the car is gone."""
    from app.reframe import Framing, write_reframed
    from app.sinks import FAST_PRESET

    calibration = load_calibration(default_calibration_path())
    blocky = tmp_path / "project_cut_1.mp4"
    write_reframed(
        data_dir / "videos" / "project_cut_1.mp4",
        Framing("as is"),
        blocky,
        calibration,
        FAST_PRESET,
    )
    rows = process_clip(blocky, tmp_path, "--calibration", "none", "--no-lanes")
    sides = [min(b[2] - b[0], b[3] - b[1]) for r in rows for b in (v["box"] for v in r["vehicles"])]
    assert sides and min(sides) >= DetectorConfig().min_box * 720
    assert not any(v["box"][0] < 1 for r in rows[45:48] for v in r["vehicles"])


@pytest.mark.parametrize("fps", [12.5, 15.0, 25.0, 30.0, 50.0, 60.0])
def test_a_car_is_shown_and_dropped_after_the_same_time_at_any_frame_rate(
    model: VehicleModel, fps: float
) -> None:
    """A detector told the clip's frame rate shows a steady car after the same time as at
    25 fps (0.16 s, within half a frame), keeps it through as long a gap, and averages heat over
    as long (0.32 s): its history is counted in seconds, not frames."""
    at_25 = DetectorConfig()
    detector = VehicleDetector(model, at_25)
    detector.reset(fps)
    car = Detections.from_boxes(np.array([[400.0, 400, 500, 470]]), np.ones(1))
    none = Detections.from_boxes(np.zeros((0, 4)), np.zeros(0))
    frames_to_show = next(k for k in range(1, 60) if len(detector.tracker.update(car)))
    frames_shown_unseen = next(k for k in range(60) if not len(detector.tracker.update(none)))
    half_frame = 0.5 / fps + 1e-9
    assert abs(frames_to_show / fps - at_25.track.confirm_frames / 25) <= half_frame
    assert abs(frames_shown_unseen / fps - at_25.track.show_missed / 25) <= half_frame
    kept = detector.heatmap.frames.maxlen
    assert kept is not None and abs(kept / fps - at_25.heat.history / 25) <= half_frame
    detector.reset()  # a new clip at the same rate
    assert detector.heatmap.frames.maxlen == round(at_25.heat.history * fps / 25)


@pytest.mark.parametrize("fps", [12.5, 15.0, 30.0, 50.0, 60.0])
def test_a_car_speeding_across_is_followed_as_closely_at_any_frame_rate(fps: float) -> None:
    """An oncoming car speeding up across the picture (100 px/s, plus 300 px/s each second),
    measured half a frame late as the heat of the last two frames boxes it: after 1.2 s its
    shown box is off by as much of a frame's motion as at 25 fps (within 5 %). The tracker's
    weights forget as much a second at any rate; kept per frame, the box was off by 2.1 times
    as many frames' motion at half the rate (10.5 px against 5.2 px now, 2.5 px at 25 fps), 0.8
    times at 30 fps and 0.4 times at 60 fps."""

    def error_at(rate: float) -> float:
        cfg = DetectorConfig().at_rate(rate)
        tracker = Tracker(cfg.track, lag=(cfg.heat.recent - 1) / 2)

        def box(t: float) -> NDArray[np.float64]:
            x, width = 900 - 100 * t - 300 * t * t, 50 + 40 * t
            return np.array([[x, 420, x + width, 460]])

        frames = round(1.2 * rate)
        for k in range(frames + 1):
            shown = tracker.update(Detections.from_boxes(box((k - 0.5) / rate), np.ones(1)))
        return float(np.abs(shown.boxes - box(frames / rate)).max())

    # The error in frames' motion (the car moves about 1/fps of a second's motion a frame).
    assert error_at(fps) * fps == pytest.approx(error_at(25.0) * 25.0, rel=0.05)


def test_pictures_of_few_rows_are_read_by_the_low_resolution_model(model: VehicleModel) -> None:
    """Under `lowres_rows` (540 rows of scale height) the 64 px bands are scored by the
    low-resolution model, checked by the same verifier; from 540 rows on by the model; the
    32 px bands keep their own; without a low-resolution model, the model reads every size."""
    lowres = load_model(default_lowres_path())
    verifier = load_model(default_verifier_path())
    small = _small()
    detector = VehicleDetector(model, verifier=verifier, small=small, lowres=lowres)
    for size, expected in (((640, 360), lowres), ((854, 480), lowres), ((960, 540), model)):
        scorers = detector.scorers_for(detector.view(size))
        assert scorers[64].model is expected and scorers[64].verifier is verifier, size
        assert scorers[32] is small
    plain = VehicleDetector(model, verifier=verifier)
    assert plain.scorers_for(plain.view((640, 360)))[64].model is model


def test_small_compressed_footage_is_read_by_the_low_resolution_model(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_1 shrunk to 640x360 and encoded as footage is (colour at half resolution):
    the model trained on sharp crops boxes the white car entering at the right a third of its
    width and misses most cars; the low-resolution model, trained also on compressed copies,
    finds more than twice as many, each where it is."""
    from app.reframe import Framing, framing_scores

    video, labels = (
        data_dir / "videos" / "project_cut_1.mp4",
        data_dir / "labels" / "project_cut_1.json",
    )
    calibration = load_calibration(default_calibration_path())
    framing = Framing("640x360", size=(640, 360))
    for name in ("lowres", "sharp"):
        (tmp_path / name).mkdir()
    scores = {
        name: framing_scores(video, labels, framing, tmp_path / name, calibration, classifier)[
            "vehicles"
        ]["iou_0.5"]
        for name, classifier in (("lowres", None), ("sharp", load_model(default_model_path())))
    }
    lowres, sharp = scores["lowres"], scores["sharp"]
    assert lowres["precision"] >= 0.95, scores
    assert lowres["true_positives"] >= 2 * sharp["true_positives"], scores


def test_windows_need_less_certainty_on_a_road_at_dusk() -> None:
    config = DetectorConfig()
    day, dusk = config.min_probability, config.dark_min_probability
    assert config.min_probability_at(None) == day  # unmeasured: daylight
    assert config.min_probability_at(120.0) == day
    assert config.min_probability_at(30.0) == dusk
    assert dusk < config.min_probability_at(50.0) < day
    # Night: noise is most of what there is; the daylight certainty again.
    assert config.min_probability_at(2.0) == day


def _clip_scores(data_dir: Path, clip: str, light: float = 1.0, **changes: Any) -> dict[str, Any]:
    """The vehicle scores at IoU 0.5 of a shared clip (times `light`), run through the pipeline
    with the shipped calibration and the shipped detector, its config changed by `changes`."""
    from dataclasses import replace

    from app.assembly import build_stages
    from app.pipeline import Pipeline
    from app.record import frame_record

    path = data_dir / "videos" / f"{clip}.mp4"
    info = probe_video(path)
    frames = (
        f if light == 1.0 else np.asarray(f * np.float32(light), np.uint8)
        for f in read_frames(path, info)
    )
    detector = build_stages(lanes=False).vehicles
    assert detector is not None
    detector.config = replace(detector.config, **changes)
    with Pipeline(load_calibration(default_calibration_path()), None, detector) as pipeline:
        pipeline.prepare(info.size, info.fps)
        records = [
            frame_record(k, k / info.fps, info.size, out.result)
            for k, out in enumerate(pipeline.stream(frames))
        ]
    labels = load_labels(data_dir / "labels" / f"{clip}.json")
    scores: dict[str, Any] = evaluate(labels, records)["vehicles"]["iou_0.5"]
    return scores


@pytest.mark.slow
def test_cars_are_found_at_dusk(data_dir: Path) -> None:
    """test_video and project_cut_1 at 0.4 of their light (asphalt at about 30 grey levels):
    with the certainty a window needs lowered on such a road, more cars are found and no more
    false boxes are drawn than with the daylight certainty (75 / 10 against 71 / 10 true /
    false boxes; 71 / 10 against 56 / 19 before, when the windows read the mean of 3 frames,
    not 2, whose blur the lowered certainty made up for in part)."""
    found = {}
    for name, dark in (("dusk", DetectorConfig().dark_min_probability), ("daylight", 0.9)):
        tp = fp = fn = 0
        for clip in ("test_video", "project_cut_1"):
            scores = _clip_scores(data_dir, clip, 0.4, dark_min_probability=dark)
            tp += scores["true_positives"]
            fp += scores["false_positives"]
            fn += scores["false_negatives"]
        found[name] = (tp / (tp + fn), tp / (tp + fp))
    (recall, precision), (day_recall, day_precision) = found["dusk"], found["daylight"]
    assert recall > day_recall and precision >= day_precision, found


def test_on_a_dark_road_the_windows_read_the_mean_of_the_last_frames(model: VehicleModel) -> None:
    detector = VehicleDetector(model)
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (24, 32, 3), dtype=np.uint8) for _ in range(4)]
    seen = [detector.seen(frame, 30.0) for frame in frames]
    np.testing.assert_array_equal(seen[0], frames[0])
    n = detector.config.dark_frames
    assert n >= 2
    mean = np.round(np.mean(frames[4 - n : 4], axis=0) + 1e-9).astype(np.uint8)  # halves up
    np.testing.assert_array_equal(seen[3], mean)  # the last n, this one included
    # In daylight the frame itself, and the dark frames are forgotten.
    np.testing.assert_array_equal(detector.seen(frames[0], 120.0), frames[0])
    np.testing.assert_array_equal(detector.seen(frames[1], 30.0), frames[1])
    cfg = DetectorConfig()
    assert cfg.at_rate(50.0).dark_frames == 2 * cfg.dark_frames  # the same time at any rate


def test_on_a_grainy_road_the_windows_read_the_colour_smoothed(model: VehicleModel) -> None:
    """A grey road with a white square, given colour grain, in a picture of 720 rows: from
    `grainy`, in daylight or on a dark road, the windows see its chroma's grain mostly gone and
    its lightness, the square's edges included, as it was; in a picture of 360 rows less
    smoothed (in proportion), with four times `chroma_grain`'s grain more; under `grainy` the
    frame as is."""
    rng = np.random.default_rng(5)
    ycc = np.full((64, 96, 3), (110, 128, 128), np.float64)
    ycc[20:40, 30:60, 0] = 230
    ycc[..., 1:] += rng.normal(0.0, 3.0, (64, 96, 2))
    frame = cv2.cvtColor(np.round(ycc).astype(np.uint8), cv2.COLOR_YCrCb2RGB)

    def ycc_of(rgb: np.ndarray) -> np.ndarray:
        return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb), dtype=int)

    def chroma_spread(rgb: np.ndarray) -> float:
        return float(ycc_of(rgb)[..., 1:].std())

    config = DetectorConfig()
    for road_grey in (120.0, 30.0):  # the first frame on a dark road: no mean of frames yet
        detector = VehicleDetector(model)
        seen = detector.seen(frame, road_grey, config.grainy, 720.0)
        assert chroma_spread(seen) < chroma_spread(frame) / 3
        assert np.abs(ycc_of(seen)[..., 0] - ycc_of(frame)[..., 0]).max() <= 2
        smaller = VehicleDetector(model).seen(frame, road_grey, config.grainy, 360.0)
        assert chroma_spread(seen) < chroma_spread(smaller) < chroma_spread(frame)
        grainier = VehicleDetector(model).seen(frame, road_grey, 4 * config.chroma_grain, 720.0)
        assert chroma_spread(grainier) < chroma_spread(seen)
        detector = VehicleDetector(model)
        grain = config.grainy - 0.1
        np.testing.assert_array_equal(detector.seen(frame, road_grey, grain, 720.0), frame)


def test_the_colour_is_smoothed_over_the_bands_rows_as_over_the_whole_frame(
    model: VehicleModel,
) -> None:
    """The windows read the rows of their bands alone: the colour is smoothed, and the mean of
    frames taken, over those rows (with a margin as wide as the Gaussian reaches), exactly as
    over the whole frame, and the rows above and below are left as they are."""
    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (180, 320, 3), dtype=np.uint8)
    for sigma, rows in ((2.0, (60, 150)), (3.7, (0, 40)), (1.0, (170, 180))):
        whole = chroma_smoothed(frame, sigma)
        part = seen_picture([frame], sigma, rows)
        top, bottom = rows
        np.testing.assert_array_equal(part[top:bottom], whole[top:bottom])
        np.testing.assert_array_equal(part[:top], frame[:top])
        np.testing.assert_array_equal(part[bottom:], frame[bottom:])
        assert not np.array_equal(whole[top:bottom], frame[top:bottom])
    # In a frame, the rows of every band, the lowest reaching the frame's bottom; there, on a
    # dark grainy road, the mean of the frames smoothed as the whole frame's, the sky as it is.
    detector = VehicleDetector(model)
    top, bottom = detector.band_rows(detector.view((1280, 720)))
    assert 300 < top < 420 and 600 < bottom <= 720
    over_all = VehicleDetector(model)
    over_bands = VehicleDetector(model, keep_debug=True)
    for shift in range(3):
        big = np.ascontiguousarray(np.resize(np.roll(frame, shift, axis=1), (720, 1280, 3)))
        result = over_bands.process(big, road_grey=30.0, grain=1.0)
        everywhere = over_all.seen(big, 30.0, 1.0, 720.0)
        assert result.debug is not None and result.debug.seen is not None
        assert result.debug.averaged == shift + 1
        np.testing.assert_array_equal(result.debug.seen[top:bottom], everywhere[top:bottom])
        np.testing.assert_array_equal(result.debug.seen[: top - 20], big[: top - 20])
        assert not np.array_equal(result.debug.seen[top:bottom], big[top:bottom])


def test_debug_shows_the_picture_the_windows_read(model: VehicleModel) -> None:
    """With debug kept, a grainy frame's intermediates hold the picture the windows read (its
    colour smoothed) and the debug mode draws the window hits on it; a clean frame's hold none,
    and the hits are drawn on the frame itself."""
    from app.debug import intermediates
    from app.pipeline import FrameOutput, FrameResult

    rng = np.random.default_rng(9)
    frame = rng.integers(60, 200, (72, 128, 3), dtype=np.uint8)
    for grain, smoothed in ((None, False), (DetectorConfig().grainy, True)):
        detector = VehicleDetector(model, keep_debug=True)
        result = detector.process(frame, grain=grain)
        assert result.debug is not None and result.debug.smoothed is smoothed
        assert (result.debug.seen is not None) is smoothed
        out = FrameOutput(frame, FrameResult(vehicles=result))
        hits = intermediates(out, frame)["window_hits"]
        read = frame if result.debug.seen is None else result.debug.seen
        corner = (slice(0, 8), slice(-8, None))  # no window reaches the sky's corner
        np.testing.assert_array_equal(hits[corner], read[corner])
        assert bool((read != frame).any()) is smoothed


def _boxes_on(
    copy: Path,
    labels: dict[int, FrameLabels],
    record: Path,
    verifier: Path | None = None,
    **changes: Any,
) -> tuple[int, int, list[dict[str, Any]]]:
    """True and false boxes at IoU 0.5 of the shipped vehicle stage (calibrated; `verifier`
    given by name, `changes` to its config) on a copy of a clip, and the record's frames."""
    from dataclasses import replace

    from app.assembly import build_stages
    from app.drivers import process_video
    from app.record import read_record

    _, detector = build_stages(lanes=False, verifier=verifier)
    assert detector is not None
    detector.config = replace(detector.config, **changes)
    calibration = load_calibration(default_calibration_path())
    process_video(copy, None, calibration, None, detector, record=record)
    frames = list(read_record(record))
    scores = evaluate(labels, frames)["vehicles"]["iou_0.5"]
    return scores["true_positives"], scores["false_positives"], frames


@pytest.mark.slow
def test_grainy_daylight_footage_is_read_with_its_colour_smoothed(
    data_dir: Path, tmp_path: Path
) -> None:
    """The three clips with a sensor's grain in daylight, encoded at a dashcam's bitrate (x264
    CRF 18 keeps it). Each frame read as it is, windows on the grainy asphalt and barrier heat
    (236 false boxes; a phantom car 6 m ahead in our lane). The scene reads the grain, and:
    - grain 0.6 (against at most 0.35 on any shared or wild clip): the windows read the picture
      with its colour smoothed, at most a tenth of the false boxes, and more cars than the mean
      of the last frames keeps (fast cars blur in it);
    - grain 4 (twice the noise): smoothed and averaged, at most a twentieth of the false boxes
      and at most 15 % of the cars fewer than on the copy with half the first grain;
    - half the first grain (0.4) is read as it is;
    - grain 7 (three times the noise): the Gaussian widened by the grain (from `chroma_grain`),
      at most a tenth of the false boxes of one width (123) and at most 5 % of its cars fewer."""
    from app.mining import dimmed_copy, grainy

    shipped = DetectorConfig()
    inf = float("inf")
    alone = {"grainy": inf, "very_grainy": inf}  # each frame read as it is
    averaged = {"grainy": inf, "very_grainy": shipped.grainy}  # the mean of frames from `grainy`
    runs: dict[tuple[int, str], dict[str, Any]] = {
        (2, "shipped"): {},
        (4, "shipped"): {},
        (4, "alone"): alone,
        (4, "averaged"): averaged,
        (8, "shipped"): {},
        (8, "alone"): alone,
        (12, "shipped"): {},
        (12, "one width"): {"chroma_grain": inf},
    }
    totals = {run: [0, 0] for run in runs}
    grains: dict[int, list[float]] = {2: [], 4: [], 8: [], 12: []}
    for clip in ("test_video", "project_cut_1", "project_cut_2"):
        source = data_dir / "videos" / f"{clip}.mp4"
        labels = load_labels(data_dir / "labels" / f"{clip}.json")
        for (strength, name), changes in runs.items():
            copy = tmp_path / f"{clip}_{strength}.mp4"
            if not copy.exists():
                dimmed_copy(source, grainy(strength), copy)
            record = tmp_path / f"{clip}_{strength}_{name}.jsonl"
            tp, fp, frames = _boxes_on(copy, labels, record, **changes)
            totals[strength, name][0] += tp
            totals[strength, name][1] += fp
            if name == "shipped":
                grains[strength] += [f["grain"] for f in frames[25:]]
    assert min(grains[4]) >= shipped.grainy > max(grains[2]), grains
    assert min(grains[8]) >= shipped.very_grainy > max(grains[4]), grains
    assert min(grains[12]) >= 1.5 * shipped.chroma_grain, grains
    (tp, fp), (tp_alone, fp_alone) = totals[4, "shipped"], totals[4, "alone"]
    assert fp <= fp_alone / 10 and tp >= 0.95 * tp_alone, totals
    assert tp > totals[4, "averaged"][0], totals
    (tp, fp), (_, fp_alone) = totals[8, "shipped"], totals[8, "alone"]
    assert fp <= fp_alone / 20 and tp >= 0.85 * totals[2, "shipped"][0], totals
    (tp, fp), (tp_one, fp_one) = totals[12, "shipped"], totals[12, "one width"]
    assert fp <= fp_one / 10 and tp >= 0.95 * tp_one, totals


@pytest.mark.slow
def test_grainy_dusk_footage_at_a_dashcams_bitrate_is_read_with_its_colour_smoothed(
    data_dir: Path, tmp_path: Path
) -> None:
    """The three clips dimmed to dusk (asphalt at about 30) with grain of strength 6, encoded at
    a dashcam's bitrate (CRF 18): the grain reads 2, and on the dark road, too, the windows read
    the picture with its colour smoothed: at most a twentieth of the false boxes of the mean of
    frames alone (446 of them), and more cars."""
    from app.mining import dimmed_copy, grainy

    dusk = grainy(6, dusk=True)
    shipped = DetectorConfig()
    totals = {True: [0, 0], False: [0, 0]}  # smoothed: true and false positives
    dark: list[bool] = []  # whether each frame's road was dark (project_cut_2's concrete: not)
    for clip in ("test_video", "project_cut_1", "project_cut_2"):
        copy = dimmed_copy(data_dir / "videos" / f"{clip}.mp4", dusk, tmp_path / f"{clip}.mp4")
        labels = load_labels(data_dir / "labels" / f"{clip}.json")
        for smoothed, counts in totals.items():
            record = tmp_path / f"{clip}_{smoothed}.jsonl"
            smoothed_from = shipped.grainy if smoothed else float("inf")
            tp, fp, frames = _boxes_on(copy, labels, record, grainy=smoothed_from)
            dark += [f["road_grey"] < shipped.dark_road[2] for f in frames if f["road_grey"]]
            assert frames[-1]["grain"] >= shipped.very_grainy
            counts[0] += tp
            counts[1] += fp
    assert np.mean(dark) > 0.6
    (tp, fp), (tp_alone, fp_alone) = totals[True], totals[False]
    assert fp <= fp_alone / 20 and tp > tp_alone, totals


def test_the_mean_of_more_frames_is_read_on_a_very_grainy_dark_road() -> None:
    """A bright road: the frame alone, or the mean of `grain_frames` from `very_grainy`. A dark
    one: the mean of `dark_frames`, of `grainy_dark_frames` from `very_grainy`, of
    `grain_frames` from `dark_grain` (unknown grain: as a dark road without it)."""
    cfg = DetectorConfig()
    bright, dark = cfg.dark_road[3] + 10, cfg.dark_road[1]
    assert cfg.dark_frames < cfg.grainy_dark_frames < cfg.grain_frames
    assert cfg.very_grainy < cfg.dark_grain
    assert cfg.averaged_frames(bright, 0.1) == 1
    assert cfg.averaged_frames(bright, cfg.very_grainy) == cfg.grain_frames
    assert cfg.averaged_frames(dark, None) == cfg.dark_frames
    assert cfg.averaged_frames(dark, cfg.very_grainy / 2) == cfg.dark_frames
    middle = (cfg.very_grainy + cfg.dark_grain) / 2
    assert cfg.averaged_frames(dark, middle) == cfg.grainy_dark_frames
    assert cfg.averaged_frames(dark, cfg.dark_grain) == cfg.grain_frames


@pytest.mark.slow
def test_very_grainy_dusk_footage_reads_the_mean_of_more_frames(
    data_dir: Path, tmp_path: Path
) -> None:
    """The three clips dimmed to dusk with grain of strength 10 at a dashcam's bitrate: the grain
    reads 5.7, past `dark_grain`, and on the dark road the windows read the mean of 5 frames:
    at most a fifth of the false boxes of 3 frames (14), and at most 3 % fewer cars."""
    from app.mining import dimmed_copy, grainy

    shipped = DetectorConfig()
    totals = {"shipped": [0, 0], "3 frames": [0, 0]}
    for clip in ("test_video", "project_cut_1", "project_cut_2"):
        copy = dimmed_copy(
            data_dir / "videos" / f"{clip}.mp4", grainy(10, dusk=True), tmp_path / f"{clip}.mp4"
        )
        labels = load_labels(data_dir / "labels" / f"{clip}.json")
        for name, counts in totals.items():
            changes: dict[str, Any] = {} if name == "shipped" else {"dark_grain": float("inf")}
            record = tmp_path / f"{clip}_{name}.jsonl"
            tp, fp, frames = _boxes_on(copy, labels, record, **changes)
            assert float(np.median([f["grain"] for f in frames])) >= shipped.dark_grain
            counts[0] += tp
            counts[1] += fp
    (tp, fp), (tp_3, fp_3) = totals["shipped"], totals["3 frames"]
    assert fp_3 >= 5 and fp <= fp_3 / 5 and tp >= 0.97 * tp_3, totals


@pytest.mark.slow
def test_grainy_dark_footage_keeps_its_precision(data_dir: Path, tmp_path: Path) -> None:
    """The three clips darkened to a black road and given a dim sensor's grain before encoding
    (as the README's grainy copies; the grain then reads 0.1-0.4): reading the mean of the
    last 2 frames (`dark_frames`), at most half the false boxes of reading each frame alone,
    for at most 4 % of the cars, and no fewer cars nor more false boxes than the mean of 3
    (159 / 2 against 165 / 14 alone and 136 / 14 of 3; pooled over this and two other draws of
    the grain 455 / 21, against 434 / 31 as shipped before: 3 frames, and the dark verifier
    mined so); checked on the dark road by the dark verifier, which learned other dimmed
    copies of other clips, at most half the false boxes of the verifier alone (161 / 19), and
    at most 3 % of the cars fewer."""
    from app.mining import Dimming, dimmed_copy

    shipped = DetectorConfig().dark_frames
    dim = Dimming(0.55, -0.08, 0.7, grain=6, seed=7)
    # (frames read, the dark verifier): true and false positives
    totals = {(shipped, True): [0, 0], (1, True): [0, 0], (3, True): [0, 0]}
    totals[shipped, False] = [0, 0]
    for clip in ("test_video", "project_cut_1", "project_cut_2"):
        grainy = dimmed_copy(data_dir / "videos" / f"{clip}.mp4", dim, tmp_path / f"{clip}.mp4")
        labels = load_labels(data_dir / "labels" / f"{clip}.json")
        for (frames, dark), counts in totals.items():
            # A verifier given by name checks every road, the dark one too.
            checker = None if dark else default_verifier_path()
            record = tmp_path / f"{clip}_{frames}_{dark}.jsonl"
            tp, fp, _ = _boxes_on(grainy, labels, record, checker, dark_frames=frames)
            counts[0] += tp
            counts[1] += fp
    (tp, fp), (tp_alone, fp_alone) = totals[shipped, True], totals[1, True]
    assert shipped == 2 and tp >= 0.96 * tp_alone and fp <= fp_alone / 2, totals
    tp_3, fp_3 = totals[3, True]
    assert tp >= tp_3 and fp <= fp_3, totals
    tp_plain, fp_plain = totals[shipped, False]
    assert fp <= fp_plain / 2 and tp >= 0.97 * tp_plain, totals


def _receding_box(frame: int) -> NDArray[np.float64]:
    """A car 1.8 m wide seen from 1.2 m up with a 1000 px lens, 4 m to our left, first 10 m away
    and receding at 1 m a frame: its box is its size and offsets from the vanishing point
    (640, 400) over its distance."""
    distance = 10.0 + 1.0 * frame
    left, right, top, bottom = -4.0, -2.2, -0.3, 1.2  # metres from the lens's axis
    x = 640 + 1000 * np.array([left, right]) / distance
    y = 400 + 1000 * np.array([top, bottom]) / distance
    return np.array([x[0], y[0], x[1], y[1]])


def test_a_receding_car_s_box_slows_towards_the_vanishing_point() -> None:
    """A car receding (an oncoming one filmed by a rear camera, one that passed us) moves as one
    over its distance, ever slower towards the vanishing point. Measured half a frame late (heat
    averaged over frames), then lost for 4 frames, the track told the horizon keeps its box on
    the car (IoU >= 0.8); at a steady velocity it ran up to 22 px ahead of it (IoU 0.67)."""

    def fits(horizon_y: float | None) -> list[float]:
        tracker = Tracker(
            plain_tracking(confirm_frames=3, max_missed=8, show_missed=4, velocity_gain=0.3),
            lag=0.5,
        )
        overlaps = []
        for frame in range(14):
            measured = (_receding_box(frame) + _receding_box(frame - 1)) / 2
            seen = measured[None] if frame < 10 else np.zeros((0, 4))
            shown = tracker.update(Detections.from_boxes(seen, np.ones(len(seen))), None, horizon_y)
            if frame >= 4:
                assert len(shown) == 1, frame
                overlaps.append(iou(shown.boxes[0], _receding_box(frame).tolist()))
        return overlaps

    told, untold = fits(400.0), fits(None)
    assert min(told) >= 0.8, told
    assert min(untold) < 0.7, untold


def test_road_velocity_slows_only_a_receding_box() -> None:
    """The velocity shrinks by the square of the distance's growth over the frame, read off the
    bottom's rise towards the horizon; a car at a steady distance or nearing keeps its own."""
    box = np.array([100.0, 410, 160, 440])  # its bottom 40 px under the horizon at 400
    receding = np.array([4.0, -1, 2, -8])  # bottom 40 -> 32 px: the distance grew by 1.25
    np.testing.assert_allclose(road_velocity(box, receding, 400.0), receding * 0.8**2)
    for velocity in ([-20.0, 0, -20, 0], [-6.0, 1, 2, 5]):  # steady distance, nearing
        np.testing.assert_array_equal(road_velocity(box, np.array(velocity), 400.0), velocity)
    np.testing.assert_array_equal(road_velocity(box, receding, 438.0), receding)  # no distance


def test_an_edge_seen_leaving_the_picture_s_side_is_not_motion() -> None:
    """A car entering at the left side is boxed from the picture's edge until most of it is in;
    then its box's left edge jumps from the edge to the car's side. The track places that edge
    where it is seen and moves it as the right one moves (before, the jump was half taken as
    the box's and partly as speed: the edge trailed the car by up to 10 px once seen)."""
    region = (0.0, 0.0, 1280.0, 720.0)
    tracker = Tracker(plain_tracking(confirm_frames=3, velocity_gain=0.3))
    errors = []
    for frame in range(16):
        x1 = -60.0 + 8 * frame  # 100 px wide, 8 px a frame to the right
        seen = np.array([[0.0 if x1 < 20 else x1, 420, x1 + 100, 470]])  # whole once 20 px in
        shown = tracker.update(Detections.from_boxes(seen, np.ones(1)), region)
        if x1 >= 20:
            errors.append(float(shown.boxes[0, 0]) - x1)
            assert cut_edges(shown.boxes, region).sum() == 0
    assert max(np.abs(errors)) <= 2, errors
    assert cut_edges(np.array([[0.0, 420, 100, 470]]), region).tolist() == [
        [True, False, False, False]
    ]


def test_a_box_falling_short_of_a_car_at_the_side_is_not_a_car_coming_in() -> None:
    """A box's side leaving the picture's edge is a vehicle coming in only where its other side
    moves in fast enough to have brought it: a car beside us, cut by the right edge and steady,
    whose heat falls 60 px short of the edge for a frame, is measured as any box is (the
    challenge clip A's SUV under the overpass: taken as coming in, its box was placed short of
    it and its track doubled, precision 0.705 -> 0.639)."""
    appeared = np.array([False, False, True, False])
    steady = np.array([-1.0, 0, 0, 0])  # its inner side creeps 1 px a frame away from the edge
    coming = np.array([-12.0, 0, -12, 0])  # 12 px a frame into the picture
    jump = np.array([0.0, 0, -60, 0])
    assert not entering_sides(appeared, jump, steady, 6).any()
    assert entering_sides(appeared, jump, coming, 6).tolist() == [False, False, True, False]
    assert not entering_sides(appeared, jump, -coming, 6).any()  # leaving, not coming in
