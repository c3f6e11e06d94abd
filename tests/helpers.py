"""Helpers for tests: run the roadview command line as a user would, read its records, and make
synthetic footage."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from app.sources import VideoInfo, probe_video, read_frames
from camera_cal.scene import SceneTracker


def interruptible() -> None:
    """For a child process (`preexec_fn`): Ctrl-C's SIGINT acts again. A shell runs background
    jobs with SIGINT ignored, and a child inherits that, so a suite run as one would not see
    its subprocesses interrupted."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def run_cli(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run `roadview ARGS` in a subprocess and capture its output."""
    return subprocess.run(
        [sys.executable, "-m", "app", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def assert_one_line_error(result: subprocess.CompletedProcess[str], *fragments: str) -> None:
    """A failure shown as one clear line, no traceback, non-zero exit."""
    assert result.returncode != 0, result.stdout
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def count_frames(path: Path) -> tuple[VideoInfo, int]:
    """Container info and the number of frames actually decoded."""
    info = probe_video(path)
    return info, sum(1 for _ in read_frames(path, info))


def read_record(path: Path) -> list[dict[str, Any]]:
    """The per-frame objects of a `--json` record."""
    return [json.loads(line) for line in path.read_text().splitlines()]


def process_clip(video: Path, folder: Path, *options: str) -> list[dict[str, Any]]:
    """`roadview process VIDEO` into `folder` with a record; asserts success, returns the record."""
    record = folder / "r.jsonl"
    result = run_cli("process", video, "-o", folder / "o.mp4", "--json", record, *options)
    assert result.returncode == 0, result.stderr
    return read_record(record)


def moving_road(
    size: tuple[int, int], frames: int, bonnet: int | None = None
) -> list[NDArray[np.uint8]]:
    """Frames of a textured road streaming down the picture (as under a moving camera), with a
    still, smooth bonnet from row `bonnet` down when given."""
    w, h = size
    rng = np.random.default_rng(7)
    texture = cv2.resize(
        rng.integers(40, 200, (h // 4 + frames * 2, w // 4), np.uint8), None, fx=4, fy=4
    )
    out = []
    for t in range(frames):
        grey = texture[(frames - t) * 8 : (frames - t) * 8 + h]
        frame = np.repeat(grey[:, :, None], 3, axis=2).copy()
        if bonnet is not None:
            frame[bonnet:] = (200, 200, 205)
        out.append(frame)
    return out


def dashed_road(
    frames: int, spacing_m: float, step_m: float, dash_m: float = 3.0
) -> Iterator[NDArray[np.uint8]]:
    """1280x720 frames of a straight road under the tuned lane warp (painted in its bird's-eye
    view, in its metres, and seen through it): textured asphalt, a solid left line and a dashed
    right one, a `dash_m` dash every `spacing_m`, streaming `step_m` towards the camera a frame."""
    from lanes.config import LaneConfig
    from lanes.finder import LaneFinder

    config = LaneConfig()
    view = LaneFinder(config).view((1280, 720))
    bw, bh = view.size
    step = step_m / view.ym_per_px
    rows = bh + round(frames * step) + 8
    rng = np.random.default_rng(3)
    asphalt = cv2.GaussianBlur(rng.integers(70, 130, (rows, bw), np.uint8), (5, 5), 0)
    half = max(1, round(config.line_width_m / view.xm_per_px / 2))
    left, right = round(config.dst_left_x * bw), round(config.dst_right_x * bw)
    asphalt[:, left - half : left + half + 1] = 235
    along = np.arange(rows) * view.ym_per_px
    dashed = (along % spacing_m) < dash_m
    asphalt[dashed, right - half : right + half + 1] = 235
    for k in range(frames):
        top = rows - bh - round(k * step)  # the road slides down the view, towards the camera
        part = np.dstack([asphalt[top : top + bh]] * 3)
        frame = cv2.warpPerspective(part, view.inverse, (1280, 720), borderValue=(100, 100, 100))
        yield np.asarray(frame, np.uint8)


def chessboard_frames(
    size: tuple[int, int],
    matrix: NDArray[np.float64],
    dist: NDArray[np.float64],
    board: tuple[int, int] = (9, 6),
    views: int = 16,
    hold: int = 6,
    seed: int = 0,
) -> list[NDArray[np.uint8]]:
    """RGB frames of a (cols, rows) inner-corner chessboard, as a camera with `matrix` and
    distortion `dist` sees it in `views` random poses (tilted up to 25 degrees, anywhere in the
    picture, 14-22 squares away per focal length in widths), each held for `hold` frames."""
    width, height = size
    px, margin = 40, 1.0  # texture pixels per square; white margin in squares
    cols, rows = board
    shape = (round((rows + 1 + 2 * margin) * px), round((cols + 1 + 2 * margin) * px))
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]] / px - margin - 1  # first inner corner at 0
    inside = (xs >= -1) & (xs < cols) & (ys >= -1) & (ys < rows)
    texture = np.where(((np.floor(xs) + np.floor(ys)) % 2 == 0) & inside, 20, 235)
    to_board = np.array([[1 / px, 0, -margin - 1], [0, 1 / px, -margin - 1], [0, 0, 1]])
    # Where each pixel of the distorted picture looks in the pinhole picture, drawn on a canvas
    # as large as those places reach (a barrel lens sees more than a pinhole of its size).
    grid = np.mgrid[0:height, 0:width][::-1].reshape(2, -1).T.astype(np.float32)
    pinhole = cv2.undistortPoints(grid.reshape(-1, 1, 2), matrix, dist, P=matrix)
    maps = pinhole.reshape(height, width, 2).astype(np.float32)
    origin = np.floor(maps.reshape(-1, 2).min(axis=0)) - 2
    canvas = tuple(int(v) for v in np.ceil(maps.reshape(-1, 2).max(axis=0) - origin) + 2)
    maps -= origin.astype(np.float32)
    shift_origin = np.array([[1, 0, -origin[0]], [0, 1, -origin[1]], [0, 0, 1]])
    rng = np.random.default_rng(seed)
    centre = np.array([(cols - 1) / 2, (rows - 1) / 2, 0.0])
    frames: list[NDArray[np.uint8]] = []
    for _ in range(views):
        rotation, _ = cv2.Rodrigues(np.deg2rad(rng.uniform(-25, 25, 3) * [1, 1, 0.4]))
        target = [rng.uniform(0.2, 0.8) * width, rng.uniform(0.25, 0.75) * height, 1.0]
        distance = rng.uniform(14, 22) * matrix[0, 0] / width
        shift = distance * np.linalg.solve(matrix, target) - rotation @ centre
        homography = (
            shift_origin
            @ matrix
            @ np.column_stack([rotation[:, 0], rotation[:, 1], shift])
            @ to_board
        )
        picture = cv2.warpPerspective(
            texture.astype(np.uint8), homography, canvas, flags=cv2.INTER_AREA, borderValue=128
        )
        seen = cv2.remap(picture, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderValue=128)
        frames += [np.dstack([seen] * 3)] * hold
    return frames


def raised_camera(frame: NDArray[np.uint8], horizon: float, factor: float) -> NDArray[np.uint8]:
    """The frame as a camera `factor` times higher over the same road would see it (same lens
    and horizon): what was d rows below the horizon is d * factor below it (the road only;
    a vehicle comes out stretched)."""
    height, width = frame.shape[:2]
    rows = np.arange(height, dtype=np.float32)
    source = np.where(rows > horizon, horizon + (rows - horizon) / factor, rows)
    map_x, map_y = np.meshgrid(np.arange(width, dtype=np.float32), source.astype(np.float32))
    return np.asarray(cv2.remap(frame, map_x, map_y, cv2.INTER_LINEAR), np.uint8)


def zoomed_replay(frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A 1280x720 frame as a zoomed replay shows it: its lower left 70 % (the horizon 120 rows
    higher, the road's vanishing point near the right edge) scaled back to the full frame."""
    height, width = frame.shape[:2]
    part = frame[round(0.3 * height) :, : round(0.7 * width)]
    return np.ascontiguousarray(cv2.resize(part, (width, height)))


def road_camera(
    turn_deg: float = 0.0,
    camera_m: float = 0.0,
    height_m: float = 1.24,
    focal_px: float = 1000.0,
    horizon_y: float = 420.0,
) -> NDArray[np.float64]:
    """The homography from a flat road's points (x across from a lane's centre line, z along
    the road from the camera, metres; homogeneous) to the 1280x720 picture of a pinhole camera
    `height_m` over the road and `camera_m` right of that line, turned `turn_deg` right of the
    road's direction and pitched to see its horizon on row `horizon_y`."""
    cx, cy = 640.0, 360.0
    turn, pitch = math.radians(turn_deg), math.atan((cy - horizon_y) / focal_px)
    # Road (x, z, 1) to the camera's axes before its pitch (right, down, ahead) ...
    ground = np.array(
        [
            [math.cos(turn), -math.sin(turn), -camera_m * math.cos(turn)],
            [0.0, 0.0, height_m],
            [math.sin(turn), math.cos(turn), -camera_m * math.sin(turn)],
        ]
    )
    # ... pitched down by `pitch` (up where negative), then onto the picture.
    pitched = np.array(
        [
            [1.0, 0.0, 0.0],
            [0.0, math.cos(pitch), -math.sin(pitch)],
            [0.0, math.sin(pitch), math.cos(pitch)],
        ]
    )
    lens = np.array([[focal_px, 0.0, cx], [0.0, focal_px, cy], [0.0, 0.0, 1.0]])
    return np.asarray(lens @ pitched @ ground, np.float64)


def placed_column(vanishing_x: float, width: int = 1280) -> float | None:
    """The column a scene places the lane view on for a road vanishing at `vanishing_x` of a
    picture `width` wide: None (the picture's middle) within its placement step (`settle_x`
    of the width) of the middle, as `SceneTracker` places it."""
    step = SceneTracker((width, 720), 420.0).settle_x * width
    return vanishing_x if abs(vanishing_x - width / 2) > step else None


def seen_road(
    paint: list[tuple[float, float, float, float]],
    camera: NDArray[np.float64],
    horizon_y: float = 420.0,
) -> tuple[NDArray[np.uint8], float]:
    """A 1280x720 frame of a flat road (asphalt, white `paint` rectangles: x0, x1 across and
    z0, z1 along it, in metres, see `road_camera`) as the `camera` homography sees it, the sky
    above `horizon_y`; and the column of the road's vanishing point. At the tuned camera's
    height (1.24 m) a 3.7 m lane reads 3.7 m wide."""
    # The road painted 1 cm a pixel across (10 m either side), 5 cm along (1-150 m ahead).
    across, along, x0, z0 = 0.01, 0.05, -10.0, 1.0
    road = np.full((round(149 / along), round(20 / across)), 90, np.uint8)
    for a, b, c, d in paint:
        rows = slice(round((c - z0) / along), round((d - z0) / along))
        road[rows, round((a - x0) / across) : round((b - x0) / across)] = 235
    to_metres = np.array([[across, 0.0, x0], [0.0, along, z0], [0.0, 0.0, 1.0]])
    picture = cv2.warpPerspective(
        road, camera @ to_metres, (1280, 720), flags=cv2.INTER_AREA, borderValue=90
    )
    picture[: math.ceil(horizon_y) + 2] = 170  # the sky (the warp folds the road over there)
    far = camera @ np.array([0.0, 1e9, 1.0])
    return np.ascontiguousarray(np.dstack([picture] * 3)), float(far[0] / far[2])
