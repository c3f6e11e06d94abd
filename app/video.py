"""Video and still-image input/output through ffmpeg pipes (the binary moviepy uses)."""

from __future__ import annotations

import contextlib
import subprocess
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from queue import Full, Queue
from typing import IO

import cv2
import numpy as np
from numpy.typing import NDArray

from app.errors import InputError

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})
Frame = NDArray[np.uint8]  # H x W x 3, RGB


def ffmpeg_binary() -> str:
    """Path of the ffmpeg executable that moviepy is configured with."""
    from moviepy.config import FFMPEG_BINARY

    return str(FFMPEG_BINARY)


@dataclass(frozen=True)
class VideoInfo:
    """What a video file holds, read from its container."""

    size: tuple[int, int]  # (width, height)
    fps: float
    n_frames: int
    duration: float
    has_audio: bool


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


def probe_video(path: Path) -> VideoInfo:
    """Size, frame rate, frame count and audio presence of a video, or a clear InputError."""
    check_input(path)
    from moviepy.video.io.ffmpeg_reader import ffmpeg_parse_infos

    try:
        infos = ffmpeg_parse_infos(str(path))
    except (OSError, IndexError, KeyError, ValueError):
        infos = {}
    if not infos.get("video_found"):
        raise InputError(f"{path} is not a video ffmpeg can read; pass an .mp4/.avi/.mov file")
    fps = float(infos.get("video_fps") or 0.0)
    size = infos.get("video_size") or [0, 0]
    n_frames = int(infos.get("video_n_frames") or 0)
    if fps <= 0 or size[0] <= 0 or n_frames <= 0:
        raise InputError(f"{path} has no video frames; the file may be truncated or empty")
    return VideoInfo(
        size=(int(size[0]), int(size[1])),
        fps=fps,
        n_frames=n_frames,
        duration=float(infos.get("video_duration") or infos.get("duration") or 0.0),
        has_audio=bool(infos.get("audio_found")),
    )


def read_frames(
    path: Path, info: VideoInfo, start_frame: int = 0, end_frame: int | None = None
) -> Iterator[Frame]:
    """Decoded RGB frames in order, from `start_frame` up to (not including) `end_frame`."""
    width, height = info.size
    command = [ffmpeg_binary(), "-nostdin", "-loglevel", "error"]
    if start_frame > 0:
        command += ["-ss", f"{start_frame / info.fps:.6f}"]
    command += [
        "-i",
        str(path),
        "-map",
        "0:v:0",
        "-fps_mode",
        "passthrough",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-",
    ]
    frame_bytes = width * height * 3
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=frame_bytes * 2
    )
    assert process.stdout is not None
    index = start_frame
    try:
        while end_frame is None or index < end_frame:
            data = _read_exactly(process.stdout, frame_bytes)
            if data is None:
                break
            yield np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3)
            index += 1
    finally:
        process.kill()
        process.wait()
        if process.stderr is not None:
            process.stderr.close()
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


class VideoWriter:
    """Encode RGB frames to H.264 through an ffmpeg pipe, copying audio from a source if asked."""

    def __init__(
        self,
        path: Path,
        size: tuple[int, int],
        fps: float,
        audio_from: Path | None = None,
        audio_start_s: float = 0.0,
        audio_end_s: float | None = None,
        preset: str = "ultrafast",
        crf: int = 20,
    ) -> None:
        self.size = size
        width, height = size
        command = [
            ffmpeg_binary(),
            "-y",
            "-nostdin",
            "-loglevel",
            "error",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            f"{width}x{height}",
            "-framerate",
            f"{fps:.6f}",
            "-i",
            "-",
        ]
        if audio_from is not None:
            if audio_start_s > 0:
                command += ["-ss", f"{audio_start_s:.6f}"]
            if audio_end_s is not None:
                command += ["-to", f"{audio_end_s:.6f}"]
            command += [
                "-i",
                str(audio_from),
                "-map",
                "0:v:0",
                "-map",
                "1:a:0?",
                "-c:a",
                "aac",
                "-shortest",
            ]
        command += [
            "-c:v",
            "libx264",
            "-preset",
            preset,
            "-crf",
            str(crf),
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
            str(path),
        ]
        self._process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        # Frames go to ffmpeg from a thread so a full pipe never stalls the processing.
        self._queue: Queue[Frame | None] = Queue(maxsize=4)
        self._broken = False
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        assert self._process.stdin is not None
        while (frame := self._queue.get()) is not None:
            if self._broken:
                continue
            try:
                self._process.stdin.write(frame.tobytes())
            except (BrokenPipeError, ValueError):
                self._broken = True

    def write(self, frame: Frame) -> None:
        """Append one RGB frame of the writer's size."""
        if (frame.shape[1], frame.shape[0]) != self.size:
            raise ValueError(f"frame size {frame.shape[1]}x{frame.shape[0]} != {self.size}")
        if self._broken:
            self.close()  # raises with ffmpeg's message
        self._queue.put(np.ascontiguousarray(frame))

    def close(self) -> None:
        """Finish the file; raise InputError if ffmpeg failed."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        if self._process.stdin is not None and not self._process.stdin.closed:
            with contextlib.suppress(BrokenPipeError):
                self._process.stdin.close()
        stderr = (
            self._process.stderr.read().decode(errors="replace") if self._process.stderr else ""
        )
        if self._process.wait() != 0:
            last = stderr.strip().splitlines()[-1] if stderr.strip() else "unknown error"
            raise InputError(f"ffmpeg could not write the video: {last}")

    def abort(self) -> None:
        """Stop encoding without finishing the file."""
        self._broken = True
        self._process.kill()
        self._process.wait()
        if self._thread.is_alive():
            with contextlib.suppress(Full):
                self._queue.put_nowait(None)


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


def write_image(path: Path, image: Frame) -> None:
    """Write an RGB image; the format follows the suffix."""
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise InputError(f"cannot write image {path}; use a .png or .jpg name")
