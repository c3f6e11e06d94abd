"""Mining hard negatives from footage without vehicles: every window the detector is sure of
there is a false alarm, cut out as a patch for `roadview train --hard-negatives`."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from app.errors import InputError
from app.sources import ffmpeg_binary, probe_video, read_frames
from camera_cal import SceneTracker
from vehicles.augment import greyed
from vehicles.detector import VehicleDetector
from vehicles.mining import surest_apart, window_patches


@dataclass(frozen=True)
class Dimming:
    """A dim or cheap sensor's picture made of footage: ffmpeg's `eq` (`gamma`, `brightness`,
    `saturation`; left out where all three keep the picture) and grain of strength `grain`
    (0-100) drawn anew in every frame from `seed`, at `rows` rows (None: as stored), then encoded
    as a dashcam would (x264 at `crf`: 23, x264's default, smooths a daylight grain of 4 away, a
    dashcam's high bitrate, 18, keeps it)."""

    gamma: float
    brightness: float
    saturation: float
    grain: int
    seed: int
    rows: int | None = None
    crf: int = 23

    def filters(self) -> str:
        """The ffmpeg filter chain."""
        scale = f"scale=-2:{self.rows}," if self.rows is not None else ""
        light = (self.gamma, self.brightness, self.saturation) != (1, 0, 1)
        eq = (
            f"eq=gamma={self.gamma:g}:brightness={self.brightness:g}:"
            f"saturation={self.saturation:g},"
            if light
            else ""
        )
        return f"{scale}{eq}noise=alls={self.grain}:allf=t:all_seed={self.seed}"


def grainy(strength: int, seed: int = 7, dusk: bool = False) -> Dimming:
    """A sensor's grain of `strength` as a high-bitrate dashcam keeps it (CRF 18): in the light
    as it is, or at `dusk` (the shared clips' asphalt at about 30 grey levels)."""
    light = (0.75, -0.05, 0.85) if dusk else (1.0, 0.0, 1.0)
    return Dimming(*light, grain=strength, seed=seed, crf=18)


# The dusk and night copies the dark verifier's hard negatives are mined from: roads of 1-18 grey
# levels, at 360 rows and upscaled to 720 (other strengths than the README's grainy copies).
DUSK = (
    Dimming(0.6, -0.06, 0.7, grain=4, seed=11),
    Dimming(0.5, -0.1, 0.6, grain=8, seed=13, rows=720),
    Dimming(0.6, -0.06, 0.7, grain=5, seed=17, rows=720),
)


def dimmed_copy(video: Path, dimming: Dimming, out: Path) -> Path:
    """`video` as `dimming` makes it, written to `out`."""
    command = [ffmpeg_binary(), "-y", "-loglevel", "error", "-i", str(video)]
    command += ["-vf", dimming.filters(), "-an", "-c:v", "libx264", "-crf", str(dimming.crf)]
    done = subprocess.run([*command, str(out)], capture_output=True, text=True)
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise InputError(f"cannot make a dimmed copy of {video} ({last}); check the clip")
    return out


def mine_clip(
    video: Path,
    detector: VehicleDetector,
    out: Path,
    share: float = 0.6,
    every: int = 3,
    min_probability: float = 0.5,
    per_frame: int = 8,
    as_seen: bool = False,
    name: str | None = None,
    grey: bool = False,
) -> int:
    """Write the surest windows of every `every`-th frame of the first `share` of `video` (a
    clip without vehicles) to `out` as `<name>_<frame>_<k>.png` (`name`: the clip's); how many.
    The windows are placed from the scene as in `roadview process` (no undistortion: footage of
    an unknown camera) and, `as_seen`, read the picture as `process` reads it (on a dark road
    the mean of the last frames); `grey`: without its colour (for the grey verifiers, with a
    grey model). The rest of the clip is left for measuring what the mined patches did."""
    info = probe_video(video)
    tracker = SceneTracker(info.size, detector.config.reference_horizon * info.size[1])
    detector.reset(info.fps)
    end = round(share * info.n_frames)
    written = 0
    for index, frame in enumerate(read_frames(video, info, 0, end)):
        scene = tracker.update(frame)
        if as_seen:
            frame = detector.seen(frame, scene.road_grey, scene.grain)
        if grey:
            frame = greyed(frame)
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
            path = out / f"{name or video.stem}_{index:05d}_{k:02d}.png"
            cv2.imwrite(str(path), np.ascontiguousarray(patch[:, :, ::-1]))
            written += 1
    return written


def mine_clips(
    videos: list[Path],
    detector: VehicleDetector,
    out: Path,
    share: float = 0.6,
    every: int = 3,
    log: Callable[[str], None] = lambda message: None,
    dimmings: Sequence[Dimming] = (),
    grey: bool = False,
) -> int:
    """`mine_clip` over `videos` into the folder `out`, which appears only when all are done
    (written beside it, then renamed; an older `out` is replaced). With `dimmings`, each clip's
    copies so dimmed are mined instead, read as `process` reads them; `grey`: each clip
    without its colour."""
    out.parent.mkdir(parents=True, exist_ok=True)
    total = 0
    with tempfile.TemporaryDirectory(prefix=f".{out.name}.", dir=out.parent) as tmp:
        part = Path(tmp) / "patches"
        part.mkdir()
        for video in videos:
            for k, dimming in enumerate(dimmings):
                copy = dimmed_copy(video, dimming, Path(tmp) / f"dim{k}.mp4")
                name = f"{video.stem}_dim{k}"
                count = mine_clip(
                    copy, detector, part, share, every, as_seen=True, name=name, grey=grey
                )
                log(f"{video.name}, dimmed ({dimming.filters()}): {count} patches")
                total += count
            if not dimmings:
                count = mine_clip(video, detector, part, share, every, grey=grey)
                log(f"{video.name}: {count} patches")
                total += count
        if out.exists():
            shutil.rmtree(out)
        part.rename(out)
    return total
