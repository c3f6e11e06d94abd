"""Driving events from the per-frame facts: lane departure, lane change, close following and
closing fast, with hysteresis so that they do not flicker. Seen by a rear camera, the vehicle
in our lane is the one behind: following closely and closing fast are then its, and the
picture's sides are the car's swapped (unless its file is saved mirrored).

The detector reads plain numbers per frame (`FrameSignals`), so it runs the same beside the
pipeline (for the video's banner and `--events`) and over a saved record (`roadview report`).
"""

from __future__ import annotations

import math
from collections import deque
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
    change_lead_s: float = 3.0  # a change spans at most this long before the jump ...
    change_tail_s: float = 3.0  # ... and after it: a wheel over the line longer drives on it
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
    lane, a change when the lane finder's offset jumps across (it now sees the next lane). A
    change spans at most `change_lead_s` before the jump and `change_tail_s` after it: a car
    that keeps a wheel over the line longer drives on it, which is a departure of its own (the
    part before, or an excursion from the new lane's line after)."""

    def __init__(self, config: EventConfig) -> None:
        self.config = config
        self._start: FrameSignals | None = None
        self._last: FrameSignals | None = None  # the last frame with a lane
        self._came_back: FrameSignals | None = None  # first frame of the current run inside
        self._side = 0.0  # +1 over the right boundary, -1 over the left
        # The excursion's frames with a lane over the last change_lead_s, each with the
        # |offset| it counts to the worst (none once changed); the last frame dropped from
        # them, and the worst of those dropped: where a change before the jump may start.
        self._recent: deque[tuple[FrameSignals, float]] = deque()
        self._dropped: FrameSignals | None = None
        self._dropped_worst = 0.0
        self._jump: FrameSignals | None = None  # the change under way: the frame it jumped at
        self._change: tuple[FrameSignals, float] | None = None  # ... its first frame, worst
        self._before: Event | None = None  # ... and the departure before it, if any

    def reset(self) -> None:
        """Forget any excursion under way."""
        self._start = self._last = self._came_back = self._dropped = self._jump = None
        self._change = self._before = None
        self._recent.clear()

    def _begin(self, s: FrameSignals) -> None:
        """Start an excursion at `s`, a frame over a boundary."""
        assert s.offset_m is not None
        self.reset()
        self._start = self._last = s
        self._side = math.copysign(1.0, s.offset_m)
        self._dropped_worst = abs(s.offset_m)
        self._recent.append((s, abs(s.offset_m)))

    @property
    def _worst(self) -> float:
        """The largest |offset| of the frames over the line so far (none after a change)."""
        return max(self._dropped_worst, max((w for _, w in self._recent), default=0.0))

    def _limit(self, s: FrameSignals) -> float:
        """The |offset| at which a wheel touches a boundary (lane widths kept to 2.5-5 m)."""
        width = s.lane_width_m
        if width is None or not math.isfinite(width):
            width = LANE_WIDTH_M
        return (min(max(width, 2.5), 5.0) - self.config.car_width_m) / 2

    def _drop_before(self, time_s: float) -> None:
        """Drop the recent frames from before `time_s` (a change cannot start there)."""
        while self._recent and self._recent[0][0].time_s < time_s:
            self._dropped, worst = self._recent.popleft()
            self._dropped_worst = max(self._dropped_worst, worst)

    def _jumped(self, s: FrameSignals) -> None:
        """The offset jumped across the centre at `s`, away from the side it went over: the
        change starts `change_lead_s` before (or where the excursion did, when what is before
        that is too short to count as a departure)."""
        start = self._start
        assert start is not None
        self._jump, self._before = s, None
        self._drop_before(s.time_s - self.config.change_lead_s)
        dropped = self._dropped
        if dropped is None or dropped.time_s - start.time_s < self.config.departure_hold_s:
            self._change = (start, round(float(self._worst), 3))
            return
        first = self._recent[0][0] if self._recent else s
        worst = max((w for _, w in self._recent), default=0.0)
        self._change = (first, round(float(worst), 3))
        worst = round(float(self._dropped_worst), 3)
        self._before = Event(
            "lane_departure", start.frame, dropped.frame, start.time_s, dropped.time_s, None, worst
        )

    def _events(self, end: FrameSignals) -> tuple[Event, ...]:
        """The excursion's events, were it to end at `end`: a departure, or a change and the
        departure before it where the wheel was over the line longer than a change takes."""
        start = self._start
        assert start is not None
        if self._change is None:
            if end.time_s - start.time_s < self.config.departure_hold_s:
                return ()
            worst = round(float(self._worst), 3)
            kind = "lane_departure"
            return (Event(kind, start.frame, end.frame, start.time_s, end.time_s, None, worst),)
        first, worst = self._change
        kind = "lane_change_right" if self._side > 0 else "lane_change_left"
        change = Event(kind, first.frame, end.frame, first.time_s, end.time_s, None, worst)
        return (change,) if self._before is None else (self._before, change)

    @property
    def active(self) -> Event | None:
        """The excursion's event under way, once it counts."""
        if self._start is None or self._last is None:
            return None
        events = self._events(self._last)
        return events[-1] if events else None

    def update(self, s: FrameSignals) -> tuple[Event, ...]:
        """Feed one frame; returns the events of an excursion that ended."""
        cfg = self.config
        if self._start is None:
            if s.offset_m is not None and abs(s.offset_m) > self._limit(s):
                self._begin(s)
            return ()
        assert self._last is not None
        if s.offset_m is None:
            if s.time_s - self._last.time_s >= cfg.lane_lost_s:
                ended = self._events(self._last)
                self.reset()
                return ended
            return ()
        previous = self._last.offset_m
        assert previous is not None
        # Jumping across the centre is a change; jumping back undoes it (the finder had locked
        # on a wrong line for a moment: we never left the lane).
        if abs(s.offset_m - previous) >= cfg.change_jump_m and math.copysign(
            1.0, s.offset_m
        ) != math.copysign(1.0, previous):
            if math.copysign(1.0, s.offset_m) != self._side:
                self._jumped(s)
            else:
                self._jump = self._change = self._before = None
        inside = abs(s.offset_m) < self._limit(s) - cfg.settle_margin_m
        jump = self._jump
        if jump is not None and not inside and s.time_s - jump.time_s >= cfg.change_tail_s:
            # Changed, and still over the new lane's line: the change ends, the car is on it.
            ended = self._events(self._last)
            self.reset()
            if abs(s.offset_m) > self._limit(s):
                self._begin(s)
            return ended
        self._last = s
        counted = 0.0 if self._jump is not None or inside else abs(s.offset_m)
        self._recent.append((s, counted))
        self._drop_before(s.time_s - cfg.change_lead_s)
        if inside:
            if self._came_back is None:
                self._came_back = s
            if s.time_s - self._came_back.time_s >= cfg.settle_s:
                ended = self._events(self._came_back)
                self.reset()
                return ended
        else:
            self._came_back = None
        return ()

    def finish(self) -> tuple[Event, ...]:
        """End of the footage: the excursion under way, if it counts."""
        ended = self._events(self._last) if self._start is not None and self._last else ()
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
            *self._excursion.update(s),
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
        for ended in (*self._excursion.finish(), self._following.finish(), self._closing.finish()):
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
