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


def _part(relative: str) -> str:
    """The part of the data set a file belongs to: its folder, or the file itself at the top."""
    folder, _, _ = relative.rpartition("/")
    return f"{folder}/" if folder else relative


def gather(source: Path, dest: Path, log: Callable[[str], None] = print) -> int:
    """Copy or download every item into dest (skipping ones already there); return files added.

    What is still missing is logged as one short line per part of the data set (a folder or a
    zip), and the error says how many parts; after one failed download no other is tried.
    """
    added = 0
    missing: dict[str, list[str]] = {}  # part -> reasons, one per missing file
    offline: str | None = None
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
        elif item.url is None:
            missing.setdefault(_part(item.relative), []).append("only in the shared data folder")
        elif offline is not None:
            missing.setdefault(_part(item.relative), []).append(offline)
        else:
            log(f"downloading {item.url}")
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                _download(item.url, target)
                added += 1
            except OSError as error:
                reason = getattr(error, "reason", None) or error.strerror or error
                offline = f"download failed: {reason}"
                missing.setdefault(_part(item.relative), []).append(offline)
    for name, expected in EXPECTED_ZIP_PNGS.items():
        path = dest / name
        if path.exists():
            try:
                found = _count_pngs(path)
            except zipfile.BadZipFile:
                found = -1
            if found != expected:
                missing.setdefault(name, []).append(f"holds {found} PNGs, expected {expected}")
    for part, reasons in missing.items():
        count = f"{len(reasons)} files" if len(reasons) > 1 else "1 file"
        log(f"missing {part}: {count} ({'; '.join(sorted(set(reasons)))})")
    if missing:
        raise InputError(
            f"data incomplete: {len(missing)} parts missing (listed above); put the shared "
            "data folder beside the checkout (README, Data) or check the network"
        )
    return added
