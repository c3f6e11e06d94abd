"""Frame sources: probing a video, decoding its frames through ffmpeg, reading stills.

ffmpeg is the binary the imageio-ffmpeg package ships. Decoding applies a rotation tag, so every
frame, size and coordinate downstream is of the upright picture.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import re
import subprocess
import tempfile
import threading
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from queue import Empty, Queue
from typing import IO

import cv2
import numpy as np
from numpy.typing import NDArray

from app.errors import InputError

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})
Frame = NDArray[np.uint8]  # H x W x 3, RGB


@functools.cache
def ffmpeg_binary() -> str:
    """Path of the ffmpeg executable that the imageio-ffmpeg package ships."""
    from imageio_ffmpeg import get_ffmpeg_exe

    return str(get_ffmpeg_exe())


@functools.cache
def can_tone_map() -> bool:
    """Whether the ffmpeg in use has the filters of the HDR tone map (imageio-ffmpeg's builds
    do; one named by IMAGEIO_FFMPEG_EXE may not)."""
    try:
        done = subprocess.run(
            [ffmpeg_binary(), "-hide_banner", "-filters"],
            capture_output=True,
            timeout=60,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    lines = done.stdout.decode(errors="replace").splitlines()
    names = {line.split()[1] for line in lines if len(line.split()) > 2}
    return {"zscale", "tonemap"} <= names


@dataclass(frozen=True)
class VideoInfo:
    """What a video file holds, as ffmpeg decodes it (rotation applied)."""

    size: tuple[int, int]  # (width, height) of the decoded, upright frames
    fps: float
    n_frames: int
    duration: float
    has_audio: bool
    rotation: int = 0  # degrees of the display-matrix tag that decoding applies
    # The stored pixels' width over their height (an anamorphic 960x720 16:9 video: 4/3);
    # decoding stretches them square, so `size` is the picture as it is meant to be seen.
    pixel_aspect: float = 1.0
    # The HDR transfer of a phone's HDR video ("smpte2084": PQ, "arib-std-b67": HLG), which
    # decoding tone-maps to the SDR picture the stages were tuned on; None: SDR.
    hdr: str | None = None
    # The upright, square-pixel size before `within_size` reduced `size` to it; None: not reduced.
    reduced_from: tuple[int, int] | None = None
    # Seconds from the file's start to its first video frame (an audio track or an edit list
    # that starts earlier): where frame k is sought (see `read_frames`).
    video_start_s: float = 0.0
    # A variable frame rate (a phone's video slows in low light): the presentation times of
    # the decoded frames, in seconds from the first; they are read at the steady `fps` the
    # video mostly runs at, each frame shown where it plays (`steady_sources`). None: steady.
    frame_times: tuple[float, ...] | None = None
    # Stored as fields (a camcorder's or a broadcast's 1080i): decoded, each frame is
    # deinterlaced, else a moving car's rows alternate between two moments (combing).
    interlaced: bool = False
    # The lens's focal length in 35 mm terms as the file's tag states it (a phone's), or None.
    focal_mm: float | None = None
    # What ffmpeg said of a damaged file (its last error: "partial file" where a camera's
    # recording was cut off), or None. The frames that decode are processed all the same.
    damage: str | None = None
    # Seconds of video the file states (its index or header); beyond `duration` where the
    # damage cut the frames short.
    stated_duration: float = 0.0
    # Degrees clockwise that decoding turns the picture, after the tag, to stand it upright
    # where the user says it is not (`turned_info`: a camera mounted upside down, a phone's
    # video that lost its tag); `size` is the turned picture's.
    turn_deg: int = 0


# The ffmpeg filters that turn a picture so many degrees clockwise.
TURN_FILTERS = {90: "transpose=clock", 180: "hflip,vflip", 270: "transpose=cclock"}


def turned_info(info: VideoInfo, degrees: int) -> VideoInfo:
    """`info` with its frames to be decoded turned `degrees` clockwise (0, 90, 180 or 270),
    after any rotation tag and before `within_size`."""
    degrees %= 360
    if degrees == 0:
        return info
    width, height = info.size
    size = (height, width) if degrees in (90, 270) else (width, height)
    return replace(info, size=size, turn_deg=degrees)


def turned_image(image: Frame, degrees: int) -> Frame:
    """A still turned `degrees` clockwise (0, 90, 180 or 270), as `turned_info` turns video."""
    quarters = (degrees % 360) // 90
    return image if quarters == 0 else np.ascontiguousarray(np.rot90(image, -quarters))


def within_size(info: VideoInfo, max_side: int) -> VideoInfo:
    """`info` with its frames to be decoded at most `max_side` pixels on their shorter side
    (0: as they are): 4K as 1080p, a portrait 2160x3840 as 1080x1920; the aspect ratio kept, the
    sides even (the 4:2:0 output's)."""
    width, height = info.size
    short = min(width, height)
    if max_side <= 0 or short <= max_side:
        return info
    scale = max_side / short
    size = (2 * round(width * scale / 2), 2 * round(height * scale / 2))
    return replace(info, size=size, reduced_from=info.size)


def reduced_row(y: float | None, info: VideoInfo) -> float | None:
    """A row of the video as it is stored (a user's `--horizon`) in the frames `info` decodes."""
    if y is None or info.reduced_from is None:
        return y
    return y * info.size[1] / info.reduced_from[1]


def is_image(path: Path) -> bool:
    """Whether a path names a still image by its suffix."""
    return path.suffix.lower() in IMAGE_SUFFIXES


def check_input(path: Path) -> None:
    """Refuse a missing, unreadable or empty input file with a clear message."""
    if not path.exists():
        raise InputError(f"input {path} does not exist; check the path")
    if path.is_dir():
        raise InputError(f"input {path} is a folder; pass a video or image file")
    try:
        with path.open("rb") as handle:
            if not handle.read(1):
                raise InputError(f"input {path} is empty; pass a video or image file")
    except PermissionError:
        raise InputError(f"input {path} cannot be read (permission denied)") from None


_STREAM = re.compile(r"^\s*Stream #0:\d+.*?: (Video|Audio): (.*)$")
_SIZE = re.compile(r"(?:^|[ ,])(\d{1,5})x(\d{1,5})(?:[ ,]|$)")
_RATE = re.compile(r"([\d.]+)(k?) (fps|tbr)")
_ROTATION = re.compile(r"(?:rotation of|rotate\s*:)\s*(-?[\d.]+)")
_SAR = re.compile(r"\[SAR (\d+):(\d+) DAR")
_FIELDS = re.compile(r"\b(?:top|bottom) (?:coded )?first\b")
_HDR = re.compile(r"\b(smpte2084|arib-std-b67)\b")
# The key of the lens's 35 mm-equivalent focal length in mm, as an iPhone (and apps writing
# Apple's keys) tags its videos: ffmpeg lists it among the file's metadata.
FOCAL_LENGTH_KEY = "com.apple.quicktime.camera.focal_length.35mm_equivalent"
_FOCAL = re.compile(rf"^\s*{re.escape(FOCAL_LENGTH_KEY)}\s*:\s*([\d.]+)")
_DURATION = re.compile(r"Duration: (\d+):(\d+):([\d.]+)")
_FILE_START = re.compile(r"Duration: .*?\bstart: (-?[\d.]+)")
_STREAM_START = re.compile(r"\bstart (-?[\d.]+)")
_PACKETS = re.compile(r"frame=\s*(\d+)")
_LEVEL = re.compile(r"\[(error|fatal)\] (.*)$")
_TIME_BASE = re.compile(r"^#tb 0: (\d+)/(\d+)")
_NO_PTS = -(2**63)


def _seconds(h: str, m: str, s: str) -> float:
    return int(h) * 3600 + int(m) * 60 + float(s)


@dataclass
class ProbeFacts:
    """What one probing pass of ffmpeg said about a file (filled while parsing its log)."""

    size: tuple[int, int] | None = None
    fps: float = 0.0
    duration: float = 0.0
    packets: int | None = None
    audio: bool = False
    rotation: int = 0
    pixel_aspect: float = 1.0
    hdr: str | None = None
    interlaced: bool = False
    focal_mm: float | None = None
    file_start: float = 0.0  # seconds: the earliest stream's first timestamp
    video_start: float | None = None  # seconds: the video's first frame's, when ffmpeg says
    errors: list[str] = field(default_factory=list)


def parse_probe(text: str) -> ProbeFacts:
    """Facts from `ffmpeg -loglevel level+info -i FILE -map 0:v:0 -c copy -f null -` output.

    Only the input section describes the file; the stream copy's closing `frame=` counts the
    video packets (the container's duration also counts a longer audio track), and errors while
    reading every packet mean the file is damaged.
    """
    facts = ProbeFacts()
    in_input, in_video = True, False
    for raw in text.replace("\r", "\n").splitlines():
        line = raw[len("[info] ") :] if raw.startswith("[info] ") else raw
        if line.startswith(("Output #", "Stream mapping")):
            in_input = False
        if in_input:
            if (match := _DURATION.search(line)) is not None:
                facts.duration = _seconds(*match.groups())
                if (start := _FILE_START.search(line)) is not None:
                    facts.file_start = float(start.group(1))
            if (match := _STREAM.match(line)) is not None:
                kind, details = match.groups()
                in_video = False
                if kind == "Audio":
                    facts.audio = True
                elif "(attached pic)" in details:
                    pass  # a cover picture (a song's, a podcast's), not video
                elif facts.size is None and (size := _SIZE.search(details)) is not None:
                    facts.size = (int(size.group(1)), int(size.group(2)))
                    found = _RATE.findall(details)
                    rates = {unit: float(v) * (1000 if k else 1) for v, k, unit in found}
                    facts.fps = rates.get("fps") or rates.get("tbr") or 0.0
                    sar = _SAR.search(details)
                    if sar is not None and int(sar.group(1)) > 0 and int(sar.group(2)) > 0:
                        facts.pixel_aspect = int(sar.group(1)) / int(sar.group(2))
                    facts.interlaced = _FIELDS.search(details) is not None
                    if (hdr := _HDR.search(details)) is not None:
                        facts.hdr = hdr.group(1)
                    if (start := _STREAM_START.search(details)) is not None:
                        facts.video_start = float(start.group(1))
                    in_video = True
            elif in_video and (rotation := _ROTATION.search(line)) is not None:
                facts.rotation = round(float(rotation.group(1))) % 360
            elif (focal := _FOCAL.match(line)) is not None and float(focal.group(1)) > 0:
                facts.focal_mm = float(focal.group(1))
        if (match := _PACKETS.search(line)) is not None:
            facts.packets = int(match.group(1))
        if (match := _LEVEL.search(raw)) is not None:
            facts.errors.append(match.group(2).strip())
    return facts


def packet_times(text: str, start: float = 0.0) -> NDArray[np.float64]:
    """The presentation times, in seconds from the first, of the packets that `ffmpeg -f
    framecrc` lists (in decoding order: sorted here), leaving out those before `start`, the
    video's first time (an edit list's, which decoding drops)."""
    scale, found = 0.0, []
    for line in text.splitlines():
        if (base := _TIME_BASE.match(line)) is not None:
            scale = int(base.group(1)) / int(base.group(2))
        elif line and not line.startswith("#"):
            fields = line.split(",")
            if len(fields) > 2 and fields[2].strip().lstrip("-").isdigit():
                found.append(int(fields[2]))
    pts = np.sort(np.array([v for v in found if v != _NO_PTS], dtype=np.float64)) * scale
    pts = pts[pts >= start - 1e-6]
    return pts - pts[0] if len(pts) else pts


def variable_rate(times: NDArray[np.float64], max_drift_s: float = 0.1) -> float | None:
    """The steady rate to read a video at whose frames stray from any steady rate by more than
    `max_drift_s` (audio and video noticeably apart), or None for a steady video.

    The rate is the one the video mostly runs at: its median frame step, averaged over the
    steps near it (a 29.97 fps step in milliseconds alternates 33 and 34). A frame dropped now
    and then strays by a step at most and is left alone.
    """
    if len(times) < 3:
        return None
    steps = np.diff(times)
    line = times[0] + (times[-1] - times[0]) * np.arange(len(times)) / (len(times) - 1)
    if float(np.abs(times - line).max()) <= max_drift_s:
        return None
    usual = float(np.median(steps[steps > 0]))
    near = steps[np.abs(steps - usual) <= 0.1 * usual]
    return 1.0 / float(near.mean())


def steady_sources(times: NDArray[np.float64], fps: float) -> NDArray[np.intp]:
    """For each frame of a variable-rate video read at a steady `fps`, the index of the decoded
    frame that plays at its time (the nearest): repeated where the video ran slower, skipping
    frames where it ran faster."""
    slots = np.arange(round(float(times[-1]) * fps) + 1) / fps
    after = np.clip(np.searchsorted(times, slots), 1, len(times) - 1)
    before = after - 1
    nearer_before = slots - times[before] <= times[after] - slots
    return np.where(nearer_before, before, after)


def _cut_off_mp4(path: Path, errors: list[str]) -> bool:
    """Whether `path` is an MP4/MOV (it opens with an `ftyp` box) whose index ffmpeg did not
    find: a recording cut off before the camera wrote it last (any other file named .mp4 gets
    the same complaint from ffmpeg)."""
    with path.open("rb") as handle:
        head = handle.read(8)
    return head[4:8] == b"ftyp" and any("moov atom not found" in e for e in errors)


def probe_video(path: Path) -> VideoInfo:
    """Size (as decoded, rotation applied), rate, frame count and audio of a video.

    One ffmpeg pass lists every video packet's time (no decoding): cheap, and it reads the
    whole file, so truncation shows here, before any output is started; the times tell a
    variable frame rate.
    """
    check_input(path)
    command = [
        ffmpeg_binary(),
        "-hide_banner",
        "-nostdin",
        "-loglevel",
        "level+info",
        "-i",
        str(path),
        "-map",
        "0:v:0?",
        "-c",
        "copy",
        "-f",
        "framecrc",
        "-",
    ]
    try:
        done = subprocess.run(command, capture_output=True, timeout=600, check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise InputError(f"ffmpeg could not read {path} ({error})") from None
    facts = parse_probe(done.stderr.decode(errors="replace"))
    if facts.size is None and _cut_off_mp4(path, facts.errors):
        raise InputError(
            f"{path} ends before its index (moov atom) was written: the recording was cut off "
            "(a dashcam losing power, a copy stopped); a repair tool such as untrunc rebuilds "
            "it with a good file of the same camera"
        )
    if facts.size is None and facts.audio:
        raise InputError(f"{path} has sound but no picture; pass a video file")
    if facts.size is None:
        raise InputError(
            f"{path} is not a video ffmpeg can read; pass an .mp4/.mov/.mkv/.webm file"
        )
    video_start_s = max(
        0.0,
        (facts.file_start if facts.video_start is None else facts.video_start) - facts.file_start,
    )
    # The listed times are the file's, counted from its start, as the seeks are.
    times = packet_times(done.stdout.decode(errors="replace"), video_start_s)
    steady = variable_rate(times) if facts.fps > 0 else None
    frame_times = None
    if steady is not None:
        facts.fps, frame_times = steady, tuple(float(t) for t in times)
        n_frames = len(steady_sources(times, steady))
    else:
        # Packets can exceed frames (an edit list may drop a few at the start) and the
        # duration can exceed the video (a longer audio track): the smaller is the estimate.
        # The decoded count is what the drivers go by.
        n_frames = round(facts.duration * facts.fps)
        if facts.packets is not None:
            n_frames = min(n_frames, facts.packets) if n_frames > 0 else facts.packets
    duration = n_frames / facts.fps if facts.fps > 0 else 0.0
    if facts.fps <= 0 or min(facts.size) <= 0 or n_frames <= 0:
        if facts.errors:
            raise InputError(
                f"{path} is truncated or damaged, and no frame of it decodes (ffmpeg: "
                f"{facts.errors[-1]}); re-export or re-download the video"
            )
        raise InputError(f"{path} has no video frames; the file may be truncated or empty")
    width, height = square_size(facts.size, facts.pixel_aspect)
    if facts.rotation in (90, 270):
        width, height = height, width
    return VideoInfo(
        size=(width, height),
        fps=facts.fps,
        n_frames=n_frames,
        duration=duration,
        has_audio=facts.audio,
        rotation=facts.rotation,
        pixel_aspect=facts.pixel_aspect,
        hdr=facts.hdr,
        interlaced=facts.interlaced,
        video_start_s=video_start_s,
        frame_times=frame_times,
        focal_mm=facts.focal_mm,
        damage=facts.errors[-1] if facts.errors else None,
        stated_duration=facts.duration,
    )


def decoding_notes(info: VideoInfo) -> list[str]:
    """What decoding changes of the stored picture, in a user's words (nothing for most video)."""
    notes = []
    if info.hdr is not None:
        curve = "PQ" if info.hdr == "smpte2084" else "HLG"
        notes.append(
            f"HDR video ({curve}): tone-mapped to SDR"
            if can_tone_map()
            else f"HDR video ({curve}), but this ffmpeg has no zscale and tonemap filters: "
            "decoded as it is, darker and greyer than meant (unset IMAGEIO_FFMPEG_EXE to use "
            "imageio-ffmpeg's own)"
        )
    if info.interlaced:
        notes.append("interlaced video: deinterlaced while decoding")
    if not square(info.pixel_aspect):
        shown = info.reduced_from or info.size
        # Three digits, four near 1 (a 853x481 rescale tagged 1.0025 read "1 times").
        digits = 3 if abs(info.pixel_aspect - 1.0) >= 0.01 else 4
        notes.append(
            f"pixels stored {info.pixel_aspect:.{digits}g} times as wide as tall: stretched "
            f"square, {shown[0]}x{shown[1]}"
        )
    if info.frame_times is not None:
        times = np.asarray(info.frame_times)
        sources = steady_sources(times, info.fps)
        distinct = len(np.unique(sources))
        steps = np.diff(times)
        rates = 1.0 / np.percentile(steps[steps > 0], [95, 5])
        notes.append(
            f"a variable frame rate ({rates[0]:.0f}-{rates[1]:.0f} fps): read at a steady "
            f"{info.fps:.4g} fps, each frame where it plays ({len(sources) - distinct} shown "
            f"twice or more, {len(times) - distinct} skipped), so the output keeps time with "
            "the sound"
        )
    if info.damage is not None:
        notes.append(damage_note(info))
    if info.reduced_from is not None:
        (fw, fh), (w, h) = info.reduced_from, info.size
        notes.append(
            f"{fw}x{fh} is processed and written at {w}x{h} (--max-size 0 keeps the full size)"
        )
    return notes


def damage_note(info: VideoInfo) -> str:
    """What is processed of a damaged file: the frames that decode (a dashcam's recording cut
    off by a power cut keeps its start), and how much of the video its index states is lost."""
    if info.stated_duration > info.duration + 1.0 / info.fps:
        return (
            f"cut short (ffmpeg: {info.damage}): it stops after {info.duration:.1f} s of the "
            f"{info.stated_duration:.1f} s it states; the frames up to there are processed, "
            "the rest is lost"
        )
    return (
        f"damaged (ffmpeg: {info.damage}): its frames are processed as they decode, damaged "
        "blocks filled in by ffmpeg, where lanes and vehicles may be misread"
    )


def square(pixel_aspect: float) -> bool:
    """Whether pixels this many times as wide as tall are square (a 1279x719 rescale of a
    1280x720 picture is tagged 0.9994: a pixel's worth over its width, left alone)."""
    return abs(pixel_aspect - 1.0) < 1e-3


def square_size(stored: tuple[int, int], pixel_aspect: float) -> tuple[int, int]:
    """The size of a `stored` picture whose pixels are `pixel_aspect` times as wide as tall,
    with square pixels: widened (or made taller) to an even size, never shrunk, so no detail is
    lost and the 4:2:0 output takes it."""
    width, height = stored
    if square(pixel_aspect):
        return width, height
    if pixel_aspect > 1:
        return 2 * round(width * pixel_aspect / 2), height
    return width, 2 * round(height / pixel_aspect / 2)


# HDR to SDR BT.709: light made linear with HDR's reference white (203 nits, ITU-R BT.2408) as
# SDR's white, BT.2020 primaries converted to BT.709 in linear light, brighter light rolled off
# (Mobius: unchanged below 60 % of white), and the BT.709 curve. Decoded as they are, PQ video
# reads dim and grey (the test clip's mean 74 against 106 of 255).
SDR_TONE_MAP = (
    "zscale=t=linear:npl=203,format=gbrpf32le,zscale=p=bt709,"
    "tonemap=tonemap=mobius:param=0.6:desat=0,zscale=t=bt709:m=bt709:r=tv,format=gbrp"
)


def read_frames(
    path: Path, info: VideoInfo, start_frame: int = 0, end_frame: int | None = None
) -> Generator[Frame, None, None]:
    """Decoded upright RGB frames in order, from `start_frame` up to (not including) `end_frame`:
    frame k is the picture that plays k / fps after the first (a variable-rate video's frames
    repeated or skipped to a steady rate, see `VideoInfo.frame_times`)."""
    if info.frame_times is None:
        # The first frame at or after half a frame before frame `start_frame`'s time (ffmpeg
        # seeks in the file's time, from its start: the LA clip's video starts 2 frames in,
        # and seeking to 182 / fps gave frame 180).
        seek = info.video_start_s + (start_frame - 0.5) / info.fps if start_frame > 0 else None
        decoded = _decode(path, info, seek)
        count = None if end_frame is None else max(0, end_frame - start_frame)
        try:
            yield from itertools.islice(decoded, count)
        finally:
            decoded.close()
        return
    times = np.asarray(info.frame_times)
    sources = steady_sources(times, info.fps)
    end = len(sources) if end_frame is None else min(end_frame, len(sources))
    if start_frame >= end:
        return
    first = int(sources[start_frame])
    # Sought half way from the frame before: the decoder starts at the frame wanted.
    seek = info.video_start_s + (times[first - 1] + times[first]) / 2 if first > 0 else None
    decoded = _decode(path, info, seek)
    index, frame = first - 1, None
    try:
        for k in range(start_frame, end):
            while index < sources[k]:
                frame = next(decoded, None)
                if frame is None:
                    return
                index += 1
            assert frame is not None
            yield frame
    finally:
        decoded.close()


def _decode(path: Path, info: VideoInfo, seek_s: float | None) -> Generator[Frame, None, None]:
    """Every frame ffmpeg decodes, in order, from the first at or after `seek_s` (seconds of
    the file's time) or from the start.

    ffmpeg's messages go to a temporary file, not a pipe: a pipe nobody reads fills up and stalls
    the decoder on a file with many warnings.
    """
    width, height = info.size
    command = [ffmpeg_binary(), "-nostdin", "-loglevel", "error"]
    if seek_s is not None:
        command += ["-ss", f"{seek_s:.6f}"]
    command += [
        "-i",
        str(path),
        "-map",
        "0:v:0",
        "-fps_mode",
        # A damaged file's frame that does not decode is filled with the one before (a steady
        # rate kept), so the frames after it keep their times; others pass as they are.
        "cfr" if info.damage is not None and info.frame_times is None else "passthrough",
    ]
    filters = []
    if info.interlaced:
        # One frame out per frame in (the rate kept), only frames flagged interlaced touched.
        filters.append("bwdif=mode=send_frame:deint=interlaced")
    if info.hdr is not None and can_tone_map():
        filters.append(SDR_TONE_MAP)
    if info.turn_deg:
        # Before any scaling, whose size is the turned picture's.
        filters.append(TURN_FILTERS[info.turn_deg])
    if info.reduced_from is not None:
        # Shrunk by area averaging (after any square-pixel stretch: one scaling does both).
        filters.append(f"scale={width}:{height}:flags=area,setsar=1")
    elif not square(info.pixel_aspect):
        # Square pixels, after the rotation ffmpeg applies first: the upright picture's size.
        filters.append(f"scale={width}:{height}:flags=bicubic,setsar=1")
    if filters:
        command += ["-vf", ",".join(filters)]
    command += [
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-",
    ]
    frame_bytes = width * height * 3
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=log, bufsize=frame_bytes * 2
        )
        assert process.stdout is not None
        try:
            while (data := _read_exactly(process.stdout, frame_bytes)) is not None:
                yield np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3)
        finally:
            process.kill()
            process.wait()
            process.stdout.close()


def _read_exactly(stream: IO[bytes], n: int) -> bytes | None:
    """Exactly n bytes from a pipe, or None at end of stream (a partial frame is dropped)."""
    chunks = []
    remaining = n
    while remaining:
        chunk = stream.read(remaining)
        if not chunk:
            return None
        chunks.append(chunk)
        remaining -= len(chunk)
    return b"".join(chunks) if len(chunks) > 1 else chunks[0]


def read_image(path: Path) -> Frame:
    """A still as 8-bit RGB: grey, 16-bit and 4-channel images are converted, not refused."""
    check_input(path)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise InputError(f"{path} is not an image OpenCV can read; pass a .jpg or .png file")
    image = np.asarray(raw)
    if image.dtype != np.uint8:
        scale = (
            255.0 / max(float(np.iinfo(image.dtype).max), 1.0)
            if image.dtype.kind in "ui"
            else 255.0
        )
        image = np.clip(image.astype(np.float32) * scale, 0, 255).astype(np.uint8)
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    else:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(image)


# EXIF's sub-directory of picture-taking facts, and its 35 mm-equivalent focal length in it.
_EXIF_IFD, _FOCAL_35MM = 0x8769, 0xA405


def image_focal_mm(path: Path) -> float | None:
    """The lens's focal length in 35 mm terms that a still's EXIF states (a phone's photo), or
    None: none stated, or not a file Pillow reads."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            focal = image.getexif().get_ifd(_EXIF_IFD).get(_FOCAL_35MM)
    except (OSError, UnidentifiedImageError, ValueError):
        return None
    return float(focal) if isinstance(focal, int | float) and focal > 0 else None


def prefetch(frames: Iterator[Frame], depth: int = 4) -> Iterator[Frame]:
    """Decode ahead in a thread so reading the pipe overlaps with processing."""
    queue: Queue[Frame | BaseException | None] = Queue(maxsize=depth)
    stop = threading.Event()

    def pump() -> None:
        try:
            for frame in frames:
                if stop.is_set():
                    break
                queue.put(frame)
            queue.put(None)
        except BaseException as error:  # handed to the consumer, which re-raises it
            queue.put(error)

    thread = threading.Thread(target=pump, daemon=True)
    thread.start()
    try:
        while (item := queue.get()) is not None:
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while thread.is_alive():
            with contextlib.suppress(Empty):
                queue.get_nowait()
            thread.join(timeout=0.01)
