"""The report: one self-contained HTML page from a record (and its events) to look at.

Plots over time (speed, offset in the lane, curvature, distance to the vehicle ahead, vehicles
in view) are inline SVG drawn here, the event list carries a JPEG thumbnail per event as a data
URI: the page needs nothing but itself, so it can be mailed or archived as one file.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from app.errors import InputError
from app.events import (
    LANE_WIDTH_M,
    Event,
    EventConfig,
    event_from_record,
    nearest_ahead,
    seen_from_behind,
)
from app.record import read_record_lines
from app.sources import probe_video, read_frames, turned_info, within_size
from camera_cal import Calibration, Undistorter, fits, turned, undistorter_for

PLOT_W, PLOT_H = 860, 170
MARGIN_L, MARGIN_R, MARGIN_T, MARGIN_B = 58, 12, 26, 26
THUMB_W = 320


@dataclass(frozen=True)
class Series:
    """One quantity over time for a plot; NaN where it is not known."""

    key: str
    title: str
    unit: str
    values: NDArray[np.float64]
    guides: tuple[float, ...] = ()  # dashed horizontal reference lines
    step: bool = False  # a count: drawn as steps


def _number(value: Any) -> float:
    """A record's number as a float; NaN for null (or anything else)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def _ahead_distance(row: Mapping[str, Any]) -> float:
    nearest = nearest_ahead(row)
    return float(nearest["distance_m"]) if nearest is not None else math.nan


def _curvature(row: Mapping[str, Any]) -> float:
    """1/R in 1/km; 0 on a straight road (a null radius), NaN without a lane."""
    lane = row.get("lane")
    if not lane:
        return math.nan
    radius = lane.get("curvature_m")
    return 0.0 if radius is None else 1000.0 / float(radius)


def _where(rows: Sequence[Mapping[str, Any]]) -> str:
    """Where the vehicle in our lane is: 'ahead', or 'behind' in a rear camera's record (its
    `facing`; see app/events.py)."""
    return "behind" if any(seen_from_behind(r) for r in rows) else "ahead"


def record_series(rows: Sequence[Mapping[str, Any]]) -> tuple[NDArray[np.float64], list[Series]]:
    """Times and the plotted quantities of a record; a stage that did not run has no plot."""
    times = np.array([float(r["time_s"]) for r in rows])
    series: list[Series] = []
    if any("speed_kmh" in r for r in rows):
        series.append(
            Series("speed", "Speed", "km/h", np.array([_number(r.get("speed_kmh")) for r in rows]))
        )
    if any("lane" in r for r in rows):
        offsets = np.array([_number((r.get("lane") or {}).get("offset_m")) for r in rows])
        touch = (LANE_WIDTH_M - EventConfig().car_width_m) / 2  # a wheel on the line
        series.append(
            Series("offset", "Offset in lane (+ right)", "m", offsets, (-touch, 0.0, touch))
        )
        series.append(
            Series(
                "curvature",
                "Curvature (0 = straight)",
                "1/km",
                np.array([_curvature(r) for r in rows]),
            )
        )
    if any("vehicles" in r for r in rows):
        series.append(
            Series(
                "distance",
                f"Distance to the vehicle {_where(rows)}",
                "m",
                np.array([_ahead_distance(r) for r in rows]),
            )
        )
        series.append(
            Series(
                "vehicles",
                "Vehicles in view",
                "",
                np.array([float(len(r.get("vehicles") or [])) for r in rows]),
                step=True,
            )
        )
    return times, series


def _ticks(low: float, high: float, count: int = 4) -> list[float]:
    """Round tick values covering [low, high]."""
    span = max(high - low, 1e-9)
    raw = span / count
    magnitude = 10 ** math.floor(math.log10(raw))
    step = min((m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw), default=raw)
    first = math.ceil(low / step) * step
    return [first + k * step for k in range(int((high - first) / step + 1e-9) + 1)]


def svg_plot(
    times: NDArray[np.float64], series: Series, spans: Sequence[tuple[float, float]] = ()
) -> str:
    """An inline SVG line plot of one series over time; gaps where it is NaN, event spans shaded."""
    values = series.values
    known = np.isfinite(values)
    t0, t1 = float(times[0]), float(max(times[-1], times[0] + 1e-3))
    if known.any():
        low, high = float(values[known].min()), float(values[known].max())
        for guide in series.guides:
            low, high = min(low, guide), max(high, guide)
    else:
        low, high = 0.0, 1.0
    pad = max((high - low) * 0.08, 0.5 if series.step else 1e-3)
    low, high = low - pad, high + pad
    if (series.step or series.key == "speed") and not (values[known] < 0).any():
        low = max(low, 0.0)  # counts and speeds: no axis below zero
    inner_w, inner_h = PLOT_W - MARGIN_L - MARGIN_R, PLOT_H - MARGIN_T - MARGIN_B

    def x_of(t: float) -> float:
        return MARGIN_L + (t - t0) / (t1 - t0) * inner_w

    def y_of(v: float) -> float:
        return MARGIN_T + (high - v) / (high - low) * inner_h

    unit = f" ({series.unit})" if series.unit else ""
    parts = [
        f'<svg class="plot" data-series="{series.key}" xmlns="http://www.w3.org/2000/svg" '
        f'width="{PLOT_W}" height="{PLOT_H}" viewBox="0 0 {PLOT_W} {PLOT_H}" role="img" '
        f'aria-label="{html.escape(series.title)}">',
        f'<text x="{MARGIN_L}" y="16" class="title">{html.escape(series.title + unit)}</text>',
    ]
    for a, b in spans:
        parts.append(
            f'<rect class="span" x="{x_of(a):.1f}" y="{MARGIN_T}" '
            f'width="{max(x_of(b) - x_of(a), 2):.1f}" height="{inner_h}"/>'
        )
    for tick in _ticks(low, high):
        y = y_of(tick)
        parts.append(
            f'<line class="grid" x1="{MARGIN_L}" x2="{PLOT_W - MARGIN_R}" '
            f'y1="{y:.1f}" y2="{y:.1f}"/><text class="tick" x="{MARGIN_L - 6}" '
            f'y="{y + 4:.1f}" text-anchor="end">{tick:g}</text>'
        )
    for tick in _ticks(t0, t1, 8):
        x = x_of(tick)
        parts.append(
            f'<text class="tick" x="{x:.1f}" y="{PLOT_H - 8}" '
            f'text-anchor="middle">{tick:g} s</text>'
        )
    for guide in series.guides:
        y = y_of(guide)
        parts.append(
            f'<line class="guide" x1="{MARGIN_L}" x2="{PLOT_W - MARGIN_R}" '
            f'y1="{y:.1f}" y2="{y:.1f}"/>'
        )
    # One polyline per run of known values.
    edges = np.flatnonzero(np.diff(np.r_[0, known.astype(np.int8), 0]))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        ts, vs = times[start:stop], values[start:stop]
        if series.step and len(ts) > 1:
            ts = np.repeat(ts, 2)[1:]
            vs = np.repeat(vs, 2)[:-1]
        points = " ".join(
            f"{x_of(float(t)):.1f},{y_of(float(v)):.1f}" for t, v in zip(ts, vs, strict=True)
        )
        if len(ts) == 1:
            x, y = x_of(float(ts[0])), y_of(float(vs[0]))
            parts.append(f'<circle class="dot" cx="{x:.1f}" cy="{y:.1f}" r="2"/>')
        else:
            parts.append(f'<polyline class="line" points="{points}"/>')
    if not known.any():
        parts.append(
            f'<text class="none" x="{PLOT_W / 2}" y="{PLOT_H / 2}" text-anchor="middle">'
            "not measured</text>"
        )
    parts.append("</svg>")
    return "".join(parts)


def thumbnail_uri(frame: NDArray[np.uint8], box: Sequence[float] | None = None) -> str:
    """A small JPEG of an RGB frame as a data URI, with `box` (frame pixels) outlined."""
    scale = THUMB_W / frame.shape[1]
    small = cv2.resize(frame, (THUMB_W, max(round(frame.shape[0] * scale), 1)), cv2.INTER_AREA)
    if box is not None:
        x1, y1, x2, y2 = (round(float(v) * scale) for v in box)
        cv2.rectangle(small, (x1, y1), (x2, y2), (255, 40, 40), 2, cv2.LINE_AA)
    ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR))
    assert ok
    return "data:image/jpeg;base64," + base64.b64encode(jpeg.tobytes()).decode("ascii")


def _stat(values: NDArray[np.float64], what: str, unit: str, digits: int = 0) -> str:
    known = values[np.isfinite(values)]
    if not len(known):
        return f"<li>{what}: not measured</li>"
    return (
        f"<li>{what}: median {np.median(known):.{digits}f} {unit}, "
        f"{np.min(known):.{digits}f}-{np.max(known):.{digits}f} {unit}</li>"
    )


def _vehicles_fact(rows: Sequence[Mapping[str, Any]], in_view: NDArray[np.float64]) -> str:
    """How many vehicles were tracked (their ids: a vehicle keeps one while in view, and when
    found again where it could be) and the most in view at once (`in_view`, the plotted
    count of each frame)."""
    ids = {int(v["id"]) for r in rows for v in r.get("vehicles") or [] if int(v.get("id", -1)) > 0}
    most = int(np.max(in_view, initial=0))
    return (
        f"<li>{len(ids)} vehicle{'' if len(ids) == 1 else 's'} tracked, "
        f"up to {most} in view at once</li>"
    )


STYLE = """
body { font: 15px/1.4 system-ui, sans-serif; margin: 24px auto; max-width: 900px; color: #222; }
h1 { font-size: 22px; } h2 { font-size: 18px; margin-top: 28px; }
svg.plot { display: block; margin: 8px 0; background: #fafafa; border: 1px solid #ddd; }
svg .title { font-size: 13px; font-weight: 600; fill: #333; }
svg .tick { font-size: 11px; fill: #666; }
svg .grid { stroke: #e4e4e4; } svg .guide { stroke: #c33; stroke-dasharray: 4 3; }
svg .line { fill: none; stroke: #1f5fbf; stroke-width: 1.6; } svg .dot { fill: #1f5fbf; }
svg .span { fill: #f3c0c0; opacity: 0.6; } svg .none { fill: #999; font-size: 13px; }
table { border-collapse: collapse; width: 100%; }
td, th { border-bottom: 1px solid #ddd; padding: 6px; text-align: left; vertical-align: top; }
img.thumb { width: 320px; display: block; } td:first-child { width: 330px; }
.muted { color: #777; }
"""

# Once loaded, the page notes what it rendered (plots with a drawn line, thumbnails decoded) on
# its root element, and marks a thumbnail that did not decode; a browser test reads these.
CHECK_SCRIPT = """
window.addEventListener("load", () => {
  const drawn = [...document.querySelectorAll("svg.plot")].filter((svg) =>
    [...svg.querySelectorAll(".line, .dot")].some((e) => e.getBBox().width > 0));
  const images = [...document.querySelectorAll("img.thumb")];
  images.filter((i) => !i.naturalWidth).forEach((i) => i.replaceWith("thumbnail missing"));
  const root = document.documentElement.dataset;
  root.plotsDrawn = drawn.length;
  root.thumbnailsShown = images.filter((i) => i.naturalWidth > 0).length;
});
"""


def report_html(
    title: str,
    rows: Sequence[Mapping[str, Any]],
    events: Sequence[Event],
    thumbnails: Mapping[int, str],
    events_source: str,
) -> str:
    """The whole page. `thumbnails` maps an event's index in `events` to its image's data URI."""
    times, series = record_series(rows)
    spans = [(e.start_s, e.end_s) for e in events]
    size = rows[0].get("size", ["?", "?"])
    facts = [
        f"<li>{len(rows)} frames, {times[0]:.2f}-{times[-1]:.2f} s, {size[0]}x{size[1]} px</li>"
    ]
    by_key = {s.key: s for s in series}
    if "speed" in by_key:
        facts.append(_stat(by_key["speed"].values, "Speed", "km/h"))
    if "offset" in by_key:
        lane = np.isfinite(by_key["offset"].values)
        facts.append(f"<li>Lane found in {100 * lane.mean():.0f} % of frames</li>")
    if "vehicles" in by_key:
        facts.append(_vehicles_fact(rows, by_key["vehicles"].values))
    if "distance" in by_key:
        facts.append(_stat(by_key["distance"].values, f"Vehicle {_where(rows)}", "m", 1))
    facts.append(f"<li>{len(events)} events ({html.escape(events_source)})</li>")
    event_rows = []
    for k, event in enumerate(events):
        picture = (
            f'<img class="thumb" alt="frame {event.start_frame}" src="{thumbnails[k]}">'
            if k in thumbnails
            else '<span class="muted">no video given (--video)</span>'
        )
        who = f"vehicle {event.vehicle_id}" if event.vehicle_id is not None else ""
        event_rows.append(
            f'<tr class="event" data-kind="{event.kind}"><td>{picture}</td>'
            f"<td><b>{html.escape(event.title)}</b><br>{event.start_s:.2f}-{event.end_s:.2f} s "
            f"({event.end_s - event.start_s:.1f} s), frames {event.start_frame}-"
            f"{event.end_frame}<br>{who}<br>{event.worst_text}</td></tr>"
        )
    events_html = (
        f"<table>{''.join(event_rows)}</table>"
        if event_rows
        else '<p class="muted">No events: the car kept its lane and its distance.</p>'
    )
    plots = "".join(svg_plot(times, s, spans) for s in series)
    return (
        "<!DOCTYPE html>\n"
        f'<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1><ul>{''.join(facts)}</ul>"
        f'<h2>Over time</h2><p class="muted">Shaded: events.</p>{plots}'
        f"<h2>Events</h2>{events_html}"
        f"<script>{CHECK_SCRIPT}</script></body></html>\n"
    )


def read_events(path: Path) -> list[Event]:
    """The events of an `--events` file, with a clear error on a malformed line."""
    events = []
    for number, obj in read_record_lines(path, "events file", "--events"):
        try:
            events.append(event_from_record(obj))
        except (KeyError, TypeError, ValueError):
            raise InputError(
                f"{path}:{number} is not an event; pass a file written by 'roadview process "
                "--events'"
            ) from None
    return sorted(events, key=lambda e: (e.start_s, e.kind))


def _record_rotation(row: Mapping[str, Any]) -> int:
    """The quarter turn clockwise that stood a record's picture upright (0: none)."""
    turn = row.get("rotate_deg", 0)
    return int(turn) if turn in (90, 180, 270) else 0


def _record_roll(row: Mapping[str, Any]) -> float:
    """The turn a record's frame was levelled by (0: none)."""
    turn = row.get("roll_deg", 0.0)
    return float(turn) if isinstance(turn, int | float) else 0.0


def event_thumbnails(
    video: Path,
    rows: Sequence[Mapping[str, Any]],
    events: Sequence[Event],
    calibration: Calibration | None,
    roll_deg: float | None = None,
) -> dict[int, str]:
    """A thumbnail per event: the video's frame in the middle of the event, turned upright as
    the record says `process` turned it (`--rotate`), undistorted (not where the record's lens
    is known by its focal length) and levelled by `roll_deg`, or by the record's turn at that
    frame, as `process` did, with the involved vehicle's box from the record."""
    rotate = _record_rotation(rows[0])
    info = turned_info(probe_video(video), rotate)
    if calibration is not None and rotate:
        calibration = turned(calibration, rotate)
    size = tuple(rows[0].get("size", info.size))
    reduced = within_size(info, min(size))
    if tuple(info.size) != size and tuple(reduced.size) == size:
        info = reduced  # processed reduced (`process --max-size`)
    if tuple(info.size) != size:
        raise InputError(
            f"--video {video} is {info.size[0]}x{info.size[1]} but the record's frames are "
            f"{size[0]}x{size[1]}; pass the video the record was made from"
        )
    # A lens known by its focal length (stated to `process`, as the record says, or tagged in
    # the video, a phone's) is another camera's: `process` left the calibration out
    # (`app.drivers.calibration_for`).
    fitting = calibration is not None and fits(calibration, info.size)
    known = info.focal_mm is not None or any("focal_mm" in r for r in rows)
    lens = calibration if fitting and not known else None
    by_frame = {int(r["frame"]): r for r in rows}
    undistorters: dict[float, Undistorter | None] = {}  # one per turn levelled by
    thumbnails = {}
    for k, event in enumerate(events):
        index = (event.start_frame + event.end_frame) // 2
        frame = next(read_frames(video, info, index, index + 1), None)
        if frame is None:
            raise InputError(
                f"--video {video} has no frame {index} (the event at {event.start_s:.2f} s); "
                "pass the video the record was made from"
            )
        turn = roll_deg if roll_deg is not None else _record_roll(by_frame.get(index, {}))
        if turn not in undistorters:
            undistorters[turn] = undistorter_for(lens, info.size, turn)
        if (undistort := undistorters[turn]) is not None:
            frame = undistort(frame)
        box = next(
            (
                v["box"]
                for v in by_frame.get(index, {}).get("vehicles") or []
                if v.get("id") == event.vehicle_id
            ),
            None,
        )
        thumbnails[k] = thumbnail_uri(frame, box)
    return thumbnails
