"""Drivers: a video or a still from its source, through the pipeline, into its sinks.

Every output appears only when the run succeeds (the sinks write temporary files and rename them).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Generator, Sequence
from contextlib import ExitStack, closing
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from app.annotators import Annotator, compose
from app.errors import InputError
from app.events import Event, event_record
from app.mounting import (
    Mounting,
    aim_note,
    check_mounting,
    check_rotate,
    sky_where,
    upright_note,
    video_mounting,
)
from app.pipeline import Pipeline
from app.progress import Progress
from app.record import frame_record
from app.runtime import warm_up_opencv
from app.sinks import AudioSpan, ImageSink, RecordSink, VideoSink
from app.sources import (
    Frame,
    VideoInfo,
    decoding_notes,
    image_focal_mm,
    prefetch,
    probe_video,
    read_frames,
    read_image,
    turned_image,
    turned_info,
    within_size,
)
from camera_cal import (
    Calibration,
    UprightConfig,
    fits,
    frame_sky,
    frames_vote,
    monochrome,
    sky_vote,
    turned,
)
from lanes.finder import LaneFinder
from vehicles.detector import VehicleDetector


@dataclass(frozen=True)
class RunSummary:
    """What a processing run did."""

    frames: int
    seconds: float  # wall time of the run
    output: Path | None
    record: Path | None
    video_seconds: float = 0.0  # length of the video processed (0 for a still)
    events: tuple[Event, ...] = ()  # driving events found, by start time
    events_file: Path | None = None

    @property
    def fps(self) -> float:
        """End-to-end frames per second."""
        return self.frames / self.seconds if self.seconds > 0 else math.inf


def frame_range(fps: float, n_frames: int, start_s: float, end_s: float | None) -> tuple[int, int]:
    """First and one-past-last frame index for a time range in seconds."""
    if start_s < 0 or (end_s is not None and end_s <= start_s):
        raise InputError("--start must be >= 0 and --end later than --start")
    first = round(start_s * fps)
    last = n_frames if end_s is None else min(n_frames, round(end_s * fps))
    if first >= n_frames:
        raise InputError(f"--start {start_s}s is past the end of the video ({n_frames / fps:.2f}s)")
    return first, last


# How the sky's side is voted on over a video's frames (README, Which way up).
SKY = UprightConfig()


# Told when the road moves away from an unstated camera: it looks back (README, A rear camera).
REAR_NOTE = (
    "a rear camera's footage (the road moves away from it; or it plays backwards): its speed is "
    "read so, and the headway, time to collision and events are of the vehicle behind in our "
    "lane (followed closely, closing fast from behind); pass --facing rear so that the vehicle "
    "search also sees the road's sides swapped, as a camera looking back does, or --facing "
    "rear-mirrored if the file is saved mirrored, as a rear-view mirror shows the road (its "
    "writing reads backwards) (the classifier learned mostly cars' rears and finds fewer of "
    "the fronts that follow)"
)


def facing_note(stated: bool | None, seen: bool | None) -> str | None:
    """What to tell a user of the way the camera faces (True: backwards): the road moving away
    from a camera stated nowhere (`REAR_NOTE`), or moving against the way stated (its speed
    is then missing: it is read only in the stated direction); None: nothing to tell."""
    if seen is None or stated == seen or (stated is None and not seen):
        return None
    if stated is None:
        return REAR_NOTE
    if seen:
        return (
            "stated to face forwards (--facing front), but its road moves away from the camera, "
            "as a rear camera's does (or it plays backwards): its speed is missing (read only "
            "as the road moves the way stated); pass --facing rear or rear-mirrored, or leave "
            "--facing out to have it read from the road"
        )
    return (
        "stated to face backwards (--facing rear or rear-mirrored), but its road comes towards "
        "the camera, as a front camera's does: its speed is missing (read only as the road "
        "moves the way stated), and the vehicle taken as behind is ahead; pass --facing front, "
        "or leave --facing out to have it read from the road"
    )


# What read a turn, by `camera_cal.RollReading.cue`: the vehicles' rear edges, the lane lines'
# spacing, or the road's motion on either side (with one vehicle's rear edges, or alone).
TURN_CUES = {
    "leans": "the vehicles' rear edges lean so, as a camera mounted askew turns them",
    "lines": "the lane lines are spaced so, as a camera mounted askew spreads them to one side",
    "vehicle and road": (
        "a vehicle's rear edges lean so, and the road moves faster on the side turned up, as "
        "a camera mounted askew shows it"
    ),
    "road": "the road moves faster on the side turned up, as a camera mounted askew shows it",
}


def levelled_note(roll_deg: float, frame: int, fps: float, cue: str = "leans") -> str:
    """What to tell of a picture levelled by a turn that `cue` read (a key of `TURN_CUES`),
    from `frame` of a video at `fps` on."""
    way = "anticlockwise" if roll_deg > 0 else "clockwise"
    return (
        f"its picture is turned {abs(roll_deg):.1f} degrees {way} "
        f"({TURN_CUES[cue]}): levelled from {frame / fps:.1f} s on "
        f"(the output and the record with it); pass --roll {roll_deg:g} to level it from the "
        "start, or --roll 0 to leave it as it is"
    )


def roll_contradicted_note(stated_deg: float, read_deg: float) -> str:
    """What to tell where the picture still reads turned once levelled by the stated turn (its
    vehicles' rear edges, or its lane lines): the turn it reads instead, and how to state it or
    have it read."""
    return (
        f"stated --roll {stated_deg:g}, but its picture still reads turned once levelled so "
        f"(its vehicles' rear edges or lane lines): a turn of {read_deg:g} degrees; pass --roll "
        f"{read_deg:g}, or leave --roll out to have it read and levelled"
    )


# Told when a video has no colour: the vehicle classifier learned colour footage (README).
MONOCHROME_NOTE = (
    "monochrome: its vehicles are read by the models trained on grey copies of the patches, "
    "less sure than in colour (README, Monochrome footage); the lanes are unaffected"
)


def lens_note(focal_mm: float | None, tagged: bool, dropped: bool) -> str | None:
    """What to tell of a lens whose focal length is known without a calibration: from the file's
    tag (`tagged`, a phone's), and so another camera than the shipped one, whose calibration
    was left out (`dropped`); None: nothing to tell (stated, and no calibration to leave)."""
    if focal_mm is None or not (tagged or dropped):
        return None
    said = (
        f"its file gives its lens's focal length ({focal_mm:g} mm in 35 mm terms, as a phone "
        "tags it): its distances and speed follow it (--focal-length MM overrides it)"
        if tagged
        else f"a lens of {focal_mm:g} mm in 35 mm terms (--focal-length)"
    )
    if dropped:
        said += (
            "; another camera than the shipped one, so processed without its calibration (a "
            "phone corrects its lens itself; pass --calibration FILE of this camera to undistort "
            "it)"
        )
    return said


def calibration_for(
    calibration: Calibration | None,
    size: tuple[int, int],
    name: str,
    required: bool,
    log: Callable[[str], None],
    focal_mm: float | None = None,
) -> Calibration | None:
    """The calibration to undistort `name`'s frames of `size` with: `calibration` where it fits.
    Frames of another aspect ratio come from another camera: without a calibration the user
    named (`required`) they are processed without undistortion, and `log` says so; with one,
    `CalibrationMismatch` says it does not fit. Frames of another size with the aspect ratio of
    a calibration the user did not name (the shipped one; a still's any) are undistorted with it
    scaled, and `log` says so: most dashcams film 16:9, and another camera's footage needs
    `--calibration none` or its own. A lens whose `focal_mm` is known (stated, or a phone's tag)
    is another camera's: such frames are processed without a calibration the user did not name
    (`lens_note` says so)."""
    if calibration is None or required:
        return calibration
    if focal_mm is not None:
        return None
    cw, ch = calibration.image_size
    if fits(calibration, size):
        if tuple(size) != (cw, ch):
            log(
                f"note: {name} is {size[0]}x{size[1]}, undistorted with the {cw}x{ch} camera's "
                "calibration scaled to it (for footage of another camera pass "
                "--calibration none, or --calibration FILE of that camera)"
            )
        return calibration
    log(
        f"note: {name} is {size[0]}x{size[1]}, not of the calibration's aspect ratio "
        f"({cw}x{ch}): another camera, processed without undistortion (pass --calibration FILE "
        "of this camera to undistort it)"
    )
    return None


def lens_for(
    calibration: Calibration | None,
    mounting: Mounting,
    size: tuple[int, int],
    tagged_mm: float | None,
    name: str,
    required: bool,
    log: Callable[[str], None],
) -> tuple[Calibration | None, Mounting]:
    """The calibration and mounting for `name`'s frames of `size`: the lens's focal length its
    file's tag states (`tagged_mm`, a phone's) where the user stated none, the calibration that
    fits (`calibration_for`), and `log` told of a lens known without one (`lens_note`); where
    the lens is known (a calibration the user named, or a focal length), the lane dashes are
    not read for the road's length (see `camera_cal.DashScale`). A calibration turns with a
    picture the mounting turns upright."""
    if calibration is not None and mounting.rotate_deg:
        # The calibration is of the picture as stored: it turns upright with it.
        calibration = turned(calibration, mounting.rotate_deg)
    tagged = mounting.focal_mm is None and tagged_mm is not None
    if tagged:
        mounting = replace(mounting, focal_mm=tagged_mm)
    dropped = mounting.focal_mm is not None and calibration is not None and not required
    shown = name
    if mounting.rotate_deg:
        shown = f"{name} (turned {mounting.rotate_deg} degrees clockwise, the calibration with it)"
    calibration = calibration_for(calibration, size, shown, required, log, mounting.focal_mm)
    # A calibration the user named sets the lens, whatever the tag says.
    if (lens := lens_note(mounting.focal_mm, tagged and calibration is None, dropped)) is not None:
        log(f"note: {name}: {lens}")
    # A lens known, by a calibration of this camera or its focal length, gives the road's
    # lengths: the dashes are read where it is assumed (the shipped camera's).
    if mounting.focal_mm is not None or (required and calibration is not None):
        mounting = replace(mounting, dash_spacing_m=None)
    return calibration, mounting


def recorded_focal_mm(calibration: Calibration | None, mounting: Mounting) -> float | None:
    """The focal length the record states: the lens's where it, not a calibration, gives the
    distances (its frames are then not undistorted, which `report` must know)."""
    return mounting.focal_mm if calibration is None else None


def camera_for(
    calibration: Calibration | None,
    mounting: Mounting,
    info: VideoInfo,
    name: str,
    required: bool,
    log: Callable[[str], None],
) -> tuple[Calibration | None, Mounting]:
    """`lens_for` the video `info` describes, its mounting checked against it first
    (`video_mounting`)."""
    mounting = video_mounting(mounting, info)
    return lens_for(calibration, mounting, info.size, info.focal_mm, name, required, log)


# Seconds of the part before that `--after` runs first: the scene's vanishing points (60, one
# every third frame: 6-7 s), the lines' and the tracks' history (a second or two) are as they
# were at its end; what is learned over longer (the length scale read off the dashes) is not.
# It costs as much time as processing them (without drawing or encoding).
LEAD_IN_S = 10.0


@dataclass(frozen=True)
class LeadIn:
    """The end of the part of a drive before a video (`--after`): its last `frames` frames,
    from `start`, are run first and not recorded, so the stages start with its history."""

    source: Path
    info: VideoInfo
    start: int
    frames: int

    def followed_by(
        self, k: int, then: Generator[Frame, None, None]
    ) -> Generator[Frame, None, None]:
        """The lead-in's frames from its k-th, then those of `then`."""
        yield from read_frames(self.source, self.info, self.start + k)
        yield from then


def lead_in(
    after: Path,
    info: VideoInfo,
    source: Path,
    max_size: int,
    log: Callable[[str], None],
    turn_deg: int = 0,
) -> LeadIn | None:
    """The lead-in of `source` from `after`, the part of the drive before it (its last
    `LEAD_IN_S`), turned upright as `source` is (`turn_deg` clockwise), or None, said in `log`,
    where `after` cannot be read or is of another size or frame rate (not the same camera's)."""
    try:
        before = within_size(turned_info(probe_video(after), turn_deg), max_size)
    except InputError as error:
        log(f"note: {error}; it is not run first, {source.name} starts afresh")
        return None
    if before.size != info.size or abs(before.fps - info.fps) > 0.01 * info.fps:
        log(
            f"note: {after.name} ({before.size[0]}x{before.size[1]}, {before.fps:.4g} fps) is "
            f"not of the camera that filmed {source.name} ({info.size[0]}x{info.size[1]}, "
            f"{info.fps:.4g} fps): it is not run first, {source.name} starts afresh"
        )
        return None
    frames = min(before.n_frames, round(LEAD_IN_S * before.fps))
    log(
        f"note: {source.name} goes on from {after.name}: its last {frames / before.fps:.1f} s "
        "are run first, so the scene, lanes and vehicles start as they were there"
    )
    return LeadIn(after, before, before.n_frames - frames, frames)


def start_part(
    pipeline: Pipeline,
    source: Path,
    info: VideoInfo,
    first: int,
    last: int,
    lead: LeadIn | None,
) -> tuple[Callable[[int, int | None], Generator[Frame, None, None]], int]:
    """Prepare `pipeline` for `source` from frame `first`, the frames of the `lead` in, if any,
    run before it, and let it read an unknown camera's horizon ahead of each shot (up to
    `last`): the first shot's now (`Pipeline.look_ahead`, which reads as many frames as its
    stages would wait), a shot's after a cut as it comes (`Pipeline.frames_from`; a second
    decoder, for a known camera never started). Returns `frames_from(k, end)`, the frames from
    the k-th of them all on (the lead-in's first), and how many the lead-in has."""
    led = 0 if lead is None else lead.frames
    pipeline.prepare(info.size, info.fps, first - led)

    def frames_from(k: int, end: int | None) -> Generator[Frame, None, None]:
        if k >= led:
            return read_frames(source, info, first + k - led, end)
        assert lead is not None
        return lead.followed_by(k, read_frames(source, info, first, end))

    pipeline.frames_from = lambda k: frames_from(k, last)
    with closing(frames_from(0, last)) as frames:
        pipeline.look_ahead(frames)
    return frames_from, led


def within_part(events: Sequence[Event], first: int, fps: float) -> tuple[Event, ...]:
    """The `events` as they show in the part that starts at frame `first`: those that ended in
    the lead-in before it are left out, and one under way at its start starts there."""
    return tuple(
        replace(event, start_frame=first, start_s=first / fps)
        if event.start_frame < first
        else event
        for event in events
        if event.end_frame >= first
    )


# How long a video's start `--rotate auto` reads the sky of, and at what size (seconds, rows).
SKY_START = (6.0, 360)


def sky_start(source: Path, info: VideoInfo) -> list[Frame]:
    """The frames of a video's first seconds that `--rotate auto` scores (`SKY_START`: every
    `SKY.every`-th, at 360 rows; `info` is the video as probed, before any turn)."""
    seconds, rows = SKY_START
    small = within_size(info, rows)
    count = min(small.n_frames, max(1, round(seconds * small.fps)))
    return [f for k, f in enumerate(read_frames(source, small, 0, count)) if k % SKY.every == 0]


def sky_mounting(
    source: Path,
    info: VideoInfo,
    mounting: Mounting,
    log: Callable[[str], None],
    after: Path | None = None,
) -> Mounting:
    """`mounting` with `--rotate auto` settled on the turn that the sky of the video's first
    seconds votes for (with those of `after`'s, the part of the drive before it, of the same
    camera and size: the parts of a drive are turned alike), and `log` told of it; where the
    vote is not clear the picture is taken as stored, and told so (`info` is the video as
    probed, before any turn)."""
    if not mounting.rotate_auto:
        return mounting
    sampled = sky_start(source, info)
    seconds = f"its first {SKY_START[0]:g} s"
    if after is not None and sampled:
        earlier = sky_start(after, probe_video(after))
        if earlier and earlier[0].shape == sampled[0].shape:
            sampled = earlier + sampled
            seconds += f" and {after.name}'s, the part before it"
    vote = frames_vote(sampled, SKY)
    side, turn = vote.side, vote.turn_deg
    if side is None or turn is None:
        log(
            f"note: {source.name}: --rotate auto could not tell which way up it is (its sky "
            f"stood out in {sum(vote.votes)} sampled frames of {seconds}; it takes "
            f"{SKY.min_votes}, {SKY.least:.0%} of them on one side): it is read as stored; "
            "pass --rotate DEG if it is turned"
        )
        return replace(mounting, rotate_auto=False)
    if turn:
        log(
            f"note: {source.name}: --rotate auto: its sky lies {sky_where(side)} in "
            f"{vote.votes[side]} of {sum(vote.votes)} frames of {seconds}: it is turned {turn} "
            "degrees clockwise to stand it upright (the record's rotate_deg)"
        )
    return replace(mounting, rotate_deg=turn, rotate_auto=False)


def process_video(
    source: Path,
    output: Path | None,
    calibration: Calibration | None,
    lanes: LaneFinder | None,
    vehicles: VehicleDetector | None,
    record: Path | None = None,
    annotators: Sequence[Annotator] = (),
    start_s: float = 0.0,
    end_s: float | None = None,
    vehicles_in_worker: bool = True,
    events_file: Path | None = None,
    log: Callable[[str], None] = lambda message: None,
    calibration_required: bool = True,
    max_size: int = 0,
    mounting: Mounting | None = None,
    after: Path | None = None,
) -> RunSummary:
    """Process a video into an annotated video, a record and/or an events file; outputs appear
    only on success (`log` hears what decoding changes: HDR tone-mapped, pixels made square;
    and, with the vehicle stage, a video without colour).
    A `calibration` of another aspect ratio is refused if `calibration_required`, else left out
    (see `calibration_for`).

    With `output` None no video is composed or encoded (the record alone). With
    `vehicles_in_worker` the vehicle stage runs in a forked worker process beside the lanes.
    The `mounting` the user states (`Mounting`: the horizon row, the camera's height, traffic
    keeping left, the picture's turn) takes the place of what the footage would tell; a video
    whose shorter side exceeds `max_size` pixels (0: none) is processed and written at that size
    (`within_size`; the mounting's horizon is a row of the video as stored). A video that goes
    on from `after`, the part of the drive before it (a dashcam's previous file), starts with
    the history the stages had at its end (`lead_in`).
    """
    warm_up = warm_up_opencv()
    try:
        probed = probe_video(source)
        mounting = sky_mounting(source, probed, mounting or Mounting(), log, after)
        upright = mounting.rotate_deg
        info = within_size(turned_info(probed, upright), max_size)
        first, last = frame_range(info.fps, info.n_frames, start_s, end_s)
        calibration, mounting = camera_for(
            calibration, mounting, info, source.name, calibration_required, log
        )
        for note in decoding_notes(info):
            log(f"note: {source.name}: {note}")
        focal_mm = recorded_focal_mm(calibration, mounting)
        lead = None if after is None else lead_in(after, info, source, max_size, log, upright)
    finally:
        # Before the fork in prepare() no thread may run, nor at exit inside OpenCV (abort).
        warm_up.join()
    started = time.perf_counter()
    count = 0
    progress = Progress(last - first, label=source.name)
    with (
        Pipeline(calibration, lanes, vehicles, vehicles_in_worker, mounting) as pipeline,
        ExitStack() as sinks,
    ):
        # The lead-in's `led` frames are run first, not recorded.
        frames_from, led = start_part(pipeline, source, info, first, last, lead)
        records = sinks.enter_context(RecordSink(record)) if record is not None else None
        video = None
        if output is not None:
            video = sinks.enter_context(
                VideoSink(
                    output,
                    info.size,
                    info.fps,
                    AudioSpan(
                        source, info.video_start_s + first / info.fps, (last - first) / info.fps
                    )
                    if info.has_audio
                    else None,
                )
            )
        # Without --end every decoded frame is read (the probed count is an estimate).
        decoded = prefetch(frames_from(0, last if end_s is not None else None))
        # Colour is looked for in every 5th frame of the first 2 s: a fade from black or a
        # camera starting up shows none at first.
        colourless, told_at = vehicles is not None, min(round(2 * info.fps), last - first) - 1
        scales: list[float] = []  # the lanes' ground scale at each frame
        aims: list[float] = []  # the vanishing point's column off the live middle, in widths
        skies: list[int | None] = []  # the sky's side in every SKY.every-th frame
        for started_at, out in enumerate(pipeline.stream(decoded)):
            offset = started_at - led
            if offset < 0:
                continue  # the lead-in: history, not output
            index = first + offset
            if (scene := out.result.scene) is not None:
                scales.append(scene.ground_scale)
                if scene.vanishing_x is not None:
                    x0, _, x1, _ = scene.live
                    aims.append((scene.vanishing_x - (x0 + x1) / 2) / max(1, x1 - x0))
            if offset % SKY.every == 0:
                skies.append(frame_sky(out.undistorted, None if scene is None else scene.live, SKY))
            if colourless and offset <= told_at and offset % 5 == 0:
                colourless = monochrome(out.undistorted)
            if colourless and offset == told_at:
                log(f"note: {source.name} is {MONOCHROME_NOTE}")
            if video is not None:
                video.write(compose(out.undistorted, out.result, annotators))
            if records is not None:
                records.write(
                    frame_record(index, index / info.fps, info.size, out.result, focal_mm, upright)
                )
            count += 1
            progress.update()
        progress.close()
        expected = last - first
        # A damaged file's count is the packets read before the damage, some of them not
        # whole: the frames that decode are what it holds (its note said so at the start).
        short = count < expected - max(2, expected // 50) and info.damage is None
        if count == 0 or short:
            raise InputError(
                f"{source} is truncated or damaged: decoded {count} of {expected} frames; "
                "re-export or re-download the video"
            )
        if cuts := [frame for frame in pipeline.cuts if frame >= first]:
            at = ", ".join(f"{frame / info.fps:.1f} s" for frame in cuts)
            log(
                f"note: {source.name} cuts to another shot at {at}; the stages started over "
                "there (the scene measured afresh where another camera's picture begins)"
            )
        facing = facing_note(mounting.rear, pipeline.facing_seen)
        if facing is not None:
            log(f"note: {source.name} is {facing}")
        if pipeline.levelled is not None:
            turn, frame = pipeline.levelled  # levelled in the lead-in: from the start
            said = levelled_note(turn, max(frame, first), info.fps, pipeline.levelled_by)
            log(f"note: {source.name}: {said}")
        if pipeline.roll_contradicted is not None:
            said = roll_contradicted_note(mounting.roll_deg or 0.0, pipeline.roll_contradicted)
            log(f"note: {source.name}: {said}")
        if count and (horizon := pipeline.horizon_note()) is not None:
            log(f"note: {source.name}: {horizon}")
        height = pipeline.height_note(float(np.median(scales))) if scales else None
        if height is not None:
            log(f"note: {source.name}: {height}")
        if (dashes := pipeline.dash_note()) is not None:
            log(f"note: {source.name}: {dashes}")
        if (aim := aim_note(float(np.median(aims)) if aims else None)) is not None:
            log(f"note: {source.name}: {aim}")
        sky = upright_note(sky_vote(skies, SKY.least, SKY.min_votes), upright)
        if sky is not None:
            log(f"note: {source.name}: {sky}")
        events = within_part(tuple(pipeline.finish_events()), first, info.fps)
        if events_file is not None:
            event_sink = sinks.enter_context(RecordSink(events_file))
            for event in events:
                event_sink.write(event_record(event))
    return RunSummary(
        count,
        time.perf_counter() - started,
        output,
        record,
        count / info.fps,
        events,
        events_file,
    )


def process_still(
    source: Path,
    output: Path,
    calibration: Calibration | None,
    lanes: LaneFinder | None,
    vehicles: VehicleDetector | None,
    record: Path | None = None,
    annotators: Sequence[Annotator] = (),
    log: Callable[[str], None] = lambda message: None,
    mounting: Mounting | None = None,
) -> RunSummary:
    """Process one still into an annotated image (and a one-line record).

    A still whose aspect ratio is not the calibration's (another camera, or a crop) is processed
    without undistortion, and says so.
    """
    mounting = mounting or Mounting()
    if mounting.rotate_auto:
        log(
            f"note: {source.name}: --rotate auto reads the sky of a video's frames, and one "
            "still can mislead: it is read as stored; pass --rotate DEG if it is turned"
        )
        mounting = replace(mounting, rotate_auto=False)
    check_rotate(mounting.rotate_deg)
    image = turned_image(read_image(source), mounting.rotate_deg)
    size = (image.shape[1], image.shape[0])
    check_mounting(mounting, size)
    started = time.perf_counter()
    calibration, mounting = lens_for(
        calibration, mounting, size, image_focal_mm(source), source.name, False, log
    )
    with Pipeline(calibration, lanes, vehicles, mounting=mounting) as pipeline:
        pipeline.prepare(size)
        out = pipeline.run(image)
    with ExitStack() as sinks:
        sinks.enter_context(ImageSink(output)).write(
            compose(out.undistorted, out.result, annotators)
        )
        if record is not None:
            sinks.enter_context(RecordSink(record)).write(
                frame_record(
                    0,
                    0.0,
                    size,
                    out.result,
                    recorded_focal_mm(calibration, mounting),
                    mounting.rotate_deg,
                )
            )
    return RunSummary(1, time.perf_counter() - started, output, record)
