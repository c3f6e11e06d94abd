"""Copies of training patches as other footage shows them: mirrored, degraded as a small,
compressed video frame is (fewer pixels, colour at half resolution, block compression), or
without colour as a monochrome camera's."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Degradation:
    """How `degraded` draws each patch's loss: the side it is seen at, in pixels of a 64 px
    patch, and the JPEG quality of its compression (colour at half resolution, 8 px blocks, as
    in H.264 footage). By default a patch keeps its pixels and loses colour resolution and
    sharpness to compression only: that is what cost the model most at 360 rows; shrunk to
    20-64 px as well, the model placed boxes less well (README)."""

    min_side: int = 64
    max_side: int = 64
    min_quality: int = 30
    max_quality: int = 90
    seed: int = 0


def mirrored(images: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Each (n, h, w, 3) patch flipped left to right."""
    return np.ascontiguousarray(images[:, :, ::-1])


def greyed(images: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Each RGB image of `images` (..., h, w, 3) with its colour taken out: its luma in all three
    channels, as a monochrome camera's frames (an infrared night camera's) decode."""
    flat = images.reshape(-1, *images.shape[-3:])
    grey = [
        cv2.cvtColor(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB) for image in flat
    ]
    return np.stack(grey).reshape(images.shape)


def degrade_patch(image: NDArray[np.uint8], side: int, quality: int) -> NDArray[np.uint8]:
    """`image` shrunk to `side` pixels, JPEG-compressed at `quality` (4:2:0) and enlarged back
    with bilinear interpolation, as the dense search enlarges a band whose windows are small."""
    h, w = image.shape[:2]
    small = image if side >= w else cv2.resize(image, (side, side), interpolation=cv2.INTER_AREA)
    params = [
        cv2.IMWRITE_JPEG_QUALITY,
        quality,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
    ]
    ok, encoded = cv2.imencode(".jpg", np.ascontiguousarray(small[:, :, ::-1]), params)
    if not ok:  # pragma: no cover - OpenCV always encodes a small RGB image
        raise RuntimeError("JPEG encoding failed")
    decoded = np.asarray(cv2.imdecode(encoded, cv2.IMREAD_COLOR))[:, :, ::-1]
    if decoded.shape[:2] != (h, w):
        decoded = cv2.resize(decoded, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(decoded)


def degraded(images: NDArray[np.uint8], config: Degradation | None = None) -> NDArray[np.uint8]:
    """Each (n, h, w, 3) patch degraded with its own side and quality, drawn reproducibly."""
    if not len(images):
        return images.copy()
    cfg = config if config is not None else Degradation()
    rng = np.random.default_rng(cfg.seed)
    width = images.shape[2]
    sides = np.round(rng.uniform(cfg.min_side, cfg.max_side, len(images)) * width / 64).astype(int)
    qualities = rng.integers(cfg.min_quality, cfg.max_quality + 1, len(images))
    drawn = zip(images, sides, qualities, strict=True)
    return np.stack([degrade_patch(im, int(s), int(q)) for im, s, q in drawn])
