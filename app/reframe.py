"""Re-framed copies of a labelled clip, to measure roadview on cameras it was not tuned on.

A framing crops the picture, pads it with black and resizes it: the horizon moves, the field of
view narrows, the aspect ratio or the size changes, black bars appear. The same affine change is
applied to the labels (boxes and lane points), so the scores of a re-framed clip are comparable
with the original's.
"""

from __future__ import annotations

import copy
import json
import subprocess
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from app.assembly import build_stages
from app.drivers import process_video
from app.evaluate import FrameLabels, evaluate, load_labels_document
from app.mounting import Mounting
from app.record import read_record
from app.sinks import VideoSink
from app.sources import FOCAL_LENGTH_KEY, Frame, ffmpeg_binary, probe_video, read_frames
from camera_cal import Calibration, undistorter_for
from camera_cal.undistort import equivalent_focal_mm, output_camera_matrix
from vehicles.augment import greyed
from vehicles.detections import iou_matrix
from vehicles.model import VehicleModel

Box = tuple[int, int, int, int]
_OTHER_SIDE = {"left": "right", "right": "left"}

# A re-framed copy should differ from the clip by its framing alone. x264's default preset keeps
# the deblocking filter on; the "ultrafast" one that `process` writes with turns it off, and the
# 8 px block edges it leaves on smooth surfaces (a barrier, a bridge's shade) read as a car's edges
# to the HOG features: precision at 1920x1080 0.775 with it, 1.000 without (README).
FAITHFUL = "medium"


@dataclass(frozen=True)
class Framing:
    """Crop `crop` (x0, y0, x1, y1 of the source; None: all), pad `pad` black pixels (left, top,
    right, bottom), then resize to `size` (None: as it is); `rate` frames out per frame in, at
    `rate` times the frame rate (2: each frame twice, as a camera twice as fast sees a scene
    moving half as far a frame; 0.5: every other frame); `mirror`: then flip it left to right
    (a road where traffic keeps right, seen as one where it keeps left); `keep_left`: roadview
    is told so (`--traffic left`); `light`: every pixel value times this (0.4: dusk, the
    asphalt at about 30 grey levels); `roll`: last, the picture turned this many degrees
    anticlockwise about its centre, as by a camera mounted askew; `roll_stated`: the turn
    roadview is told (`--roll`; None: it reads one off the vehicles' rear edges or the lane
    lines, as by default,
    and levels the frames by it from then on): each frame's labels are turned by what is left
    of the turn in roadview's output (none where it was told the copy's); `reverse`: the
    frames played backwards, the road moving away as a rear camera films it (with `mirror`, its
    sides swapped too, as a rear camera's lens sees them; without, as its file saved mirrored
    shows them); `facing`: what roadview is told of that (`--facing`); `focal_mm`: the copy
    tagged with its lens's focal length in 35 mm terms, as a phone tags its videos; `bow`:
    after the light, the picture seen through a wider lens's barrel distortion (`bowed`), its
    corners kept where they are (not with `roll`); `grey`: after the light, its colour taken
    out, as an infrared night camera or a grey-only export shows it."""

    name: str
    crop: Box | None = None
    pad: Box = (0, 0, 0, 0)
    size: tuple[int, int] | None = None
    rate: float = 1.0
    mirror: bool = False
    keep_left: bool = False
    light: float = 1.0
    roll: float = 0.0
    roll_stated: float | None = None
    reverse: bool = False
    facing: str = "auto"
    focal_mm: float | None = None
    bow: float = 0.0
    grey: bool = False

    @property
    def unchanged(self) -> bool:
        """Whether the clip stays as it is (no crop, pad, resize or other frame rate)."""
        return (
            self.crop is None
            and not any(self.pad)
            and self.size is None
            and self.rate == 1
            and not self.mirror
            and self.light == 1
            and self.roll == 0
            and not self.reverse
            and self.bow == 0
            and not self.grey
        )

    def source_frame(self, frame: int, source_frames: int) -> int:
        """The index of the source frame that the re-framed copy of a clip of `source_frames`
        shows as its `frame`."""
        shown = int(np.floor(frame / self.rate + 1e-9))
        return source_frames - 1 - shown if self.reverse else shown

    def frame_count(self, source_frames: int) -> int:
        """How many frames the re-framed copy of a clip of `source_frames` has."""
        return int(np.floor(source_frames * self.rate + 1e-9))

    def padded_size(self, source: tuple[int, int]) -> tuple[int, int]:
        """(width, height) after the crop and the padding, before the resize."""
        x0, y0, x1, y1 = self.crop or (0, 0, *source)
        left, top, right, bottom = self.pad
        return x1 - x0 + left + right, y1 - y0 + top + bottom

    def output_size(self, source: tuple[int, int]) -> tuple[int, int]:
        """(width, height) of the re-framed picture of a `source`-sized one."""
        return self.size or self.padded_size(source)

    def affine(self, source: tuple[int, int]) -> tuple[float, float, float, float]:
        """(sx, sy, dx, dy): a source point (x, y) lands at (x sx + dx, y sy + dy), in pixel-edge
        coordinates (a mirrored picture's sx is negative: its boxes' sides trade places)."""
        x0, y0, _, _ = self.crop or (0, 0, *source)
        pw, ph = self.padded_size(source)
        ow, oh = self.output_size(source)
        sx, sy = ow / pw, oh / ph
        dx, dy = (self.pad[0] - x0) * sx, (self.pad[1] - y0) * sy
        if self.mirror:
            return -sx, sy, ow - dx, dy
        return sx, sy, dx, dy

    def move_boxes(
        self, boxes: NDArray[np.float64], source: tuple[int, int]
    ) -> NDArray[np.float64]:
        """Boxes (x0, y0, x1, y1) of the source picture where the re-framed picture shows them."""
        sx, sy, dx, dy = self.affine(source)
        moved = boxes * np.array([sx, sy, sx, sy]) + np.array([dx, dy, dx, dy])
        return np.asarray(moved[:, [2, 1, 0, 3]] if self.mirror else moved, np.float64)

    def unmove_boxes(
        self, boxes: NDArray[np.float64], source: tuple[int, int]
    ) -> NDArray[np.float64]:
        """Boxes of the re-framed picture where the source picture shows them."""
        sx, sy, dx, dy = self.affine(source)
        back = (boxes - np.array([dx, dy, dx, dy])) / np.array([sx, sy, sx, sy])
        return np.asarray(back[:, [2, 1, 0, 3]] if self.mirror else back, np.float64)


def standard_framings(source: tuple[int, int]) -> tuple[Framing, ...]:
    """The framings of issue #15 for a `source`-sized clip: as it is, horizon 10 % of the height
    higher (crop the top) and lower (pad the top, crop the bottom), a narrower field of view (the
    middle 80 % enlarged back), a 4:3 crop, a 21:9 crop (an ultra-wide dashcam's picture: the
    top and bottom cut, the bonnet and the nearest road with them), black side bars, two other
    sizes and half the size (many phones' and dashcams' small copies), half and twice the frame
    rate, mirrored (traffic keeping left, as in the UK, India or Japan), turned 3 degrees
    (a camera mounted askew, levelled by `--roll`), and cut off-centre by a tenth of the width
    on either side (as a camera turned 3 degrees sideways sees the road: the picture's middle
    64 px off the road's vanishing point at 1280 px) and by a twentieth (turned 1.5 degrees:
    32 px, less than the 3 % of the width the lane stage's view is placed in steps of)."""
    w, h = source
    cut = round(0.1 * h)
    side = round((w - h * 4 / 3) / 2)
    narrow = (round(0.1 * w), round(0.1 * h), w - round(0.1 * w), h - round(0.1 * h))
    wide = round(w * 9 / 21)
    tenth, twentieth = round(0.1 * w), round(0.05 * w)
    return (
        Framing("as is"),
        Framing("horizon up", crop=(0, cut, w, h)),
        Framing("horizon down", crop=(0, 0, w, h - cut), pad=(0, cut, 0, 0)),
        Framing("narrower view", crop=narrow, size=(w, h)),
        Framing("4:3 crop", crop=(side, 0, w - side, h)),
        Framing("21:9 crop", crop=(0, (h - wide) // 2, w, (h - wide) // 2 + wide)),
        Framing("side bars", crop=(side, 0, w - side, h), pad=(side, 0, side, 0)),
        Framing("960x540", size=(round(w * 0.75), round(h * 0.75))),
        Framing("1920x1080", size=(round(w * 1.5), round(h * 1.5))),
        Framing("640x360", size=(round(w * 0.5), round(h * 0.5))),
        Framing("half frame rate", rate=0.5),
        Framing("twice the frame rate", rate=2.0),
        Framing("mirrored", mirror=True),
        Framing("mirrored, --traffic left", mirror=True, keep_left=True),
        Framing("turned 3°, --roll 3", roll=3.0, roll_stated=3.0),
        Framing("cut off-centre (as turned 3° right)", crop=(tenth, 0, w, h)),
        Framing("cut off-centre (as turned 3° left)", crop=(0, 0, w - tenth, h)),
        Framing("cut a little off-centre (as turned 1.5° right)", crop=(twentieth, 0, w, h)),
        Framing("cut a little off-centre (as turned 1.5° left)", crop=(0, 0, w - twentieth, h)),
    )


def upright_framing(source: tuple[int, int]) -> Framing:
    """A phone held upright (a rotation-tagged video, decoded portrait) on a `source`-sized
    landscape clip: the same lens turned a quarter turn sees the middle columns, as many as the
    picture is tall, with as much again above and below (black here: no picture is there)."""
    w, h = source
    side = (w - h) // 2
    return Framing("phone held upright", crop=(side, 0, side + h, h), pad=(0, side, 0, side))


def tagged_lens_framing(source: tuple[int, int], calibration: Calibration) -> Framing:
    """The narrower view of a `source`-sized clip undistorted with `calibration` (its middle
    80 % enlarged back: a lens 1.25 times longer) tagged with that lens's focal length, as a
    phone tags its videos: read from the tag, its distances are the clip's own."""
    narrow = next(f for f in standard_framings(source) if f.name == "narrower view")
    focal = 1.25 * output_camera_matrix(calibration, source)[1, 1]
    return replace(
        narrow,
        name="narrower view, its lens tagged",
        focal_mm=round(equivalent_focal_mm(float(focal), source), 2),
    )


def dusk_framings(source: tuple[int, int]) -> tuple[Framing, ...]:
    """Dusk on a `source`-sized clip: 0.4 of its light as it is, and so at half the size with
    black side bars (the issue's dusk freeway at 640x360, where no lane was found)."""
    w, h = source
    side = round((w - h * 4 / 3) / 2)
    return (
        Framing("dusk (0.4 of the light)", light=0.4),
        Framing(
            "dusk, half size, side bars",
            crop=(side, 0, w - side, h),
            pad=(side, 0, side, 0),
            size=(round(w * 0.5), round(h * 0.5)),
            light=0.4,
        ),
    )


# A camera mounted askew that roadview is not told of: turned 3 degrees either way, the turn read
# off the vehicles' rear edges or the lane lines and levelled from then on, and the same told
# `--roll 0` (as roadview was before it read the turn).
UNTOLD_ROLL_FRAMINGS = (
    Framing("turned 3°, read", roll=3.0),
    Framing("turned 3°, --roll 0", roll=3.0, roll_stated=0.0),
    Framing("turned -3°, read", roll=-3.0),
    Framing("turned -3°, --roll 0", roll=-3.0, roll_stated=0.0),
)


# A rear camera on a clip: played backwards and mirrored (the road moving away, its sides swapped
# as a camera looking back sees them), read by roadview unaided and told `--facing rear`; and a
# rear camera's file saved mirrored (as a rear-view mirror shows the road: played backwards
# alone), unaided and told `--facing rear-mirrored`.
REAR_FRAMINGS = (
    Framing("rear camera (played backwards, mirrored)", reverse=True, mirror=True),
    Framing("rear camera, --facing rear", reverse=True, mirror=True, facing="rear"),
    Framing("rear camera saved mirrored (played backwards)", reverse=True),
    Framing(
        "rear camera saved mirrored, --facing rear-mirrored", reverse=True, facing="rear-mirrored"
    ),
)


# A wider lens than the tuned camera's, untold: its barrel distortion (`Framing.bow`) bends
# straight lines off the picture's centre about 2.3 times as much as the shipped lens does at
# the corners (the middle enlarged 1.3 times against the corners, the shipped lens 1.1 times).
WIDE_LENS_FRAMING = Framing("a wider lens's distortion", bow=0.3)

# An infrared night camera's picture (or a grey-only export): the clips without their colour.
MONOCHROME_FRAMING = Framing("monochrome (no colour)", grey=True)


def bowed_source(
    x: NDArray[np.floating[Any]], y: NDArray[np.floating[Any]], size: tuple[int, int], bow: float
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Where a picture of `size` seen through a lens of barrel distortion `bow` shows the
    undistorted picture's point at pixel (x, y) of the distorted one: at rho (the distance from
    the centre in half-diagonals) it shows the point at rho (1 + bow rho^2) / (1 + bow), so the
    middle is enlarged 1 + bow times, the corners stay, and straight lines off the centre bow
    outwards (0.3: a 16:9 picture's straight line along its top edge sags by about 4 % of the
    height in its middle)."""
    cx, cy = (size[0] - 1) / 2, (size[1] - 1) / 2
    half = np.hypot(size[0] / 2, size[1] / 2)
    gain = (1 + bow * ((x - cx) ** 2 + (y - cy) ** 2) / half**2) / (1 + bow)
    return (cx + (x - cx) * gain).astype(np.float32), (cy + (y - cy) * gain).astype(np.float32)


def bowed(
    x: NDArray[np.floating[Any]], y: NDArray[np.floating[Any]], size: tuple[int, int], bow: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Where the picture seen through the lens of `bowed_source` shows the undistorted point
    (x, y): its inverse, by Newton's method on rho (1 + bow rho^2) = (1 + bow) rho_source."""
    cx, cy = (size[0] - 1) / 2, (size[1] - 1) / 2
    half = np.hypot(size[0] / 2, size[1] / 2)
    source = np.hypot(x - cx, y - cy) / half
    rho = source.astype(np.float64)
    for _ in range(20):
        rho = rho - (rho * (1 + bow * rho**2) - (1 + bow) * source) / (1 + 3 * bow * rho**2)
    gain = np.divide(rho, source, out=np.full_like(rho, 1 / (1 + bow)), where=source > 0)
    return cx + (x - cx) * gain, cy + (y - cy) * gain


def reframe_image(frame: Frame, framing: Framing) -> Frame:
    """The re-framed picture."""
    h, w = frame.shape[:2]
    x0, y0, x1, y1 = framing.crop or (0, 0, w, h)
    out = frame[y0:y1, x0:x1]
    if any(framing.pad):
        left, top, right, bottom = framing.pad
        out = cv2.copyMakeBorder(out, top, bottom, left, right, cv2.BORDER_CONSTANT, value=0)
    if framing.size is not None and framing.size != (out.shape[1], out.shape[0]):
        shrink = framing.size[0] < out.shape[1]
        interpolation = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
        out = cv2.resize(out, framing.size, interpolation=interpolation)
    if framing.mirror:
        out = out[:, ::-1]
    if framing.light != 1:
        out = cv2.convertScaleAbs(out, alpha=framing.light)
    if framing.grey:
        out = greyed(out)
    if framing.bow:
        h, w = out.shape[:2]
        columns, rows = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        xs, ys = bowed_source(columns, rows, (w, h), framing.bow)
        out = cv2.remap(out, xs, ys, cv2.INTER_LINEAR)
    if framing.roll:
        h, w = out.shape[:2]
        turn = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), framing.roll, 1.0)
        out = cv2.warpAffine(out, turn, (w, h), flags=cv2.INTER_LINEAR)
    return np.ascontiguousarray(out)


def reframe_labels(
    document: dict[str, Any], framing: Framing, source: tuple[int, int]
) -> dict[str, Any]:
    """A labels document (the format of ../shared/data/README.md) moved with the picture:
    boxes are clipped to what is still shown; a vehicle less than half shown is ignored, one
    not shown at all dropped; lane points of rows no longer shown are dropped."""
    sx, sy, dx, dy = framing.affine(source)
    ow, oh = framing.output_size(source)
    # What of the picture is real: not a black bar.
    left, top, right, bottom = framing.pad
    pw, ph = framing.padded_size(source)
    if framing.mirror:
        left, right = right, left
    shown = (left * abs(sx), top * sy, (pw - right) * abs(sx), (ph - bottom) * sy)
    out = copy.deepcopy(document)
    out["clip"] = f"{document.get('clip', 'clip')} ({framing.name})"
    for frame in out.get("keyframes", {}).values():
        vehicles = []
        for vehicle in frame.get("vehicles", []):
            box = framing.move_boxes(np.array([vehicle["box"]], np.float64), source)[0].tolist()
            if framing.bow:  # the box around its outline as the lens bows it
                x0, y0, x1, y1 = box
                t = np.linspace(0.0, 1.0, 17)
                xs = np.concatenate([x0 + (x1 - x0) * t, x0 + (x1 - x0) * t, [x0] * 17, [x1] * 17])
                ys = np.concatenate([[y0] * 17, [y1] * 17, y0 + (y1 - y0) * t, y0 + (y1 - y0) * t])
                bx, by = bowed(xs, ys, (ow, oh), framing.bow)
                box = [float(bx.min()), float(by.min()), float(bx.max()), float(by.max())]
            clipped = [
                max(box[0], shown[0]),
                max(box[1], shown[1]),
                min(box[2], shown[2]),
                min(box[3], shown[3]),
            ]
            if clipped[2] <= clipped[0] or clipped[3] <= clipped[1]:
                continue
            area = (box[2] - box[0]) * (box[3] - box[1])
            kept = (clipped[2] - clipped[0]) * (clipped[3] - clipped[1])
            vehicle["box"] = [round(c, 1) for c in clipped]
            vehicle["ignore"] = bool(vehicle.get("ignore", False)) or kept < 0.5 * area
            vehicles.append(vehicle)
        frame["vehicles"] = vehicles
        lane = frame.get("lane") or {}
        # Points are pixel centres, half a pixel inside the edge coordinates the map is in.
        for side, points in list(lane.items()):
            moved = {}
            for row, x in (points or {}).items():
                y, nx = float(row) * sy + dy, (float(x) + 0.5) * sx + dx - 0.5
                if framing.bow:
                    bx, by = bowed(np.array([nx]), np.array([y]), (ow, oh), framing.bow)
                    nx, y = float(bx[0]), float(by[0])
                if shown[1] <= y < shown[3] and 0 <= y < oh and 0 <= nx < ow:
                    moved[str(round(y))] = round(nx, 1)
            lane[side] = moved
        if framing.mirror and lane:
            frame["lane"] = {_OTHER_SIDE.get(side, side): points for side, points in lane.items()}
    return out


def write_reframed(
    video: Path,
    framing: Framing,
    output: Path,
    calibration: Calibration | None,
    preset: str = FAITHFUL,
) -> tuple[int, int]:
    """`video` undistorted with `calibration` (the labels' frame) and re-framed, encoded to
    `output` with the x264 `preset`; its size."""
    info = probe_video(video)
    undistort = undistorter_for(calibration, info.size)
    size = framing.output_size(info.size)
    frames: Iterable[Frame] = read_frames(video, info)
    count = info.n_frames
    if framing.reverse:  # played backwards: the labelled clips are seconds long
        held = list(frames)
        frames, count = reversed(held), len(held)
    # ffmpeg converts the copies' RGB, as it did when the table was first measured: the table
    # is one draw of the encoder, and a conversion a grey level apart is another (README).
    with VideoSink(
        output, size, info.fps * framing.rate, preset=preset, ffmpeg_converts=True
    ) as sink:
        shown = 0  # frames written so far
        for played, frame in enumerate(frames):
            index = count - 1 - played if framing.reverse else played
            if framing.source_frame(shown, count) != index:
                continue  # dropped at a lower frame rate
            picture = reframe_image(undistort(frame) if undistort else frame, framing)
            while framing.source_frame(shown, count) == index:
                sink.write(picture)
                shown += 1
    if framing.focal_mm is not None:
        tag_focal_length(output, framing.focal_mm)
    return size


def tag_focal_length(video: Path, focal_mm: float) -> None:
    """Tag the MP4 or MOV `video` in place with its lens's focal length in 35 mm terms, as a
    phone does (the streams copied as they are)."""
    tagged = video.with_name(f".tagged{video.suffix}")
    command = [
        ffmpeg_binary(), "-nostdin", "-loglevel", "error", "-y", "-i", str(video), "-map", "0",
        "-c", "copy", "-movflags", "use_metadata_tags", "-metadata",
        f"{FOCAL_LENGTH_KEY}={focal_mm:g}", str(tagged),
    ]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True)
    tagged.replace(video)


def turned_labels(
    labels: Mapping[int, FrameLabels],
    turns: Mapping[int, float],
    size: tuple[int, int],
    centre: tuple[float, float] | None = None,
) -> dict[int, FrameLabels]:
    """Per-frame labels of a picture of `size` with frame k turned `turns[k]` degrees
    anticlockwise about `centre` (None: the picture's, as `reframe_image` turns it): each box
    becomes the bounds of its turned corners less half their growth (a car is no rectangle),
    each lane side is read off its turned points at its rows."""
    w, h = size
    about = centre if centre is not None else ((w - 1) / 2, (h - 1) / 2)
    out = {}
    for k, frame in labels.items():
        turn = turns.get(k, 0.0)
        if not turn:
            out[k] = frame
            continue
        matrix = cv2.getRotationMatrix2D(about, turn, 1.0)
        vehicles = []
        for vehicle in frame.vehicles:
            x0, y0, x1, y1 = vehicle.box
            corners = np.array([[x0, y0, 1], [x1, y0, 1], [x0, y1, 1], [x1, y1, 1]]) @ matrix.T
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            gx, gy = ((hi[0] - lo[0]) - (x1 - x0)) / 4, ((hi[1] - lo[1]) - (y1 - y0)) / 4
            box = (
                float(max(lo[0] + gx, 0.0)),
                float(max(lo[1] + gy, 0.0)),
                float(min(hi[0] - gx, w)),
                float(min(hi[1] - gy, h)),
            )
            vehicles.append(replace(vehicle, box=box))
        lane: dict[str, dict[int, float]] = {}
        for side, points in frame.lane.items():
            if len(points) < 2:
                lane[side] = {}
                continue
            rows = np.array(sorted(points), np.float64)
            xs = np.array([points[int(r)] for r in rows])
            moved = np.column_stack([xs, rows, np.ones(len(rows))]) @ matrix.T
            order = np.argsort(moved[:, 1])
            ys, mx = moved[order, 1], moved[order, 0]
            lane[side] = {int(r): float(np.interp(r, ys, mx)) for r in rows if ys[0] <= r <= ys[-1]}
        out[k] = FrameLabels(tuple(vehicles), lane)
    return out


def retime_labels(
    labels: Mapping[int, FrameLabels], framing: Framing, source_frames: int
) -> dict[int, FrameLabels]:
    """Per-frame labels (of `load_labels`) of the re-framed copy's frames: each shows the labels
    of the source frame it shows."""
    count = framing.frame_count(source_frames)
    frames = (framing.source_frame(j, source_frames) for j in range(count))
    return {j: labels[i] for j, i in enumerate(frames) if i in labels}


def framing_scores(
    video: Path,
    labels: Path,
    framing: Framing,
    folder: Path,
    calibration: Calibration | None,
    classifier: VehicleModel | None = None,
    preset: str = FAITHFUL,
) -> dict[str, Any]:
    """Scores of roadview (without calibration, as on an unknown camera) on the re-framed clip
    (encoded with the x264 `preset`) against the labels moved the same way."""
    info = probe_video(video)
    clip = folder / f"{video.stem}.mp4"
    write_reframed(video, framing, clip, calibration, preset)
    document = reframe_labels(json.loads(labels.read_text()), framing, info.size)
    record = folder / f"{video.stem}.jsonl"
    lanes, vehicles = build_stages(classifier=classifier)
    process_video(
        clip,
        None,
        None,
        lanes,
        vehicles,
        record=record,
        vehicles_in_worker=False,
        mounting=Mounting(
            keep_left=framing.keep_left,
            roll_deg=framing.roll_stated,
            facing=framing.facing,
        ),
    )
    truth = retime_labels(load_labels_document(document), framing, info.n_frames)
    frames = list(read_record(record))
    if framing.roll:  # each frame as turned as roadview left it
        left = {int(f["frame"]): framing.roll - float(f.get("roll_deg", 0.0)) for f in frames}
        truth = turned_labels(truth, left, framing.output_size(info.size))
    # The warm-up is the labels' 10 frames of the clip as it is, whatever the frame rate.
    return {**evaluate(truth, frames, warmup=round(10 * framing.rate)), "frames": frames}


def distance_ratios(
    reference: Sequence[Mapping[str, Any]],
    frames: Sequence[Mapping[str, Any]],
    framing: Framing,
    source: tuple[int, int],
    min_iou: float = 0.5,
) -> NDArray[np.float64]:
    """Per vehicle and frame, its distance in the re-framed clip's record `frames` over the
    same vehicle's in the `reference` record of the clip as it is (boxes matched at `min_iou`
    once moved back to the source picture): 1 where the geometry holds under the re-framing."""
    by_frame = {int(r["frame"]): r for r in reference}
    ratios: list[float] = []
    for record in frames:
        shown = framing.source_frame(int(record["frame"]), len(reference))
        seen = list(by_frame.get(shown, {}).get("vehicles", []))
        framed = [v for v in record.get("vehicles", []) if v.get("distance_m")]
        if not seen or not framed:
            continue
        a = framing.unmove_boxes(np.array([v["box"] for v in framed], np.float64), source)
        b = np.array([v["box"] for v in seen], np.float64)
        overlap = iou_matrix(a, b)
        for i, j in enumerate(overlap.argmax(axis=1)):
            if overlap[i, j] >= min_iou and seen[j].get("distance_m"):
                ratios.append(framed[i]["distance_m"] / seen[j]["distance_m"])
    return np.asarray(ratios, np.float64)


def _at_source(
    reference: Sequence[Mapping[str, Any]],
    frames: Sequence[Mapping[str, Any]],
    framing: Framing,
    value: Callable[[Mapping[str, Any]], float | None],
) -> list[tuple[float, float]]:
    """(re-framed, as it is) pairs of `value` of each frame of the re-framed clip's record
    `frames` and of the `reference` record's frame at the source frame it shows, where both
    have one."""
    seen = {int(r["frame"]): value(r) for r in reference}
    pairs = []
    for record in frames:
        before = seen.get(framing.source_frame(int(record["frame"]), len(reference)))
        after = value(record)
        if before is not None and after is not None:
            pairs.append((after, before))
    return pairs


def speed_ratios(
    reference: Sequence[Mapping[str, Any]], frames: Sequence[Mapping[str, Any]], framing: Framing
) -> NDArray[np.float64]:
    """Per frame, the speed in the re-framed clip's record `frames` over the speed in the
    `reference` record of the clip as it is at the source frame it shows: 1 where the road's
    scale and the frame rate are read right."""
    pairs = _at_source(reference, frames, framing, lambda r: r.get("speed_kmh") or None)
    return np.asarray([after / before for after, before in pairs], np.float64)


def offset_shifts(
    reference: Sequence[Mapping[str, Any]], frames: Sequence[Mapping[str, Any]], framing: Framing
) -> NDArray[np.float64]:
    """Per frame with a lane in both, the lane offset in the re-framed clip's record `frames`
    less the offset in the `reference` record of the clip as it is at the source frame it shows
    (negated where mirrored: the camera is as far the other way): 0 where the camera's place
    in its lane is read right; none for a clip played backwards (its lane is seen from
    behind)."""
    if framing.reverse:
        return np.zeros(0, np.float64)
    sign = -1.0 if framing.mirror else 1.0
    pairs = _at_source(reference, frames, framing, lambda r: (r.get("lane") or {}).get("offset_m"))
    return np.asarray([after - sign * before for after, before in pairs], np.float64)


def pooled(scores: Iterable[Mapping[str, Any]], threshold: str = "iou_0.5") -> dict[str, float]:
    """Vehicle precision, recall and mean IoU pooled over clips, and the lane's share within
    20 px, from `evaluate` results."""
    tp = fp = fn = 0
    iou_sum = points = within = 0.0
    for s in scores:
        v = s["vehicles"][threshold]
        tp, fp, fn = tp + v["true_positives"], fp + v["false_positives"], fn + v["false_negatives"]
        iou_sum += v["mean_iou"] * v["true_positives"]
        lane = s["lane"]
        points += lane["points"]
        within += (lane["share_within_20px"] or 0.0) * lane["points"]
    return {
        "precision": tp / (tp + fp) if tp + fp else 1.0,
        "recall": tp / (tp + fn) if tp + fn else 1.0,
        "mean_iou": iou_sum / tp if tp else 0.0,
        "lane_within_20px": within / points if points else 0.0,
        "true_positives": tp,
        "false_positives": fp,
        "false_negatives": fn,
    }


def framing_table(
    clips: Sequence[tuple[Path, Path]],
    calibration: Calibration | None,
    framings: Sequence[Framing] | None = None,
    classifier: VehicleModel | None = None,
    preset: str = FAITHFUL,
) -> dict[str, dict[str, float]]:
    """Pooled scores per framing over `clips` ((video, labels) pairs of one size): the table
    that shows whether roadview holds on footage framed unlike the clips it was tuned on. With
    "as is" first, each other framing also gets the median ratio of its vehicles' distances to
    the same vehicles' as they are, and of its speed to the speed at the same moment as it is,
    and the median shift of its lane offset (`offset_shifts`). Copies are encoded with the x264
    `preset`."""
    source = probe_video(clips[0][0]).size
    table: dict[str, dict[str, float]] = {}
    plain: list[Sequence[Mapping[str, Any]]] = []
    for framing in framings or standard_framings(source):
        with tempfile.TemporaryDirectory() as tmp:
            scores = [
                framing_scores(video, labels, framing, Path(tmp), calibration, classifier, preset)
                for video, labels in clips
            ]
        table[framing.name] = pooled(scores)
        if framing.unchanged:
            plain = [s["frames"] for s in scores]
        elif plain:
            pairs = list(zip(plain, scores, strict=True))
            distances = np.concatenate(
                [distance_ratios(ref, s["frames"], framing, source) for ref, s in pairs]
            )
            speeds = np.concatenate([speed_ratios(ref, s["frames"], framing) for ref, s in pairs])
            # How far the distances and the speed moved with the framing (1 = not at all): the
            # median ratios.
            for key, ratios in (("distance_ratio", distances), ("speed_ratio", speeds)):
                table[framing.name][key] = float(np.median(ratios)) if len(ratios) else float("nan")
            # ... and the lane offset (0 = not at all): the median shift, in metres.
            shifts = np.concatenate([offset_shifts(ref, s["frames"], framing) for ref, s in pairs])
            table[framing.name]["offset_shift_m"] = (
                float(np.median(shifts)) if len(shifts) else float("nan")
            )
    return table
