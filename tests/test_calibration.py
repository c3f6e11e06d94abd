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
    calibrated_scale_height,
    default_calibration_path,
    load_calibration,
    save_calibration,
)
from camera_cal.calibration import list_images


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


def test_other_aspect_ratio_is_refused() -> None:
    cal = load_calibration(default_calibration_path())
    with pytest.raises(CalibrationError, match="aspect ratio"):
        build_undistorter(cal, (640, 480))


def test_committed_file_is_small_json() -> None:
    document = json.loads(default_calibration_path().read_text())
    assert set(document) >= {"camera_matrix", "dist_coeffs", "image_size", "rms", "images_used"}
