"""Helpers for tests: run the roadview command line as a user would, read its records, and make
synthetic footage."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from app.sources import VideoInfo, probe_video, read_frames


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
