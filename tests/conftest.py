"""Shared fixtures: paths of the data set gathered by `make data` (or ../shared/data)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _data_dir() -> Path:
    for candidate in (ROOT / "data", ROOT.parent / "shared" / "data"):
        if (candidate / "videos" / "test_video.mp4").exists():
            return candidate
    pytest.exit("no data set: run 'make data' first", returncode=2)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """Root of the data set."""
    return _data_dir()


@pytest.fixture(scope="session")
def test_video(data_dir: Path) -> Path:
    """The 38-frame labelled test clip."""
    return data_dir / "videos" / "test_video.mp4"


@pytest.fixture(scope="session")
def wild_dir(data_dir: Path) -> Path:
    """The unlabelled clips of other cameras (../shared/data/wild); tests skip without them."""
    for candidate in (data_dir / "wild", ROOT.parent / "shared" / "data" / "wild"):
        if (candidate / "night_highway_istock.mp4").exists():
            return candidate
    pytest.skip("no wild clips beside the checkout (../shared/data/wild)")
