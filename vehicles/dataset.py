"""The 64x64 training patches, read from the zips or their folders, grouped for honest splits."""

from __future__ import annotations

import re
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

PATCH_SUFFIXES = (".png", ".jpg", ".jpeg")
GROUP_CHUNK = 30  # consecutive frames in one group at most, so a long run is not one giant group


class DatasetError(Exception):
    """The training data cannot be found or read; the message states the facts."""


@dataclass(frozen=True, eq=False)
class PatchSet:
    """RGB patches with labels (1 = vehicle), a group id per patch, and where each came from."""

    images: NDArray[np.uint8]  # (n, size, size, 3)
    labels: NDArray[np.int8]
    groups: NDArray[np.int64]
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, index: NDArray[np.intp]) -> PatchSet:
        """The patches at `index`."""
        return PatchSet(
            self.images[index],
            self.labels[index],
            self.groups[index],
            tuple(self.names[i] for i in index),
        )


def _decode(data: bytes, size: int) -> NDArray[np.uint8] | None:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return None
    if image.shape[:2] != (size, size):
        image = cv2.resize(image, (size, size), interpolation=cv2.INTER_AREA)
    return np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def _entries(root: Path, kind: str) -> Iterator[tuple[str, bytes]]:
    """(relative name, bytes) of every patch of one kind, from `kind/` or `kind.zip`."""
    folder, archive = root / kind, root / f"{kind}.zip"
    if folder.is_dir():
        for path in sorted(folder.rglob("*")):
            if path.suffix.lower() in PATCH_SUFFIXES:
                yield str(path.relative_to(root)), path.read_bytes()
    elif archive.is_file():
        with zipfile.ZipFile(archive) as zf:
            for name in sorted(zf.namelist()):
                if name.lower().endswith(PATCH_SUFFIXES) and "__MACOSX" not in name:
                    yield name, zf.read(name)
    else:
        raise DatasetError(f"neither {folder} nor {archive} exists")


def group_key(name: str) -> tuple[str, int]:
    """Group of a patch: its folder and a chunk of consecutive image numbers within it.

    GTI folders hold consecutive video frames (near-duplicates); runs of consecutive numbers are
    cut into chunks of GROUP_CHUNK so that a split keeps near-duplicates on one side.
    """
    parts = name.replace("\\", "/").split("/")
    folder = "/".join(parts[:-1])
    digits = re.findall(r"\d+", parts[-1])
    number = int(digits[-1]) if digits else 0
    return folder, number // GROUP_CHUNK


def load_patches(root: Path, size: int = 64) -> PatchSet:
    """Every vehicle and non-vehicle patch under `root` (zips or extracted folders)."""
    images: list[NDArray[np.uint8]] = []
    labels: list[int] = []
    names: list[str] = []
    for label, kind in ((1, "vehicles"), (0, "non-vehicles")):
        count = 0
        for name, data in _entries(root, kind):
            image = _decode(data, size)
            if image is None:
                continue
            images.append(image)
            labels.append(label)
            names.append(name)
            count += 1
        if count == 0:
            raise DatasetError(f"no {kind} patches (.png/.jpg) found under {root}")
    keys = [group_key(n) for n in names]
    index = {key: i for i, key in enumerate(dict.fromkeys(keys))}
    return PatchSet(
        images=np.stack(images),
        labels=np.asarray(labels, dtype=np.int8),
        groups=np.asarray([index[k] for k in keys], dtype=np.int64),
        names=tuple(names),
    )


def load_patch_folder(folder: Path, size: int = 64) -> list[NDArray[np.uint8]]:
    """Every patch image under a folder (e.g. mined hard negatives), as RGB of `size`."""
    if not folder.is_dir():
        raise DatasetError(f"{folder} is not a folder of patches")
    images = [
        _decode(p.read_bytes(), size)
        for p in sorted(folder.rglob("*"))
        if p.suffix.lower() in PATCH_SUFFIXES
    ]
    return [image for image in images if image is not None]
