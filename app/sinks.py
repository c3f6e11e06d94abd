"""Sinks: every output is written to a temporary file beside its place and renamed into place
only when its `with` block ends without an error, so no half-written output is ever left.

`atomic_output` is the one helper all outputs use (videos, stills, records, tables, calibration
and model files), with one file mode: what the user's umask gives a new file.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import tempfile
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from queue import Full, Queue
from types import TracebackType
from typing import Any, TextIO

import cv2
import numpy as np

from app.errors import InputError
from app.sources import Frame, ffmpeg_binary


def ensure_writable_dir(folder: Path) -> None:
    """Create `folder` if needed and check that files can be written in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(
            f"cannot create output folder {folder} ({error.strerror}); choose another with -o"
        ) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"output folder {folder} is not writable; choose another with -o")


@contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside `path` with the same suffix; rename it to `path` on success."""
    path = Path(path)
    ensure_writable_dir(path.parent)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent
        )
    except OSError as error:
        raise InputError(
            f"cannot write {path} ({error.strerror or error}); choose another place for it"
        ) from None
    os.close(fd)
    tmp = Path(tmp_name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


@dataclass(frozen=True)
class Container:
    """How roadview encodes into one output container: video codec options and audio codec."""

    video: tuple[str, ...]
    audio: str


# x264's fastest preset, as roadview writes its videos (it turns the deblocking filter off).
FAST_PRESET = "ultrafast"
_X264 = ("-c:v", "libx264", "-preset", FAST_PRESET, "-crf", "20", "-pix_fmt", "yuv420p")
# VP9 in real-time mode: about as fast as the processing; quality set by CRF alone.
_VP9 = (
    "-c:v",
    "libvpx-vp9",
    "-deadline",
    "realtime",
    "-cpu-used",
    "8",
    "-row-mt",
    "1",
    "-crf",
    "32",
    "-b:v",
    "0",
    "-pix_fmt",
    "yuv420p",
)
CONTAINERS: dict[str, Container] = {
    ".mp4": Container((*_X264, "-movflags", "+faststart"), "aac"),
    ".m4v": Container((*_X264, "-movflags", "+faststart"), "aac"),
    ".mov": Container((*_X264, "-movflags", "+faststart"), "aac"),
    ".mkv": Container(_X264, "aac"),
    ".avi": Container(_X264, "libmp3lame"),
    ".webm": Container(_VP9, "libopus"),
}


def container_for(path: Path) -> Container:
    """The encoding for an output name, or an InputError naming the containers roadview writes."""
    container = CONTAINERS.get(path.suffix.lower())
    if container is None:
        names = ", ".join(sorted(CONTAINERS))
        raise InputError(
            f"roadview cannot write a {path.suffix or 'suffix-less'} video ({path}); "
            f"name the output with one of {names}"
        )
    return container


@dataclass(frozen=True)
class AudioSpan:
    """The audio to copy into a video: `seconds` of `source`'s audio from `start_s`."""

    source: Path
    start_s: float = 0.0
    seconds: float | None = None


def i420(frame: Frame) -> Frame:
    """An RGB frame as planar 4:2:0 YUV (BT.601, video range), its odd width or height padded by
    repeating the last column or row: the (1.5 h, w) layout ffmpeg's yuv420p reads."""
    height, width = frame.shape[:2]
    if width % 2 or height % 2:
        frame = cv2.copyMakeBorder(frame, 0, height % 2, 0, width % 2, cv2.BORDER_REPLICATE)
    return np.asarray(cv2.cvtColor(frame, cv2.COLOR_RGB2YUV_I420))


class VideoWriter:
    """Encode RGB frames through an ffmpeg pipe, in the codec the output's suffix calls for.

    Frames go down the pipe as 4:2:0 YUV, the codecs' own format, converted by OpenCV (BT.601,
    video range, as ffmpeg converts RGB by default): half the bytes of RGB, and OpenCV converts
    in a fraction of the time ffmpeg takes. With `ffmpeg_converts` the frames go as RGB and
    ffmpeg converts them, as the re-framed table's copies are made (`app.reframe`): the two
    conversions differ by a grey level here and there, and that alone moves the table's rows
    (see the README), so its copies stay made one way. Odd frame sizes are padded by one pixel at
    the right or bottom (the codecs need even sizes), so coordinates stay those of the input.
    Audio is copied from `audio`, cut to its span and never used to end the video: every frame
    written is in the file.
    """

    def __init__(
        self,
        path: Path,
        size: tuple[int, int],
        fps: float,
        audio: AudioSpan | None = None,
        preset: str = FAST_PRESET,
        ffmpeg_converts: bool = False,
    ) -> None:
        self.size = size
        self._rgb = ffmpeg_converts
        container = container_for(path)
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
            "rgb24" if ffmpeg_converts else "yuv420p",
            "-s",
            f"{width}x{height}"
            if ffmpeg_converts
            else f"{width + width % 2}x{height + height % 2}",
            "-framerate",
            f"{fps:.6f}",
            "-i",
            "-",
        ]
        if audio is not None:
            if audio.start_s > 0:
                command += ["-ss", f"{audio.start_s:.6f}"]
            if audio.seconds is not None:
                command += ["-t", f"{audio.seconds:.6f}"]
            command += ["-i", str(audio.source), "-map", "0:v:0", "-map", "1:a:0?"]
            command += ["-c:a", container.audio]
        if ffmpeg_converts and (width % 2 or height % 2):
            command += ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]
        video = list(container.video)
        if "-preset" in video:
            video[video.index("-preset") + 1] = preset
        # Tagged with the matrix the frames were converted with: untagged HD video is shown as
        # BT.709 by most players (mpv, VLC, browsers), a red 601 red read so with 23 of green.
        video += ["-colorspace", "smpte170m", "-color_range", "tv"]
        command += [*video, str(path)]
        # Messages go to a file: a full stderr pipe would stall ffmpeg and then this writer.
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 (lives as long as the writer)
        self._process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=self._log)
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
                self._process.stdin.write(frame.data if self._rgb else i420(frame).data)
            except (BrokenPipeError, ValueError, OSError):
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
        code = self._process.wait()
        self._log.seek(0)
        messages = self._log.read().decode(errors="replace").strip()
        self._log.close()
        if code != 0:
            last = messages.splitlines()[-1] if messages else f"exit code {code}"
            raise InputError(f"ffmpeg could not write the video: {last}")

    def abort(self) -> None:
        """Stop encoding without finishing the file."""
        self._broken = True
        self._process.kill()
        self._process.wait()
        if self._thread.is_alive():
            with contextlib.suppress(Full):
                self._queue.put_nowait(None)
        self._log.close()


def write_image(path: Path, image: Frame) -> None:
    """Write an RGB image; the format follows the suffix."""
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise InputError(f"cannot write image {path}; use a .png or .jpg name")


class _AtomicSink:
    """Base of the sinks: the output lives at a temporary path until the block ends cleanly."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._stack = contextlib.ExitStack()
        self._tmp: Path | None = None

    def _open(self) -> Path:
        self._tmp = self._stack.enter_context(atomic_output(self.path))
        return self._tmp

    def _finish(self) -> None:
        """Complete the temporary file before it is renamed (subclasses close encoders here)."""

    def _abandon(self) -> None:
        """Stop writing after an error (subclasses kill encoders here)."""

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if exc_type is None:
            try:
                self._finish()
            except BaseException as error:
                self._stack.__exit__(type(error), error, error.__traceback__)
                raise
        else:
            self._abandon()
        self._stack.__exit__(exc_type, exc, traceback)


class VideoSink(_AtomicSink):
    """`with VideoSink(path, size, fps) as sink: sink.write(frame)`: an encoded video (codec by
    the name's suffix, `audio` copied in, x264 `preset`, RGB converted by ffmpeg if
    `ffmpeg_converts`) that appears only if the block succeeds."""

    def __init__(
        self,
        path: Path,
        size: tuple[int, int],
        fps: float,
        audio: AudioSpan | None = None,
        preset: str = FAST_PRESET,
        ffmpeg_converts: bool = False,
    ) -> None:
        super().__init__(path)
        container_for(self.path)  # an impossible container is refused before any work
        self._settings = (size, fps, audio, preset, ffmpeg_converts)
        self._writer: VideoWriter | None = None

    def __enter__(self) -> VideoSink:
        size, fps, audio, preset, ffmpeg_converts = self._settings
        self._writer = VideoWriter(self._open(), size, fps, audio, preset, ffmpeg_converts)
        return self

    def write(self, frame: Frame) -> None:
        """Append one RGB frame."""
        assert self._writer is not None, "use VideoSink in a with block"
        self._writer.write(frame)

    def _finish(self) -> None:
        if self._writer is not None:
            self._writer.close()

    def _abandon(self) -> None:
        if self._writer is not None:
            self._writer.abort()


class ImageSink(_AtomicSink):
    """`with ImageSink(path) as sink: sink.write(image)`: one still, format by suffix."""

    def __enter__(self) -> ImageSink:
        self._open()
        return self

    def write(self, image: Frame) -> None:
        """Write the RGB image."""
        assert self._tmp is not None, "use ImageSink in a with block"
        write_image(self._tmp, image)


class RecordSink(_AtomicSink):
    """`with RecordSink(path) as sink: sink.write(obj)`: JSON Lines, one compact object a line."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self._handle: TextIO | None = None

    def __enter__(self) -> RecordSink:
        self._handle = self._stack.enter_context(self._open().open("w"))
        return self

    def write(self, obj: Mapping[str, Any]) -> None:
        """Append one object as a line."""
        assert self._handle is not None, "use RecordSink in a with block"
        self._handle.write(json.dumps(obj, separators=(",", ":")))
        self._handle.write("\n")

    def _finish(self) -> None:
        if self._handle is not None:
            self._handle.flush()
