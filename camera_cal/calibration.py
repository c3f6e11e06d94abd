"""Chessboard calibration: find corners, solve for the camera matrix, persist as small JSON."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

FORMAT_VERSION = 1
SIZE_SLACK = 2  # pixels by which a photo may exceed the common size
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


class CalibrationError(Exception):
    """A calibration cannot be computed, read, or applied; the message states the facts."""


class ChessboardImagesError(CalibrationError):
    """The chessboard photos are missing or unreadable."""


class TooFewBoardsError(CalibrationError):
    """Too few photos show the whole board (wrong board size, or too few good photos)."""


class CalibrationFileError(CalibrationError):
    """A calibration file is missing, unreadable, or not a roadview calibration."""


@dataclass(frozen=True, eq=False)
class Calibration:
    """Pinhole camera matrix and distortion coefficients for one camera at one image size."""

    camera_matrix: NDArray[np.float64]
    dist_coeffs: NDArray[np.float64]
    image_size: tuple[int, int]  # (width, height) of the calibration images
    rms: float = 0.0
    # The share of the picture inside the outline of all board corners used: beyond it (a wide
    # lens's corners and edges, where it bends most) the distortion is extrapolated.
    coverage: float = 0.0
    images_used: tuple[str, ...] = field(default_factory=tuple)
    images_skipped: tuple[str, ...] = field(default_factory=tuple)


def turned(calibration: Calibration, degrees: int) -> Calibration:
    """The same lens for its pictures turned `degrees` (a multiple of 90) clockwise: a camera
    mounted upside down (180) or a phone's video that lost its rotation tag (90, 270) is made
    upright before undistortion, so its calibration turns with it. A quarter turn maps the
    normalised point (x, y) to (-y, x): the focal lengths and the centre's coordinates swap
    (the centre measured from the other side), the radial terms stay and the tangential ones
    become (p2, -p1), the thin prism's (s1..s4) (-s3, -s4, s1, s2)."""
    if degrees % 90 != 0:
        raise ValueError(f"a calibration turns by quarter turns, not {degrees} degrees")
    if np.any(np.asarray(calibration.dist_coeffs).ravel()[12:]):
        raise ValueError("a tilted sensor's calibration (tau terms) cannot be turned")
    matrix = np.array(calibration.camera_matrix, dtype=np.float64)
    dist = np.array(calibration.dist_coeffs, dtype=np.float64).ravel()
    width, height = calibration.image_size
    for _ in range((degrees // 90) % 4):
        fx, fy, cx, cy = matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2]
        matrix = np.array([[fy, 0.0, height - 1 - cy], [0.0, fx, cx], [0.0, 0.0, 1.0]])
        if dist.size >= 4:
            dist[2], dist[3] = dist[3], -dist[2]
        if dist.size >= 12:
            dist[8:12] = -dist[10], -dist[11], dist[8], dist[9]
        width, height = height, width
    return replace(calibration, camera_matrix=matrix, dist_coeffs=dist, image_size=(width, height))


def default_calibration_path() -> Path:
    """The committed calibration of the shared dashcam."""
    return Path(__file__).with_name("dashcam.json")


def find_board_corners(
    gray: NDArray[np.uint8], board: tuple[int, int]
) -> NDArray[np.float32] | None:
    """Inner corners of a (cols, rows) chessboard refined to sub-pixel accuracy, or None."""
    found, corners = cv2.findChessboardCorners(gray, board)
    if not found:
        # The sector-based detector copes with blur and strong lens distortion at the edges.
        found, corners = cv2.findChessboardCornersSB(gray, board)
        if not found:
            return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    refined = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria)
    return np.asarray(refined, dtype=np.float32).reshape(-1, 2)


def _board_object_points(board: tuple[int, int]) -> NDArray[np.float32]:
    """Board corner coordinates in board units on the z = 0 plane."""
    cols, rows = board
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2)
    return np.hstack([grid, np.zeros((grid.shape[0], 1))]).astype(np.float32)


def list_images(folder: Path) -> list[Path]:
    """Image files in a folder, sorted naturally (calibration2 before calibration10)."""
    if not folder.is_dir():
        raise ChessboardImagesError(f"{folder} is not a folder of chessboard photos")
    files = [p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]

    def natural(p: Path) -> tuple[str, int]:
        stem = p.stem.rstrip("0123456789")
        digits = p.stem[len(stem) :]
        return stem, int(digits) if digits else -1

    return sorted(files, key=natural)


def calibrate(
    paths: Sequence[Path], board: tuple[int, int] = (9, 6), min_boards: int = 5
) -> Calibration:
    """Calibrate from chessboard photos; photos without the whole board are skipped and named."""
    if not paths:
        raise ChessboardImagesError("no chessboard images given")
    images: list[tuple[str, NDArray[np.uint8] | None]] = [
        (path.name, cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)) for path in paths
    ]
    sizes = Counter((im.shape[1], im.shape[0]) for _, im in images if im is not None)
    if not sizes:
        raise ChessboardImagesError("none of the chessboard files could be read as an image")
    size = sizes.most_common(1)[0][0]
    views: list[NDArray[np.float32]] = []
    used: list[str] = []
    skipped: list[str] = []
    for name, image in images:
        if image is None:
            skipped.append(f"{name}: not an image")
            continue
        if abs(image.shape[1] - size[0]) > SIZE_SLACK or abs(image.shape[0] - size[1]) > SIZE_SLACK:
            skipped.append(f"{name}: size {image.shape[1]}x{image.shape[0]} differs")
            continue
        # A photo a pixel or two larger (seen in the dashcam set) is cropped to the common size.
        corners = find_board_corners(image[: size[1], : size[0]], board)
        if corners is None:
            skipped.append(f"{name}: whole board not found")
            continue
        views.append(corners)
        used.append(name)
    if len(used) < min_boards:
        raise TooFewBoardsError(
            f"only {len(used)} of {len(paths)} images show the whole {board[0]}x{board[1]} board "
            f"(need {min_boards})"
        )
    return _solve(views, board, size, tuple(used), tuple(skipped))


def calibrate_frames(
    frames: Iterable[tuple[str, NDArray[np.uint8]]],
    board: tuple[int, int] = (9, 6),
    min_boards: int = 8,
    min_shift: float = 0.03,
    max_views: int = 40,
) -> Calibration:
    """Calibrate from named video frames (grey or RGB, one size) of a chessboard moved about the
    picture. A frame whose corners lie within `min_shift` of the width (on average) of a view
    already kept adds nothing but weight and is left out; of more than `max_views` distinct views
    the most different are kept. `images_used` names the frames used, `images_skipped` counts the
    rest."""
    views: list[NDArray[np.float32]] = []
    names: list[str] = []
    seen = with_board = 0
    size: tuple[int, int] | None = None
    for name, frame in frames:
        grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY) if frame.ndim == 3 else frame
        size = size or (grey.shape[1], grey.shape[0])
        seen += 1
        # The quick test (a millisecond or two) spares the full search on frames without a board.
        if not cv2.checkChessboard(grey, board):
            continue
        corners = find_board_corners(grey, board)
        if corners is None:
            continue
        with_board += 1
        shifts = [np.linalg.norm(corners - v, axis=1).mean() / size[0] for v in views]
        if min(shifts, default=np.inf) >= min_shift:
            views.append(corners)
            names.append(name)
    if size is None:
        raise ChessboardImagesError("the video has no frames")
    if len(views) < min_boards:
        raise TooFewBoardsError(
            f"only {len(views)} distinct views of the whole {board[0]}x{board[1]} board in "
            f"{seen} frames ({with_board} show it; need {min_boards})"
        )
    keep = _most_different(np.array([v.ravel() for v in views]), max_views)
    skipped = (f"{seen - len(keep)} of {seen} frames: no board, or a view already used",)
    return _solve([views[i] for i in keep], board, size, tuple(names[i] for i in keep), skipped)


def _most_different(vectors: NDArray[np.float32], count: int) -> list[int]:
    """Indices of `count` rows chosen farthest-first (the first row, then each time the row
    furthest from all chosen), in their original order; all rows if there are no more."""
    if len(vectors) <= count:
        return list(range(len(vectors)))
    chosen = [0]
    distance = np.linalg.norm(vectors - vectors[0], axis=1)
    while len(chosen) < count:
        pick = int(distance.argmax())
        chosen.append(pick)
        distance = np.minimum(distance, np.linalg.norm(vectors - vectors[pick], axis=1))
    return sorted(chosen)


def _solve(
    views: Sequence[NDArray[np.float32]],
    board: tuple[int, int],
    size: tuple[int, int],
    used: tuple[str, ...],
    skipped: tuple[str, ...],
) -> Calibration:
    """The camera matrix and distortion that best map the board's corners onto the views."""
    object_grid = _board_object_points(board)
    rms, matrix, dist, _, _ = cv2.calibrateCamera(
        [object_grid] * len(views), list(views), size, None, None
    )
    outline = cv2.convexHull(np.concatenate(list(views)).astype(np.float32))
    return Calibration(
        camera_matrix=np.asarray(matrix, dtype=np.float64),
        dist_coeffs=np.asarray(dist, dtype=np.float64).ravel(),
        image_size=size,
        rms=float(rms),
        coverage=float(cv2.contourArea(outline) / (size[0] * size[1])),
        images_used=used,
        images_skipped=skipped,
    )


def save_calibration(calibration: Calibration, path: Path) -> None:
    """Write the calibration as JSON to `path` (the caller makes the write atomic)."""
    document = {
        "format_version": FORMAT_VERSION,
        "camera_matrix": np.round(calibration.camera_matrix, 6).tolist(),
        "dist_coeffs": np.round(calibration.dist_coeffs, 8).tolist(),
        "image_size": list(calibration.image_size),
        "rms": round(calibration.rms, 6),
        "coverage": round(calibration.coverage, 4),
        "images_used": list(calibration.images_used),
        "images_skipped": list(calibration.images_skipped),
    }
    with Path(path).open("w") as handle:
        json.dump(document, handle, indent=2)
        handle.write("\n")


def load_calibration(path: Path) -> Calibration:
    """Read a calibration JSON, checking its version and shapes."""
    try:
        document = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise CalibrationFileError(f"calibration file {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CalibrationFileError(f"calibration file {path} is not valid JSON ({error})") from None
    if not isinstance(document, dict) or document.get("format_version") != FORMAT_VERSION:
        raise CalibrationFileError(
            f"calibration file {path} is not a roadview calibration of format {FORMAT_VERSION}"
        )
    try:
        matrix = np.asarray(document["camera_matrix"], dtype=np.float64)
        dist = np.asarray(document["dist_coeffs"], dtype=np.float64).ravel()
        width, height = (int(v) for v in document["image_size"])
        rms = float(document.get("rms", 0.0))
        coverage = float(document.get("coverage", 0.0))
    except (KeyError, TypeError, ValueError):
        raise CalibrationFileError(
            f"calibration file {path} lacks a field or has a wrong one"
        ) from None
    if matrix.shape != (3, 3) or dist.size not in (4, 5, 8, 12, 14) or width <= 0 or height <= 0:
        raise CalibrationFileError(f"calibration file {path} has wrong shapes")
    return Calibration(
        camera_matrix=matrix,
        dist_coeffs=dist,
        image_size=(width, height),
        rms=rms,
        coverage=coverage,
        images_used=tuple(document.get("images_used", ())),
        images_skipped=tuple(document.get("images_skipped", ())),
    )
