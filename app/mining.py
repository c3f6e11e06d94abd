"""Mining hard negatives from footage without vehicles: every window the detector is sure of
there is a false alarm, cut out as a patch for `roadview train --hard-negatives`."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from app.sources import probe_video, read_frames
from camera_cal import SceneTracker
from vehicles.detector import VehicleDetector
from vehicles.mining import surest_apart, window_patches


def mine_clip(
    video: Path,
    detector: VehicleDetector,
    out: Path,
    share: float = 0.6,
    every: int = 3,
    min_probability: float = 0.5,
    per_frame: int = 8,
) -> int:
    """Write the surest windows of every `every`-th frame of the first `share` of `video` (a
    clip without vehicles) to `out` as `<clip>_<frame>_<k>.png`; how many. The windows are
    placed from the scene as in `roadview process` (no undistortion: footage of an unknown
    camera). The rest of the clip is left for measuring what the mined patches did."""
    info = probe_video(video)
    tracker = SceneTracker(info.size, detector.config.reference_horizon * info.size[1])
    end = round(share * info.n_frames)
    written = 0
    for index, frame in enumerate(read_frames(video, info, 0, end)):
        tracker.update(frame)
        if index % every:
            continue
        placed = tracker.placement
        view = detector.view(info.size, placed["horizon_y"], placed["live"], placed["scale_height"])
        hits = detector.search(frame, None, view)
        if not hits:
            continue
        boxes = np.concatenate([hit.boxes for hit in hits])
        proba = detector.window_terms(hits, view)[0]
        chosen = surest_apart(boxes, proba, min_probability, per_frame)
        for k, patch in enumerate(window_patches(frame, boxes[chosen])):
            name = out / f"{video.stem}_{index:05d}_{k:02d}.png"
            cv2.imwrite(str(name), np.ascontiguousarray(patch[:, :, ::-1]))
            written += 1
    return written


def mine_clips(
    videos: list[Path],
    detector: VehicleDetector,
    out: Path,
    share: float = 0.6,
    every: int = 3,
    log: Callable[[str], None] = lambda message: None,
) -> int:
    """`mine_clip` over `videos` into the folder `out`, which appears only when all are done
    (written beside it, then renamed; an older `out` is replaced)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    total = 0
    with tempfile.TemporaryDirectory(prefix=f".{out.name}.", dir=out.parent) as tmp:
        part = Path(tmp) / "patches"
        part.mkdir()
        for video in videos:
            count = mine_clip(video, detector, part, share, every)
            log(f"{video.name}: {count} patches")
            total += count
        if out.exists():
            shutil.rmtree(out)
        part.rename(out)
    return total
