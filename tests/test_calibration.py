"""Camera calibration on the shared chessboards, JSON round trip, and undistortion accuracy."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from camera_cal import (
    Calibration,
    CalibrationError,
    build_undistorter,
    calibrate,
    calibrate_frames,
    calibrated_scale_height,
    default_calibration_path,
    focal_scale_height,
    load_calibration,
    save_calibration,
)
from camera_cal.calibration import find_board_corners, list_images
from camera_cal.undistort import kept_width, scaled_camera_matrix
from tests.helpers import assert_one_line_error, chessboard_frames, run_cli


@pytest.fixture(scope="module")
def dashcam(data_dir: Path) -> Calibration:
    return calibrate(list_images(data_dir / "camera_cal"))


def test_shared_chessboards_calibrate_well(dashcam: Calibration) -> None:
    assert dashcam.rms < 1.5
    fx, fy = dashcam.camera_matrix[0, 0], dashcam.camera_matrix[1, 1]
    assert 1100 < fx < 1200 and 1100 < fy < 1200
    assert dashcam.image_size == (1280, 720)
    # A few photos do not show the whole board: they are skipped and named.
    assert 15 <= len(dashcam.images_used) < 20
    assert all(": " in s for s in dashcam.images_skipped)


def test_committed_calibration_is_reproduced(dashcam: Calibration) -> None:
    committed = load_calibration(default_calibration_path())
    np.testing.assert_allclose(committed.camera_matrix, dashcam.camera_matrix, rtol=1e-4)
    np.testing.assert_allclose(committed.dist_coeffs, dashcam.dist_coeffs, atol=1e-4)


def test_calibration_json_round_trip(dashcam: Calibration, tmp_path: Path) -> None:
    path = tmp_path / "cal.json"
    save_calibration(dashcam, path)
    loaded = load_calibration(path)
    np.testing.assert_allclose(loaded.camera_matrix, dashcam.camera_matrix, atol=1e-6)
    np.testing.assert_allclose(loaded.dist_coeffs, dashcam.dist_coeffs, atol=1e-8)
    assert loaded.image_size == dashcam.image_size
    assert loaded.images_used == dashcam.images_used
    assert loaded.rms == pytest.approx(dashcam.rms, abs=1e-6)
    assert loaded.coverage == pytest.approx(dashcam.coverage, abs=1e-4) and dashcam.coverage > 0.6


@pytest.mark.parametrize(
    "content",
    ["not json", '{"format_version": 99}', '{"format_version": 1, "camera_matrix": [[1]]}'],
)
def test_bad_calibration_files_fail_clearly(tmp_path: Path, content: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(CalibrationError, match="calibrat"):
        load_calibration(path)


def test_empty_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="no chessboard images"):
        calibrate(list_images(tmp_path))


def test_wrong_board_size_is_refused(data_dir: Path) -> None:
    paths = list_images(data_dir / "camera_cal")[:6]
    with pytest.raises(CalibrationError, match="whole 11x8 board"):
        calibrate(paths, board=(11, 8))


def _dot_image(points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """White anti-aliased dots at sub-pixel positions on black."""
    image = np.zeros((size[1], size[0]), np.uint8)
    shift = 4
    for x, y in points:
        center = (round(x * (1 << shift)), round(y * (1 << shift)))
        cv2.circle(image, center, 6 << shift, 255, -1, cv2.LINE_AA, shift)
    return image


def test_undistortion_inverts_known_distortion() -> None:
    size = (640, 360)
    matrix = np.array([[580.0, 0, 320], [0, 580.0, 180], [0, 0, 1]])
    dist = np.array([-0.28, 0.09, 0.0005, -0.0003, -0.02])
    cal = Calibration(camera_matrix=matrix, dist_coeffs=dist, image_size=size)
    xs, ys = np.meshgrid(np.linspace(60, 580, 9), np.linspace(40, 320, 6))
    truth = np.stack([xs.ravel(), ys.ravel()], axis=1)
    # Where each undistorted point lands in the distorted photo.
    normalized = cv2.undistortPoints(truth.reshape(-1, 1, 2), matrix, None).reshape(-1, 2)
    object_points = np.hstack([normalized, np.ones((len(normalized), 1))])
    distorted, _ = cv2.projectPoints(object_points, np.zeros(3), np.zeros(3), matrix, dist)
    photo = _dot_image(distorted.reshape(-1, 2), size)
    restored = build_undistorter(cal, size)(np.dstack([photo] * 3))
    n, _, _stats, centroids = cv2.connectedComponentsWithStats(
        (restored[:, :, 0] > 60).astype(np.uint8)
    )
    found = centroids[1:]
    assert n - 1 == len(truth)
    distances = np.linalg.norm(found[:, None, :] - truth[None, :, :], axis=2).min(axis=1)
    assert distances.max() < 1.0


def test_a_turned_picture_is_levelled_about_the_principal_point() -> None:
    """A camera mounted turned about its axis: dots on a level grid, turned 4 degrees
    anticlockwise about the principal point (with the lens's distortion, or without a lens),
    come back to the grid with `roll_deg` 4; with -4 they turn further, and 0 changes nothing."""
    size = (640, 360)
    matrix = np.array([[580.0, 0, 300], [0, 580.0, 170], [0, 0, 1]])
    dist = np.array([-0.28, 0.09, 0.0, 0.0, -0.02])
    cal = Calibration(camera_matrix=matrix, dist_coeffs=dist, image_size=size)
    xs, ys = np.meshgrid(np.linspace(80, 560, 7), np.linspace(50, 310, 5))
    truth = np.stack([xs.ravel(), ys.ravel()], axis=1)
    a = np.radians(4.0)
    turn = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])  # anticlockwise, y down

    def found(image: np.ndarray) -> np.ndarray:
        _, _, _, centroids = cv2.connectedComponentsWithStats((image[:, :, 0] > 60).astype("u1"))
        return np.asarray(centroids[1:])

    def error(points: np.ndarray) -> float:
        return float(np.linalg.norm(points[:, None] - truth[None], axis=2).min(axis=1).max())

    for lens in (cal, None):
        centre = matrix[:2, 2] if lens is not None else (np.array(size) - 1) / 2
        turned = (truth - centre) @ turn.T + centre
        if lens is not None:  # where each turned point lands in the distorted photo
            rays = cv2.undistortPoints(turned.reshape(-1, 1, 2), matrix, None).reshape(-1, 2)
            rays = np.hstack([rays, np.ones((len(rays), 1))])
            turned = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), matrix, dist)[0]
        photo = np.dstack([_dot_image(turned.reshape(-1, 2), size)] * 3)
        level = found(build_undistorter(lens, size, 4.0)(photo))
        assert len(level) == len(truth) and error(level) < 1.0
        assert error(found(build_undistorter(lens, size, -4.0)(photo))) > 20
    plain = np.dstack([_dot_image(truth, size)] * 3)
    np.testing.assert_array_equal(
        build_undistorter(cal, size, 0.0).map1, build_undistorter(cal, size).map1
    )
    assert error(found(build_undistorter(None, size, 0.0)(plain))) < 0.5


def test_undistortion_in_stripes_is_one_remap_of_the_whole_frame() -> None:
    # A height that is no multiple of the stripes, a strong lens: the same pixels as OpenCV's
    # one call over the frame.
    size = (333, 101)
    matrix = np.array([[300.0, 0, 166], [0, 300.0, 50], [0, 0, 1]])
    cal = Calibration(matrix, np.array([-0.3, 0.1, 0.001, 0.0, 0.0]), size)
    undistort = build_undistorter(cal, size)
    rng = np.random.default_rng(1)
    frame = rng.integers(0, 256, (101, 333, 3), dtype=np.uint8)
    whole = cv2.remap(frame, undistort.map1, undistort.map2, cv2.INTER_LINEAR)
    np.testing.assert_array_equal(undistort(frame), whole)
    assert not np.array_equal(whole, frame)


def test_scaled_calibration_matches_full_size() -> None:
    cal = load_calibration(default_calibration_path())
    full = build_undistorter(cal, (1280, 720))
    half = build_undistorter(cal, (640, 360))
    # The same scene point maps to half the coordinates at half size.
    np.testing.assert_allclose(half.camera_matrix[:2, :2], full.camera_matrix[:2, :2] / 2)
    rng = np.random.default_rng(0)
    scene = cv2.GaussianBlur(rng.integers(0, 255, (720, 1280, 3), dtype=np.uint8), (31, 31), 0)
    big = full(scene)
    small = half(cv2.resize(scene, (640, 360), interpolation=cv2.INTER_AREA))
    reference = cv2.resize(big, (640, 360), interpolation=cv2.INTER_AREA)
    inner = (slice(40, -40), slice(40, -40))
    assert np.abs(small[inner].astype(int) - reference[inner].astype(int)).mean() < 3


def test_a_calibrated_lens_sets_the_scale_the_stages_work_in() -> None:
    """The shipped lens is the unit (its picture's height at any size); a lens of twice the
    focal length reads as a picture twice as tall, so its distances come out right."""
    cal = load_calibration(default_calibration_path())
    assert calibrated_scale_height(cal, (1280, 720)) == pytest.approx(720)
    assert calibrated_scale_height(cal, (1920, 1080)) == pytest.approx(1080)
    matrix = cal.camera_matrix.copy()
    matrix[:2, :2] *= 2
    longer = dataclasses.replace(cal, camera_matrix=matrix)
    assert calibrated_scale_height(longer, (1280, 720)) == pytest.approx(1440)


def test_a_lens_known_by_its_focal_length_sets_the_scale_as_a_calibration_would() -> None:
    """Without a calibration, a lens of a stated (or tagged) 35 mm-equivalent focal length is
    one without distortion of that focal length: the shipped lens's own reads as its picture's
    height, a longer one's as a taller picture, at any size; a phone held upright spans its
    longer side, as its sensor's width, so the same lens gives the same focal length."""
    from camera_cal.undistort import equivalent_focal_mm, focal_length_px, output_camera_matrix

    cal = load_calibration(default_calibration_path())
    shipped = equivalent_focal_mm(float(output_camera_matrix(cal, (1280, 720))[1, 1]), (1280, 720))
    assert 30 < shipped < 33  # a phone's main camera is 24-28 mm: wider
    assert focal_scale_height(shipped, (1280, 720)) == pytest.approx(720)
    assert focal_scale_height(shipped, (1920, 1080)) == pytest.approx(1080)
    assert focal_scale_height(2 * shipped, (1280, 720)) == pytest.approx(1440)
    assert focal_length_px(26, (1080, 1920)) == focal_length_px(26, (1920, 1080))
    # An iPhone's 26 mm main camera over its full 4:3 width: 67.8 degrees across, as it says.
    across = 2 * np.degrees(np.arctan(2016 / focal_length_px(26, (4032, 3024))))
    assert across == pytest.approx(67.8, abs=0.6)


def test_a_wide_lens_keeps_the_sides_of_its_picture() -> None:
    """A lens of focal length half the width with strong barrel distortion: undistorted at its
    own focal length, it shows 78 % of its picture's width (a car at the side, in the next lane,
    is cut off); the undistorted view is zoomed out until 90 % stays, and the stages' scale
    follows that view. The shipped lens (92 % shown) is undistorted at its own focal length."""
    size = (1280, 720)
    matrix = np.array([[640.0, 0, 645], [0, 640.0, 355], [0, 0, 1]])
    dist = np.array([-0.32, 0.11, 0.0, 0.0, -0.015])
    wide = Calibration(camera_matrix=matrix, dist_coeffs=dist, image_size=size)
    undistorter = build_undistorter(wide, size)
    assert undistorter.camera_matrix[0, 0] < matrix[0, 0]
    assert kept_width(wide, size, undistorter.camera_matrix) == pytest.approx(0.9, abs=1e-3)
    assert kept_width(wide, size, matrix) < 0.8
    # Dots 7 % of the width in from the picture's sides, along the principal row.
    sides = np.array([[90.0, 355.0], [1190.0, 355.0]])
    photo = np.dstack([_dot_image(sides, size)] * 3)
    n, _, _, centroids = cv2.connectedComponentsWithStats(
        (undistorter(photo)[:, :, 0] > 60).astype(np.uint8)
    )
    assert n - 1 == len(sides)  # both still in the picture, where the lens puts them
    expected = cv2.undistortPoints(
        sides.reshape(-1, 1, 2), matrix, dist, P=undistorter.camera_matrix
    ).reshape(-1, 2)
    found = centroids[1:]  # (the stretched dots' centroids lie within 2 px)
    assert np.linalg.norm(found[:, None] - expected[None], axis=2).min(axis=1).max() < 2.5
    # At the lens's own focal length the same dots would fall outside the frame.
    same = cv2.undistortPoints(sides.reshape(-1, 1, 2), matrix, dist, P=matrix).reshape(-1, 2)
    assert ((same[:, 0] < 0) | (same[:, 0] > size[0] - 1)).all()
    shipped = load_calibration(default_calibration_path())
    assert calibrated_scale_height(wide, size) == pytest.approx(
        undistorter.camera_matrix[1, 1] / shipped.camera_matrix[1, 1] * 720
    )
    for frame_size in ((1280, 720), (1920, 1080), (854, 480)):
        shipped_undistorter = build_undistorter(shipped, frame_size)
        assert kept_width(shipped, frame_size, shipped_undistorter.camera_matrix) > 0.91
        np.testing.assert_array_equal(
            shipped_undistorter.camera_matrix, scaled_camera_matrix(shipped, frame_size)
        )


def test_other_aspect_ratio_is_refused() -> None:
    cal = load_calibration(default_calibration_path())
    with pytest.raises(CalibrationError, match="aspect ratio"):
        build_undistorter(cal, (640, 480))


def test_committed_file_is_small_json() -> None:
    document = json.loads(default_calibration_path().read_text())
    assert set(document) >= {"camera_matrix", "dist_coeffs", "image_size", "rms", "images_used"}


def _write_video(path: Path, frames: list[np.ndarray], fps: float = 24.0) -> Path:
    from app.sinks import VideoSink

    height, width = frames[0].shape[:2]
    with VideoSink(path, (width, height), fps, preset="medium") as sink:
        for frame in frames:
            sink.write(np.ascontiguousarray(frame))
    return path


def test_a_wide_lens_is_calibrated_from_a_video_of_the_board(tmp_path: Path) -> None:
    """A wide-angle dashcam (focal length half the width, strong barrel distortion) films a
    board held in 16 places for a quarter of a second each: `calibrate --video` recovers the lens
    within a fraction of a pixel wherever the board was seen, and one view per place."""
    size = (1280, 720)
    matrix = np.array([[640.0, 0, 645], [0, 640.0, 355], [0, 0, 1]])
    dist = np.array([-0.32, 0.11, 0.0, 0.0, -0.015])
    frames = chessboard_frames(size, matrix, dist, views=16, hold=6)
    video = _write_video(tmp_path / "board.mp4", frames)
    result = run_cli("calibrate", "--video", video, "--out", tmp_path / "wide.json")
    assert result.returncode == 0, result.stderr
    assert "distinct views" in result.stdout
    found = load_calibration(tmp_path / "wide.json")
    assert found.image_size == size
    assert 8 <= len(found.images_used) <= 16  # a view held still is used once
    assert found.rms < 0.5
    np.testing.assert_allclose(found.camera_matrix[:2, :2], matrix[:2, :2], rtol=0.01, atol=1)
    np.testing.assert_allclose(found.camera_matrix[:2, 2], matrix[:2, 2], atol=3)
    # Undistorted positions against the true lens's, where the corners were seen.
    views = [
        find_board_corners(frames[int(n.split()[1])][:, :, 0], (9, 6)) for n in found.images_used
    ]
    corners = np.vstack([v for v in views if v is not None])
    hull = cv2.convexHull(corners.astype(np.float32))
    xs, ys = np.meshgrid(np.arange(0, size[0], 16), np.arange(0, size[1], 16))
    grid = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float32)
    seen = np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), False) >= 0 for x, y in grid])
    assert seen.mean() > 0.4
    # The outline of the corners used, as the calibration reports it (and says so when small).
    assert found.coverage == pytest.approx(seen.mean(), abs=0.05)
    assert ("corners and edges" in result.stderr) == (found.coverage < 0.6)
    points = grid[seen].reshape(-1, 1, 2)
    truth = cv2.undistortPoints(points, matrix, dist, P=matrix).reshape(-1, 2)
    for coeffs, within in ((found.dist_coeffs, 3.0), (np.zeros(5), None)):
        got = cv2.undistortPoints(points, found.camera_matrix, coeffs, P=matrix).reshape(-1, 2)
        error = np.linalg.norm(got - truth, axis=1)
        if within is not None:  # (the most at the outermost corners seen: 1.8-2.5 px)
            assert np.median(error) < 0.5 and error.max() < within
        else:  # the lens matters: read as a pinhole, the same points are tens of pixels off
            assert error.max() > 30


def test_the_shared_chessboards_calibrate_alike_from_a_video(
    dashcam: Calibration, data_dir: Path, tmp_path: Path
) -> None:
    """The 20 photos shown for half a second each, as a video: the same photos show the board,
    each is used once, and the lens comes out as from the photos."""
    photos = [
        cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB)[:720, :1280]
        for p in list_images(data_dir / "camera_cal")
    ]
    video = _write_video(tmp_path / "photos.mp4", [p for p in photos for _ in range(12)])
    from app.sources import probe_video, read_frames

    frames = (  # every sixth, as `calibrate --video` looks at 24 fps video
        (str(i), f) for i, f in enumerate(read_frames(video, probe_video(video))) if i % 6 == 0
    )
    found = calibrate_frames(frames)
    assert len(found.images_used) == len(dashcam.images_used)
    assert {int(name) // 12 for name in found.images_used} == {
        i
        for i, p in enumerate(list_images(data_dir / "camera_cal"))
        if p.name in dashcam.images_used
    }
    np.testing.assert_allclose(
        found.camera_matrix[:2, :2], dashcam.camera_matrix[:2, :2], rtol=0.01
    )
    assert found.rms < 1.5


def test_a_video_without_a_board_is_refused(test_video: Path, tmp_path: Path) -> None:
    out = tmp_path / "cal.json"
    result = run_cli("calibrate", "--video", test_video, "--out", out)
    assert_one_line_error(result, "distinct views of the whole 9x6 board", "--board")
    assert not out.exists()
    both = run_cli("calibrate", "--video", test_video, "--images", tmp_path, "--out", out)
    assert_one_line_error(both, "--images or --video")


@pytest.mark.parametrize("degrees", [90, 180, 270])
def test_a_calibration_turns_with_its_picture(degrees: int) -> None:
    """A picture turned a quarter turn or two, undistorted with its calibration turned alike, is
    the undistorted picture turned (a camera mounted upside down, a phone's video without its
    tag): to the pixel, with the tangential and thin prism terms of a lens that has them. Four
    quarter turns give the calibration back."""
    from camera_cal import turned

    size = (320, 200)
    matrix = np.array([[300.0, 0, 171.3], [0, 290.0, 93.6], [0, 0, 1]])
    dist = np.array([-0.25, 0.08, 0.004, -0.003, -0.02, 0, 0, 0, 0.002, -0.001, 0.003, 0.0005])
    cal = Calibration(camera_matrix=matrix, dist_coeffs=dist, image_size=size)
    rng = np.random.default_rng(1)
    photo = cv2.GaussianBlur((rng.random((size[1], size[0], 3)) * 255).astype(np.uint8), (0, 0), 2)
    quarters = -degrees // 90  # np.rot90 turns anticlockwise
    expected = np.rot90(cv2.undistort(photo, matrix, dist), quarters)
    turn = turned(cal, degrees)
    got = cv2.undistort(np.ascontiguousarray(np.rot90(photo, quarters)), turn.camera_matrix,
                        turn.dist_coeffs)  # fmt: skip
    assert turn.image_size == (expected.shape[1], expected.shape[0])
    difference = np.abs(got.astype(int) - expected.astype(int))[4:-4, 4:-4]
    assert difference.max() <= 1
    back = turned(turned(turn, 360 - degrees), 0)
    np.testing.assert_allclose(back.camera_matrix, matrix)
    np.testing.assert_allclose(back.dist_coeffs, dist)
    assert back.image_size == size
    with pytest.raises(ValueError):
        turned(cal, 45)
