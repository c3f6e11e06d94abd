"""Driving events from the per-frame facts: lane departure, lane change, close following and
closing fast, with hysteresis so that they do not flicker. Seen by a rear camera, the vehicle
in our lane is the one behind: following closely and closing fast are then its, and the
picture's sides are the car's swapped (unless its file is saved mirrored).

The detector reads plain numbers per frame (`FrameSignals`), so it runs the same beside the
pipeline (for the video's banner and `--events`) and over a saved record (`roadview report`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

LANE_WIDTH_M = 3.7  # when the lane's own width is not known: the usual width

KIND_TITLES = {
    "lane_departure": "lane departure",
    "lane_change_left": "lane change left",
    "lane_change_right": "lane change right",
    "close_following": "close following",
    "closing_fast": "closing fast",
    "followed_closely": "followed closely",
    "closing_fast_behind": "closing fast from behind",
}
# What each kind is when a rear camera sees it: the vehicle in our lane follows us ...
REAR_KINDS = {"close_following": "followed_closely", "closing_fast": "closing_fast_behind"}
# ... and, in its file as its lens sees the road (not saved mirrored), the picture's left is
# the car's right.
SWAPPED_SIDES = {"lane_change_left": "lane_change_right", "lane_change_right": "lane_change_left"}


@dataclass(frozen=True)
class EventConfig:
    """Thresholds of the events and how long a condition must hold to start or end one."""

    car_width_m: float = 1.8  # a wheel is over a boundary when |offset| > (lane - car) / 2
    departure_hold_s: float = 0.3  # wheel over for this long: a departure
    settle_margin_m: float = 0.15  # back inside by this much ...
    settle_s: float = 0.5  # ... for this long ends a departure or a change
    change_jump_m: float = 1.2  # the offset jumping across the centre: we are in the next lane
    lane_lost_s: float = 2.0  # no lane for this long ends an excursion where it was last seen
    headway_s: float = 1.0  # close following: headway under this ...
    headway_exit_s: float = 1.2  # ... (ends at or above this) ...
    following_hold_s: float = 2.0  # ... for over this long
    ttc_s: float = 3.0  # closing fast: time to collision under this ...
    ttc_exit_s: float = 4.0  # ... (ends at or above this) ...
    closing_hold_s: float = 0.3  # ... for this long
    release_s: float = 0.5  # a value missing or outside for this long ends an episode


@dataclass(frozen=True)
class FrameSignals:
    """What the events are made of, for one frame."""

    frame: int
    time_s: float
    offset_m: float | None = None  # camera minus lane centre; None without a lane
    lane_width_m: float | None = None
    headway_s: float | None = None
    ttc_s: float | None = None
    ahead_id: int | None = None  # the vehicle ahead in our lane
    rear: bool = False  # seen by a rear camera: that vehicle is behind us
    mirrored: bool = False  # ... whose file is saved mirrored: the picture's sides are the car's


@dataclass(frozen=True)
class Event:
    """One event: kind, when (inclusive frames and times), the vehicle involved, and its worst
    value (the least headway or time to collision in seconds, the largest |offset| in metres)."""

    kind: str
    start_frame: int
    end_frame: int
    start_s: float
    end_s: float
    vehicle_id: int | None = None
    worst: float | None = None

    @property
    def title(self) -> str:
        """The kind in words, e.g. 'close following'."""
        return KIND_TITLES[self.kind]

    @property
    def worst_text(self) -> str:
        """The worst value with its unit ('worst 0.70 s'), or '' without one."""
        if self.worst is None:
            return ""
        unit = "m" if self.kind.startswith("lane") else "s"
        return f"worst {self.worst:.2f} {unit}"

    def describe(self) -> str:
        """One short line for the closing summary."""
        who = f", vehicle {self.vehicle_id}" if self.vehicle_id is not None else ""
        worst = f", {self.worst_text}" if self.worst is not None else ""
        return f"{self.title} {self.start_s:.2f}-{self.end_s:.2f} s{who}{worst}"


def event_record(event: Event) -> dict[str, Any]:
    """An event as one object of the `--events` JSON-lines file."""
    return {
        "kind": event.kind,
        "start_s": round(event.start_s, 3),
        "end_s": round(event.end_s, 3),
        "start_frame": event.start_frame,
        "end_frame": event.end_frame,
        "vehicle_id": event.vehicle_id,
        "worst": round(event.worst, 3) if event.worst is not None else None,
    }


def event_from_record(obj: Mapping[str, Any]) -> Event:
    """The inverse of `event_record` (KeyError or TypeError on a malformed object)."""
    if obj["kind"] not in KIND_TITLES:
        raise KeyError(obj["kind"])
    return Event(
        str(obj["kind"]),
        int(obj["start_frame"]),
        int(obj["end_frame"]),
        float(obj["start_s"]),
        float(obj["end_s"]),
        None if obj.get("vehicle_id") is None else int(obj["vehicle_id"]),
        None if obj.get("worst") is None else float(obj["worst"]),
    )


class _Below:
    """History of one 'value under a threshold' event: it starts when the value drops under
    `enter`, runs while it stays under `leave` (gaps up to `release_s`), and counts once it has
    run for `hold_s`. A new vehicle ends the episode and may start another."""

    def __init__(self, kind: str, enter: float, leave: float, hold_s: float, release_s: float):
        self.kind, self.enter, self.leave = kind, enter, leave
        self.hold_s, self.release_s = hold_s, release_s
        self._episode: Event | None = None  # start, last frame inside, vehicle, worst so far

    def reset(self) -> None:
        """Forget any episode under way."""
        self._episode = None

    @property
    def active(self) -> Event | None:
        """The event under way, once it counts."""
        e = self._episode
        return e if e is not None and e.end_s - e.start_s >= self.hold_s else None

    def update(self, s: FrameSignals, value: float | None) -> Event | None:
        """Feed one frame; returns an event that ended before this frame."""
        ended = None
        e = self._episode
        if e is not None:
            inside = value is not None and value < self.leave and s.ahead_id == e.vehicle_id
            if inside:
                assert value is not None and e.worst is not None
                self._episode = replace(
                    e, end_frame=s.frame, end_s=s.time_s, worst=min(e.worst, value)
                )
                return None
            if s.time_s - e.end_s < self.release_s and (
                value is None or s.ahead_id == e.vehicle_id
            ):
                return None  # a short gap: the episode goes on
            ended, self._episode = self.active, None
        if value is not None and value < self.enter:
            self._episode = Event(
                self.kind, s.frame, s.frame, s.time_s, s.time_s, s.ahead_id, value
            )
        return ended

    def finish(self) -> Event | None:
        """End of the footage: the event under way, if it counts."""
        ended, self._episode = self.active, None
        return ended


class _Excursion:
    """History of a wheel over a lane boundary: a departure when it comes back into the same
    lane, a change when the lane finder's offset jumps across (it now sees the next lane)."""

    def __init__(self, config: EventConfig) -> None:
        self.config = config
        self._start: FrameSignals | None = None
        self._last: FrameSignals | None = None  # the last frame with a lane
        self._came_back: FrameSignals | None = None  # first frame of the current run inside
        self._side = 0.0  # +1 over the right boundary, -1 over the left
        self._changed = False
        self._worst = 0.0

    def reset(self) -> None:
        """Forget any excursion under way."""
        self._start = self._last = self._came_back = None
        self._changed = False

    def _limit(self, s: FrameSignals) -> float:
        """The |offset| at which a wheel touches a boundary (lane widths kept to 2.5-5 m)."""
        width = s.lane_width_m
        if width is None or not math.isfinite(width):
            width = LANE_WIDTH_M
        return (min(max(width, 2.5), 5.0) - self.config.car_width_m) / 2

    def _event(self, end: FrameSignals) -> Event | None:
        start = self._start
        assert start is not None
        counts = self._changed or end.time_s - start.time_s >= self.config.departure_hold_s
        if not counts:
            return None
        kind = "lane_departure"
        if self._changed:
            kind = "lane_change_right" if self._side > 0 else "lane_change_left"
        worst = round(float(self._worst), 3)
        return Event(kind, start.frame, end.frame, start.time_s, end.time_s, None, worst)

    @property
    def active(self) -> Event | None:
        """The excursion under way, once it counts."""
        if self._start is None or self._last is None:
            return None
        return self._event(self._last)

    def update(self, s: FrameSignals) -> Event | None:
        """Feed one frame; returns an excursion that ended."""
        cfg = self.config
        if self._start is None:
            if s.offset_m is not None and abs(s.offset_m) > self._limit(s):
                self._start = self._last = s
                self._side = math.copysign(1.0, s.offset_m)
                self._changed, self._came_back, self._worst = False, None, abs(s.offset_m)
            return None
        assert self._last is not None
        if s.offset_m is None:
            if s.time_s - self._last.time_s >= cfg.lane_lost_s:
                ended = self._event(self._last)
                self.reset()
                return ended
            return None
        previous = self._last.offset_m
        assert previous is not None
        # Jumping across the centre is a change; jumping back undoes it (the finder had locked
        # on a wrong line for a moment: we never left the lane).
        if abs(s.offset_m - previous) >= cfg.change_jump_m and math.copysign(
            1.0, s.offset_m
        ) != math.copysign(1.0, previous):
            self._changed = math.copysign(1.0, s.offset_m) != self._side
        self._last = s
        if abs(s.offset_m) < self._limit(s) - cfg.settle_margin_m:
            if self._came_back is None:
                self._came_back = s
            if s.time_s - self._came_back.time_s >= cfg.settle_s:
                ended = self._event(self._came_back)
                self.reset()
                return ended
        else:
            self._came_back = None
            if not self._changed:
                self._worst = max(self._worst, abs(s.offset_m))
        return None

    def finish(self) -> Event | None:
        """End of the footage: the excursion under way, if it counts."""
        ended = self._event(self._last) if self._start is not None and self._last else None
        self.reset()
        return ended


class EventDetector:
    """History for the events: one small state machine per kind. Feed it every frame with
    `update`; `active` is what is under way (for a banner); `finish` ends the footage."""

    def __init__(self, config: EventConfig | None = None) -> None:
        self.config = config if config is not None else EventConfig()
        cfg = self.config
        self._excursion = _Excursion(cfg)
        self._following = _Below(
            "close_following", cfg.headway_s, cfg.headway_exit_s, cfg.following_hold_s,
            cfg.release_s,
        )  # fmt: skip
        self._closing = _Below(
            "closing_fast", cfg.ttc_s, cfg.ttc_exit_s, cfg.closing_hold_s, cfg.release_s
        )
        self.events: list[Event] = []  # every event that ended, in the order they ended
        self._kinds: dict[str, str] = {}  # kinds as the last frame's camera sees them

    def reset(self) -> None:
        """Forget everything: a new clip."""
        self._excursion.reset()
        self._following.reset()
        self._closing.reset()
        self.events.clear()
        self._kinds = {}

    def _seen(self, event: Event) -> Event:
        """The event as the camera's facing makes it (see `REAR_KINDS`, `SWAPPED_SIDES`)."""
        kind = self._kinds.get(event.kind, event.kind)
        return replace(event, kind=kind) if kind != event.kind else event

    def update(self, s: FrameSignals) -> tuple[Event, ...]:
        """Feed one frame; returns the events under way at it."""
        self._kinds = {**REAR_KINDS, **({} if s.mirrored else SWAPPED_SIDES)} if s.rear else {}
        for ended in (
            self._excursion.update(s),
            self._following.update(s, s.headway_s),
            self._closing.update(s, s.ttc_s),
        ):
            if ended is not None:
                self.events.append(self._seen(ended))
        return self.active

    @property
    def active(self) -> tuple[Event, ...]:
        """The events under way (each once it counts)."""
        found = (self._excursion.active, self._following.active, self._closing.active)
        return tuple(self._seen(e) for e in found if e is not None)

    def close(self) -> None:
        """End what is under way (the footage cut to another shot); the events found stay."""
        for ended in (self._excursion.finish(), self._following.finish(), self._closing.finish()):
            if ended is not None:
                self.events.append(self._seen(ended))

    def finish(self) -> list[Event]:
        """End the footage: close what is under way; every event, by start time."""
        self.close()
        return sorted(self.events, key=lambda e: (e.start_s, e.kind))


def find_events(signals: Iterable[FrameSignals], config: EventConfig | None = None) -> list[Event]:
    """Every event of a whole series of frames."""
    detector = EventDetector(config)
    for s in signals:
        detector.update(s)
    return detector.finish()


def nearest_ahead(row: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The nearest vehicle in our lane of a record line (one with a known distance), or None."""
    ahead = [
        v
        for v in row.get("vehicles") or []
        if v.get("lane") == "ego"
        and isinstance(v.get("distance_m"), int | float)
        and math.isfinite(v["distance_m"])
    ]
    return min(ahead, key=lambda v: float(v["distance_m"]), default=None)


def seen_from_behind(row: Mapping[str, Any]) -> bool:
    """Whether a record line is a rear camera's (its `facing`, either kind of file)."""
    return row.get("facing") in ("rear", "rear-mirrored")


def signals_from_record(row: Mapping[str, Any]) -> FrameSignals:
    """A record line's signals (see app/record.py): the lane's offset and width, the headway and
    time to collision, the nearest vehicle in our lane, and whether a rear camera saw it."""
    lane = row.get("lane") or {}
    nearest = nearest_ahead(row)
    return FrameSignals(
        int(row["frame"]),
        float(row["time_s"]),
        lane.get("offset_m"),
        lane.get("width_m"),
        row.get("headway_s"),
        row.get("ttc_s"),
        int(nearest["id"]) if nearest is not None else None,
        seen_from_behind(row),
        row.get("facing") == "rear-mirrored",
    )
