"""Annotators: small objects that draw one kind of result onto the scene, composable in a list.

Each has `annotate(scene, result) -> scene` and draws on (and returns) the scene it is given, as
`supervision`'s annotators do; `compose` copies the frame and applies a list of them. The debug
pictures reuse them.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from app.events import Event
from app.pipeline import FrameResult
from lanes.finder import LaneEstimate, LaneResult
from vehicles.detections import Detections

Frame = NDArray[np.uint8]
LANE_FILL = (0, 200, 90)
LANE_EDGE = (255, 230, 0)
BOX = (255, 60, 60)
TEXT = (255, 255, 255)
PANEL = (20, 20, 20)
BANNER = (220, 30, 30)


def _scale(frame: Frame) -> float:
    """Drawing scale: 1.0 at 720 rows, so text stays readable from 540 to 1080 rows."""
    return float(frame.shape[0]) / 720.0


def draw_lane(frame: Frame, lane: LaneEstimate, alpha: float) -> None:
    """A translucent filled lane between the boundaries, and the boundaries themselves."""
    s = _scale(frame)
    polygon = np.vstack([lane.left, lane.right[::-1]]).round().astype(np.int32)
    x, y, w, h = cv2.boundingRect(polygon)
    x, y = max(x, 0), max(y, 0)
    w, h = min(w, frame.shape[1] - x), min(h, frame.shape[0] - y)
    if w <= 0 or h <= 0:
        return
    roi = frame[y : y + h, x : x + w]
    overlay = roi.copy()
    cv2.fillPoly(overlay, [polygon - [x, y]], LANE_FILL, lineType=cv2.LINE_AA)
    cv2.addWeighted(overlay, alpha, roi, 1 - alpha, 0, dst=roi)
    for line in (lane.left, lane.right):
        cv2.polylines(
            frame,
            [line.round().astype(np.int32)],
            False,
            LANE_EDGE,
            max(2, round(5 * s)),
            cv2.LINE_AA,
        )


def _label(frame: Frame, text: str, x: int, y: int, color: tuple[int, int, int]) -> None:
    s = _scale(frame)
    font, size, thick = cv2.FONT_HERSHEY_SIMPLEX, 0.55 * s, max(1, round(1.5 * s))
    (tw, th), base = cv2.getTextSize(text, font, size, thick)
    y = max(y, th + base + 2)
    cv2.rectangle(frame, (x, y - th - base - 4), (x + tw + 6, y), color, -1)
    cv2.putText(frame, text, (x + 3, y - base - 1), font, size, TEXT, thick, cv2.LINE_AA)


def draw_boxes(
    frame: Frame,
    detections: Detections,
    color: tuple[int, int, int] = BOX,
    distances: dict[int, float] | None = None,
) -> None:
    """Each box with its id (when it has one), and its distance in metres or its score."""
    s = _scale(frame)
    distances = distances or {}
    for box, score, track_id in zip(
        detections.boxes, detections.scores, detections.ids, strict=True
    ):
        x1, y1, x2, y2 = (round(float(v)) for v in box)
        cv2.rectangle(frame, (x1, y1), (x2, y2), color, max(2, round(3 * s)), cv2.LINE_AA)
        what = f"{distances[track_id]:.0f} m" if track_id in distances else f"{score:.2f}"
        text = f"#{track_id} {what}" if track_id >= 0 else what
        _label(frame, text, x1, y1, color)


def offset_words(offset_m: float) -> str:
    """The camera's place in its lane as the panel says it: metres left or right of centre."""
    return f"{abs(offset_m):.2f} m {'right' if offset_m > 0 else 'left'} of centre"


def hud_lines(
    lane: LaneEstimate | None, vehicles: int | None, fps: float, speed_kmh: float | None = None
) -> list[str]:
    """The text of the heads-up panel."""
    lines = [f"Speed: {speed_kmh:.0f} km/h"] if speed_kmh is not None else []
    if lane is None:
        lines.append("Lane: searching")
    else:
        radius = "straight" if math.isinf(lane.curvature_m) else f"{lane.curvature_m:,.0f} m"
        lines.append(f"Radius of curvature: {radius}")
        lines.append(f"Offset: {offset_words(lane.offset_m)}")
    if vehicles is not None:
        lines.append(f"Vehicles in view: {vehicles}")
    if fps > 0:
        lines.append(f"Processing: {fps:.1f} fps")
    return lines


def _text_block(
    frame: Frame,
    lines: list[str],
    color: tuple[int, int, int],
    keep: float,
    size: float,
    line_px: int,
    centred: bool,
) -> None:
    """White lines of text on a translucent block (`keep` of the scene shows through) at the top
    left, or the top centre; sizes in pixels at 720 rows."""
    if not lines:
        return
    s = _scale(frame)
    font, size, thick = cv2.FONT_HERSHEY_SIMPLEX, size * s, max(1, round(2 * s))
    line_h, pad = round(line_px * s), round(16 * s)
    width = max(cv2.getTextSize(t, font, size, thick)[0][0] for t in lines) + 2 * pad
    x0 = max((frame.shape[1] - width) // 2, 0) if centred else 0
    roi = frame[: line_h * len(lines) + pad, x0 : x0 + width]
    cv2.addWeighted(roi, keep, np.full_like(roi, color), 1 - keep, 0, dst=roi)
    for i, text in enumerate(lines):
        origin = (x0 + pad, round((i + 1) * line_h))
        cv2.putText(frame, text, origin, font, size, TEXT, thick, cv2.LINE_AA)


def draw_panel(frame: Frame, lines: list[str]) -> None:
    """A dark translucent panel at the top left with one line of text per item."""
    _text_block(frame, lines, PANEL, keep=0.4, size=0.8, line_px=34, centred=False)


def draw_banner(frame: Frame, lines: list[str]) -> None:
    """A red banner across the top centre with one line per event under way."""
    _text_block(frame, lines, BANNER, keep=0.25, size=0.9, line_px=38, centred=True)


def banner_lines(events: Sequence[Event]) -> list[str]:
    """The banner's text: each event under way in capitals, with its vehicle's id."""
    return [
        e.title.upper() + (f"  #{e.vehicle_id}" if e.vehicle_id is not None else "") for e in events
    ]


def draw_insets(frame: Frame, insets: list[NDArray[np.uint8]]) -> None:
    """Small pictures (RGB or grey) along the top right edge."""
    w = frame.shape[1]
    inset_w = w // 5
    x = w - 10
    for picture in insets:
        if picture.ndim == 2:
            picture = np.asarray(cv2.cvtColor(picture, cv2.COLOR_GRAY2RGB))
        inset_h = round(picture.shape[0] * inset_w / picture.shape[1])
        small = cv2.resize(picture, (inset_w, inset_h), interpolation=cv2.INTER_AREA)
        x -= inset_w
        frame[10 : 10 + inset_h, x : x + inset_w] = small
        cv2.rectangle(frame, (x, 10), (x + inset_w - 1, 10 + inset_h - 1), TEXT, 1)
        x -= 10


def lane_inset(result: LaneResult) -> NDArray[np.uint8] | None:
    """Bird's-eye mask with the pixels of each line and the fits."""
    if result.debug is None:
        return None
    d = result.debug
    picture = np.dstack([d.mask * 90] * 3).astype(np.uint8)
    for pixels, color in ((d.left_pixels, (255, 80, 80)), (d.right_pixels, (80, 80, 255))):
        picture[pixels.y.astype(int), pixels.x.astype(int)] = color
    if result.lane is not None:
        ys = np.arange(picture.shape[0], dtype=np.float64)
        for fit in (result.lane.left_fit, result.lane.right_fit):
            pts = np.stack([np.polyval(fit, ys), ys], axis=1).round().astype(np.int32)
            cv2.polylines(picture, [pts], False, (255, 255, 0), 3)
    return picture


def heat_picture(heat: NDArray[np.float32], threshold: float) -> NDArray[np.uint8]:
    """A heat map as a colour picture; the threshold maps to the middle of the scale."""
    scaled = np.clip(heat / max(2 * threshold, 1e-6) * 255, 0, 255).astype(np.uint8)
    return np.asarray(
        cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO), cv2.COLOR_BGR2RGB)
    )


class Annotator(Protocol):
    """Draws one kind of result onto the scene."""

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw onto `scene` (in place) and return it."""
        ...


@dataclass(frozen=True)
class LaneAnnotator:
    """The ego lane: a translucent area between its boundaries, and the boundaries."""

    alpha: float = 0.3

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw the lane when there is one."""
        if result.lane is not None and result.lane.lane is not None:
            draw_lane(scene, result.lane.lane, self.alpha)
        return scene


@dataclass(frozen=True)
class BoxAnnotator:
    """Each shown vehicle's box with its id and score."""

    color: tuple[int, int, int] = BOX

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw the vehicles' boxes."""
        if result.vehicles is not None:
            facts = result.facts.vehicles if result.facts is not None else ()
            distances = {f.id: f.distance_m for f in facts}
            draw_boxes(scene, result.vehicles.detections, self.color, distances)
        return scene


class PanelAnnotator:
    """The heads-up panel: curvature, offset, vehicles in view, and the processing rate.

    The rate is measured here, over the last `window` frames annotated (a still shows none).
    """

    def __init__(self, window: int = 25) -> None:
        self._times: deque[float] = deque(maxlen=window)

    @property
    def fps(self) -> float:
        """Frames annotated per second over the recent window."""
        if len(self._times) < 2:
            return 0.0
        return (len(self._times) - 1) / max(self._times[-1] - self._times[0], 1e-9)

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw the panel for the stages that ran."""
        self._times.append(time.perf_counter())
        lane = result.lane.lane if result.lane is not None else None
        count = len(result.vehicles.detections) if result.vehicles is not None else None
        if result.lane is not None or count is not None:
            speed = result.facts.speed_kmh if result.facts is not None else None
            lines = hud_lines(lane, count, self.fps, speed)
        else:
            lines = [f"Processing: {self.fps:.1f} fps"] if self.fps > 0 else []
        draw_panel(scene, lines)
        return scene


@dataclass(frozen=True)
class BannerAnnotator:
    """A banner while a driving event (lane departure, close following, ...) is under way."""

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw the banner when an event is under way."""
        draw_banner(scene, banner_lines(result.events))
        return scene


@dataclass(frozen=True)
class InsetAnnotator:
    """The bird's-eye lane fit and the vehicle heat history, small at the top right."""

    def annotate(self, scene: Frame, result: FrameResult) -> Frame:
        """Draw the insets of the stages that kept their intermediates."""
        pictures = []
        if result.lane is not None and (p := lane_inset(result.lane)) is not None:
            pictures.append(p)
        if result.vehicles is not None and (d := result.vehicles.debug) is not None:
            pictures.append(heat_picture(d.history_heat, d.heat_threshold))
        draw_insets(scene, pictures)
        return scene


def default_annotators(insets: bool = False) -> list[Annotator]:
    """What `process` and `batch` draw: lane, boxes, panel, event banner (and insets)."""
    chain: list[Annotator] = [LaneAnnotator(), BoxAnnotator(), PanelAnnotator(), BannerAnnotator()]
    if insets:
        chain.append(InsetAnnotator())
    return chain


def compose(frame: Frame, result: FrameResult, annotators: Sequence[Annotator]) -> Frame:
    """A copy of the frame with every annotator applied in turn (the input is not modified)."""
    scene = frame.copy()
    for annotator in annotators:
        scene = annotator.annotate(scene, result)
    return scene
