"""Gather the data set under data/: copy from ../shared/data, or download the public files."""

from __future__ import annotations

import shutil
import urllib.request
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from app.errors import InputError

LANES_REPO = "https://github.com/udacity/CarND-Advanced-Lane-Lines/raw/master"
VEHICLES_REPO = "https://github.com/udacity/CarND-Vehicle-Detection/raw/master"
TRAINING_BASE = "https://s3.amazonaws.com/udacity-sdc/Vehicle_Tracking"


@dataclass(frozen=True)
class Item:
    """One file of the data set, where it goes, and where it can be downloaded (if public)."""

    relative: str
    url: str | None


def _items() -> list[Item]:
    items = [
        Item("vehicles.zip", f"{TRAINING_BASE}/vehicles.zip"),
        Item("non-vehicles.zip", f"{TRAINING_BASE}/non-vehicles.zip"),
    ]
    items += [
        Item(f"camera_cal/calibration{i}.jpg", f"{LANES_REPO}/camera_cal/calibration{i}.jpg")
        for i in range(1, 21)
    ]
    stills = ["straight_lines1", "straight_lines2"] + [f"test{i}" for i in range(1, 7)]
    items += [Item(f"test_images/{s}.jpg", f"{LANES_REPO}/test_images/{s}.jpg") for s in stills]
    items.append(Item("videos/test_video.mp4", f"{VEHICLES_REPO}/test_video.mp4"))
    # The cuts of the project video and the hand-made labels exist only in the shared folder.
    for clip in ("project_cut_1", "project_cut_2"):
        items.append(Item(f"videos/{clip}.mp4", None))
    for clip in ("test_video", "project_cut_1", "project_cut_2"):
        items.append(Item(f"labels/{clip}.json", None))
    return items


EXPECTED_ZIP_PNGS = {"vehicles.zip": 8792, "non-vehicles.zip": 8968}


def _same_file(a: Path, b: Path) -> bool:
    return b.exists() and a.stat().st_size == b.stat().st_size


def _download(url: str, dest: Path) -> None:
    tmp = dest.with_name(f".{dest.name}.part")
    try:
        with urllib.request.urlopen(url, timeout=60) as response, tmp.open("wb") as out:
            shutil.copyfileobj(response, out)
        tmp.replace(dest)
    finally:
        tmp.unlink(missing_ok=True)


def _count_pngs(path: Path) -> int:
    with zipfile.ZipFile(path) as archive:
        return sum(1 for name in archive.namelist() if name.lower().endswith(".png"))


def gather(source: Path, dest: Path, log: Callable[[str], None] = print) -> int:
    """Copy or download every item into dest (skipping ones already there); return files added."""
    added = 0
    problems: list[str] = []
    for item in _items():
        target = dest / item.relative
        origin = source / item.relative
        if origin.exists():
            if _same_file(origin, target):
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(origin, target)
            added += 1
        elif target.exists():
            continue
        elif item.url is not None:
            log(f"downloading {item.url}")
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                _download(item.url, target)
                added += 1
            except OSError as error:
                problems.append(f"{item.relative} (download failed: {error})")
        else:
            problems.append(f"{item.relative} (only in the shared data folder)")
    for name, expected in EXPECTED_ZIP_PNGS.items():
        path = dest / name
        if path.exists():
            try:
                found = _count_pngs(path)
            except zipfile.BadZipFile:
                found = -1
            if found != expected:
                problems.append(f"{name} holds {found} PNGs, expected {expected}")
    if problems:
        raise InputError(
            f"data incomplete in {dest}: {'; '.join(problems)}. "
            f"Put the shared data folder at {source} (see README) or check the network"
        )
    return added
