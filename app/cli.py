"""The roadview command line: data, calibrate, process, evaluate."""

from __future__ import annotations

import json
import sys
import traceback
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from numpy.typing import NDArray

from app.errors import USER_ERRORS, InputError, Interrupted, describe
from app.mounting import Mounting, check_mounting, check_roll
from app.runtime import tune_process
from camera_cal import (
    US_DASH_SPACING_M,
    Calibration,
    calibrate,
    calibrate_frames,
    default_calibration_path,
    load_calibration,
    save_calibration,
)
from camera_cal.calibration import list_images

cli = typer.Typer(
    name="roadview",
    help="Annotate dashcam video with the ego lane and surrounding vehicles.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: no <bool>/<path> type tags, no box drawing
)


# Options that several commands share.
DEFAULT_CALIBRATION = str(default_calibration_path())
CalibrationOption = Annotated[
    str, typer.Option(metavar="FILE|none", help="Calibration JSON, or 'none' to skip undistortion.")
]
ModelOption = Annotated[
    Path | None, typer.Option(help="Vehicle model file (default: the shipped one).")
]
VerifierOption = Annotated[
    str | None,
    typer.Option(
        metavar="FILE|none",
        help="Model that vetoes the vehicle model's windows (default: the shipped one trained "
        "also on hard negatives), or 'none'.",
    ),
]
HorizonOption = Annotated[
    float | None,
    typer.Option(metavar="Y", help="Horizon row in pixels (default: estimated from the footage)."),
]
CameraHeightOption = Annotated[
    float | None,
    typer.Option(
        "--camera-height",
        metavar="M",
        help="The camera's height over the road in metres, e.g. 2.2 for a lorry's: sizes the "
        "vehicle search for it (default: a car's, 1.24 m).",
    ),
]
RollOption = Annotated[
    float | None,
    typer.Option(
        "--roll",
        metavar="DEG",
        help="The picture's tilt from a camera mounted askew, in degrees: positive when it is "
        "turned anticlockwise (the horizon rises to the right). The frames are levelled, the "
        "output and the record too (default: read off the vehicles' rear edges or the lane "
        "lines' spacing, and levelled from when they agree; 0: level).",
    ),
]

RotateOption = Annotated[
    str,
    typer.Option(
        "--rotate",
        metavar="DEG|auto",
        help="Turn the picture this many degrees clockwise to stand it upright: 180 for a "
        "dashcam mounted upside down without its flip setting, 90 or 270 for a phone's video "
        "that lost its rotation tag (decoding turns it, the calibration with it; --horizon "
        "is a row of the upright picture); 'auto' turns a video by what the sky of its first "
        "6 s votes for (where the vote is clear; else it is read as stored, with a note).",
    ),
]

# Video larger than 1080p is processed at 1080p: the stages read no more from more pixels (the
# lanes keep a 720-row view, the vehicle bands are shrunk to their windows' model size) and 4K
# would take decoding, undistortion and encoding four times as long (README: Speed at 1080p).
DEFAULT_MAX_SIZE = 1080
MaxSizeOption = Annotated[
    int,
    typer.Option(
        "--max-size",
        metavar="PX",
        help="Video whose shorter side is longer than this many pixels is processed and written "
        "at this size (4K as 1080p); 0 keeps every video's full size.",
    ),
]

TrafficOption = Annotated[
    str,
    typer.Option(
        "--traffic",
        metavar="right|left",
        help="The side of the road traffic keeps to: 'left' in the UK, Ireland, India, Japan, "
        "Australia (the vehicle search, tuned on traffic keeping right, sees the frames "
        "mirrored).",
    ),
]


FacingOption = Annotated[
    str,
    typer.Option(
        "--facing",
        metavar="auto|front|rear|rear-mirrored",
        help="Which way the camera looks: 'rear' for a dual-channel dashcam's rear file as its "
        "lens sees the road (the speed is read from the road moving away, the vehicle in our "
        "lane is the one behind, the vehicle search sees the road's sides swapped), "
        "'rear-mirrored' for one saved mirrored, as a rear-view mirror shows it (its writing "
        "reads backwards); 'auto' reads a rear camera from the road's motion but searches "
        "vehicles as for a front camera.",
    ),
]


FocalLengthOption = Annotated[
    float | None,
    typer.Option(
        "--focal-length",
        metavar="MM",
        help="The lens's focal length in 35 mm terms, as a phone's camera specs give it (26 for "
        "most phones' main camera): sets the distances and speed of a camera without a "
        "calibration (default: the video's tag where a phone wrote one, else the shipped "
        "dashcam's lens, 31).",
    ),
]


DashSpacingOption = Annotated[
    str | None,
    typer.Option(
        "--dash-spacing",
        metavar="M|none",
        help="The spacing of the lane dashes on the roads filmed, one dash and gap, in metres: "
        "where the lens is not known (no --calibration FILE, --focal-length or phone's tag), "
        "distances and speed follow the dashes (default: 12.19, US highways; the UK's "
        "motorways 9, German autobahns 18); none: the lens is taken as the shipped camera's.",
    ),
]


def _dash_spacing(value: str | None) -> float | None:
    """The --dash-spacing option in metres (None: the dashes are not read); a value that is no
    number is refused (the range is checked with the rest of the mounting)."""
    if value is None:
        return US_DASH_SPACING_M
    if value.strip().lower() == "none":
        return None
    try:
        return float(value)
    except ValueError:
        raise InputError(
            f"--dash-spacing {value} is not a number of metres; give one (US highways 12.19) "
            "or none"
        ) from None


def _mounting(
    horizon: float | None,
    camera_height: float | None,
    traffic: str,
    roll: float | None,
    facing: str,
    focal_length: float | None,
    calibration: str,
    dash_spacing: str | None = None,
    rotate: str = "0",
) -> Mounting:
    """The `Mounting` the options state; a focal length beside a calibration file is refused
    (the calibration holds the lens's own)."""
    if focal_length is not None and _named(calibration) and calibration.lower() != "none":
        raise InputError(
            f"--focal-length and --calibration {calibration} both give the lens; pass one (the "
            "calibration holds its focal length)"
        )
    keep_left = _keep_left(traffic)
    return Mounting(
        horizon,
        camera_height,
        keep_left,
        roll,
        _facing(facing),
        focal_length,
        _dash_spacing(dash_spacing),
        *_rotate(rotate),
    )


def _rotate(rotate: str) -> tuple[int, bool]:
    """The --rotate option: degrees clockwise (-90 is 270) and whether the sky decides."""
    if rotate.strip().lower() == "auto":
        return 0, True
    try:
        return int(rotate) % 360, False
    except ValueError:
        raise InputError(
            f"--rotate {rotate} is not a quarter turn; pass 90, 180 or 270 (degrees clockwise "
            "that stand the picture upright), or auto to read it off the sky"
        ) from None


def _facing(facing: str) -> str:
    """The `--facing` value in lower case (checked with the rest of the mounting)."""
    return facing.strip().lower()


def _max_size(pixels: int) -> int:
    """The --max-size option: 0, or a size the stages can work at."""
    if pixels != 0 and pixels < 240:
        raise InputError(
            f"--max-size {pixels} is too small to find lanes and vehicles; "
            "give 240 or more (1080 by default), or 0 for the full size"
        )
    return pixels


def _keep_left(traffic: str) -> bool:
    """Whether `--traffic` says traffic keeps left; anything but right or left is refused."""
    side = traffic.strip().lower()
    if side not in ("right", "left"):
        raise InputError(f"--traffic {traffic} is not a side; give right or left")
    return side == "left"


@cli.callback()
def _options(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Show tracebacks.")] = False,
) -> None:
    """Options before the command (main() reads --verbose itself, to show tracebacks)."""


def _parse_board(board: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in board.lower().split("x"))
    except ValueError:
        raise InputError(f"--board {board!r} is not COLSxROWS of inner corners, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise InputError("--board needs at least 2x2 inner corners")
    return cols, rows


@cli.command("data")
def data_command(
    source: Annotated[Path, typer.Option(help="Shared data folder to copy from.")] = Path(
        "../shared/data"
    ),
    dest: Annotated[Path, typer.Option(help="Where the data set goes.")] = Path("data"),
) -> None:
    """Copy the data set from the shared folder (or download the public files) into DEST."""
    from app.data import gather

    added = gather(source, dest, log=lambda m: typer.echo(m, err=True))
    typer.echo(f"data ready in {dest} ({added} files added)")


@cli.command("calibrate")
def calibrate_command(
    images: Annotated[
        Path | None,
        typer.Option(help="Folder of chessboard photos (default: data/camera_cal)."),
    ] = None,
    video: Annotated[
        Path | None,
        typer.Option(
            help="Instead of photos: a video of the chessboard, filmed with the dashcam while "
            "the board is moved about the picture."
        ),
    ] = None,
    board: Annotated[str, typer.Option(help="Inner corners per row x per column.")] = "9x6",
    out: Annotated[Path, typer.Option(help="Calibration JSON to write.")] = Path(
        "camera_cal/dashcam.json"
    ),
) -> None:
    """Calibrate the camera from chessboard photos or a video and save the matrix and
    distortion as JSON."""
    from app.sinks import atomic_output

    size = _parse_board(board)
    if video is not None and images is not None:
        raise InputError("give --images or --video, not both")
    if video is not None:
        calibration = _calibrate_video(video, size)
        source = f"{len(calibration.images_used)} distinct views in {video}"
    else:
        calibration = calibrate(list_images(images or Path("data/camera_cal")), board=size)
        for skipped in calibration.images_skipped:
            typer.echo(f"skipped {skipped}", err=True)
        total = len(calibration.images_used) + len(calibration.images_skipped)
        source = f"{len(calibration.images_used)} of {total} images"
    try:
        with atomic_output(out) as tmp:
            save_calibration(calibration, tmp)
    except OSError as error:
        raise InputError(f"cannot write {out} ({error.strerror}); choose another --out") from None
    m = calibration.camera_matrix
    typer.echo(
        f"calibrated from {source}: "
        f"RMS reprojection error {calibration.rms:.3f} px, fx {m[0, 0]:.1f}, fy {m[1, 1]:.1f}, "
        f"cx {m[0, 2]:.1f}, cy {m[1, 2]:.1f}; the board covered {calibration.coverage:.0%} "
        f"of the picture; saved {out}"
    )
    if calibration.coverage < GOOD_COVERAGE:
        typer.echo(
            "note: the picture's corners and edges, where a lens bends most, were not seen: "
            "the distortion there is extrapolated; give views with the board near them",
            err=True,
        )


# The share of the picture the board's corners should have covered: less leaves a wide lens's
# corners and edges to extrapolation (the shared photos cover most of the picture).
GOOD_COVERAGE = 0.6

# Frames of a calibration video looked at per second: a board moved by hand changes little
# in a quarter of a second, and each look costs a few milliseconds (tens where a board is).
CALIBRATION_LOOKS_PER_S = 4.0


def _calibrate_video(video: Path, board: tuple[int, int]) -> Calibration:
    """Calibrate from the upright frames of a chessboard video, a few per second (a progress
    bar on a terminal: a look where the board is costs tens of milliseconds)."""
    from app.progress import Progress
    from app.sources import probe_video, read_frames

    info = probe_video(video)
    step = max(1, round(info.fps / CALIBRATION_LOOKS_PER_S)) if info.fps > 0 else 1
    progress = Progress(-(-info.n_frames // step), label=video.name, unit="looks/s")

    def looks() -> Iterator[tuple[str, NDArray[np.uint8]]]:
        for i, frame in enumerate(read_frames(video, info)):
            if i % step == 0:
                yield f"frame {i}", frame
                progress.update()

    try:
        return calibrate_frames(looks(), board=board)
    finally:
        progress.close()


def _named(calibration: str) -> bool:
    """Whether the user named the --calibration (a file of another aspect ratio is then refused;
    the shipped default is left out for another camera's frames)."""
    return calibration != DEFAULT_CALIBRATION


def _calibration(value: str) -> Calibration | None:
    """The --calibration option: a calibration file, or None for 'none' (no undistortion)."""
    return None if value.lower() == "none" else load_calibration(Path(value))


def _verifier(value: str | None) -> dict[str, Any]:
    """The --verifier option as `build_stages` keywords: a file, the shipped one, or 'none'."""
    if value is not None and value.lower() == "none":
        return {"verify": False}
    if value is not None and not Path(value).is_file():
        raise InputError(f"--verifier {value} does not exist; give a model file or 'none'")
    return {"verifier": Path(value) if value is not None else None}


@cli.command("process")
def process_command(
    source: Annotated[Path, typer.Argument(metavar="INPUT", help="Video or still image.")],
    output: Annotated[
        Path | None,
        typer.Option(
            "-o", "--output", help="Output file (default: NAME_roadview.EXT beside the input)."
        ),
    ] = None,
    record: Annotated[
        Path | None, typer.Option("--json", help="Per-frame JSON-lines record.")
    ] = None,
    events: Annotated[
        Path | None,
        typer.Option(
            "--events", help="Driving events (lane departure, close following, ...) as JSON lines."
        ),
    ] = None,
    calibration: CalibrationOption = DEFAULT_CALIBRATION,
    start: Annotated[float, typer.Option(help="Start time in seconds.")] = 0.0,
    end: Annotated[float | None, typer.Option(help="End time in seconds.")] = None,
    lanes: Annotated[bool, typer.Option("--lanes/--no-lanes", help="Find the ego lane.")] = True,
    vehicles: Annotated[
        bool, typer.Option("--vehicles/--no-vehicles", help="Detect and track vehicles.")
    ] = True,
    model: ModelOption = None,
    verifier: VerifierOption = None,
    insets: Annotated[bool, typer.Option(help="Add bird's-eye and heat-map insets.")] = False,
    horizon: HorizonOption = None,
    camera_height: CameraHeightOption = None,
    traffic: TrafficOption = "right",
    max_size: MaxSizeOption = DEFAULT_MAX_SIZE,
    roll: RollOption = None,
    facing: FacingOption = "auto",
    focal_length: FocalLengthOption = None,
    dash_spacing: DashSpacingOption = None,
    rotate: RotateOption = "0",
    after: Annotated[
        Path | None,
        typer.Option(
            metavar="PREV",
            help="The video this one goes on from, a dashcam's previous file of the drive: "
            "its last 10 s are run first, unrecorded, so the scene, lanes and vehicles go on "
            "as they were.",
        ),
    ] = None,
) -> None:
    """Undistort and annotate a video or still; optionally write the per-frame record."""
    from app.annotators import default_annotators
    from app.assembly import build_stages
    from app.drivers import process_still, process_video
    from app.outputs import check_after, plan_outputs
    from app.sources import check_input, is_image

    check_input(source)
    mounting = _mounting(
        horizon, camera_height, traffic, roll, facing, focal_length, calibration, dash_spacing,
        rotate,
    )  # fmt: skip
    max_size = _max_size(max_size)
    outputs = plan_outputs(source, output, record, lambda m: typer.echo(m, err=True), events)
    if after is not None:
        check_after(after, source, outputs, start)
    output, record = outputs.media, outputs.record
    cal = _calibration(calibration)
    still = is_image(source)
    stages = build_stages(
        lanes, vehicles, model, keep_debug=insets, still=still, **_verifier(verifier)
    )
    annotators = default_annotators(insets)
    if still:
        summary = process_still(
            source,
            output,
            cal,
            *stages,
            record,
            annotators,
            log=lambda m: typer.echo(m, err=True),
            mounting=mounting,
        )
    else:
        # Vehicles run in a worker process beside the lanes, one frame ahead of the compositor.
        summary = process_video(
            source,
            output,
            cal,
            *stages,
            record,
            annotators,
            start,
            end,
            events_file=events,
            log=lambda m: typer.echo(m, err=True),
            calibration_required=_named(calibration),
            max_size=max_size,
            mounting=mounting,
            after=after,
        )
    written = [str(p) for p in (summary.record, summary.events_file) if p is not None]
    typer.echo(
        f"wrote {summary.output} ({summary.frames} frames, {summary.fps:.1f} fps)"
        + (f" and {' and '.join(written)}" if written else "")
    )
    if not still:
        typer.echo(f"events: {len(summary.events) or 'none'}")
        for event in summary.events:
            typer.echo(f"  {event.describe()}")


@cli.command("batch")
def batch_command(
    inputs: Annotated[
        list[Path],
        typer.Argument(metavar="INPUTS...", help="Videos, folders (searched) or .txt lists."),
    ],
    out: Annotated[Path, typer.Option("--out", help="Output folder.")],
    scheduler: Annotated[
        str | None, typer.Option(help="A running Dask scheduler, e.g. tcp://HOST:8786.")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Local worker processes (default: one per core).")
    ] = None,
    video: Annotated[
        bool, typer.Option("--video/--no-video", help="Write annotated videos.")
    ] = True,
    force: Annotated[bool, typer.Option(help="Redo inputs already done.")] = False,
    calibration: CalibrationOption = DEFAULT_CALIBRATION,
    model: ModelOption = None,
    camera_height: CameraHeightOption = None,
    traffic: TrafficOption = "right",
    max_size: MaxSizeOption = DEFAULT_MAX_SIZE,
    roll: RollOption = None,
    facing: FacingOption = "auto",
    focal_length: FocalLengthOption = None,
    dash_spacing: DashSpacingOption = None,
    rotate: RotateOption = "0",
    drives: Annotated[
        bool,
        typer.Option(
            help="The videos in each folder are parts of one camera's drives, in name order, "
            "as a dashcam splits them: each goes on from the one before (process --after).",
        ),
    ] = False,
) -> None:
    """Process many videos on Dask (local cluster or --scheduler); resumable; Parquet table."""
    from app.batch import BatchOptions, find_inputs, in_drives, run_batch, summary_line

    mounting = _mounting(
        None, camera_height, traffic, roll, facing, focal_length, calibration, dash_spacing,
        rotate,
    )  # fmt: skip
    check_mounting(mounting)
    entries = find_inputs(inputs)
    if not entries:
        raise InputError("no video files found in the inputs; pass videos, folders or a .txt list")
    if drives:
        entries = in_drives(entries)
    _calibration(calibration)  # a bad calibration fails here, once, not in every task
    options = BatchOptions(
        out=out.resolve(),
        video=video,
        calibration=None if calibration.lower() == "none" else str(Path(calibration).resolve()),
        calibration_required=_named(calibration),
        model=str(model.resolve()) if model is not None else None,
        mounting=mounting,
        max_size=_max_size(max_size),
    )
    summary = run_batch(
        entries, options, scheduler, workers, force, log=lambda m: typer.echo(m, err=True)
    )
    typer.echo(summary_line(summary))
    if summary.failed:
        raise typer.Exit(1)


@cli.command("debug")
def debug_command(
    source: Annotated[Path, typer.Argument(metavar="INPUT", help="Video to step through.")],
    frames: Annotated[str, typer.Option(help="Frames A:B (B excluded) or one frame number.")],
    out: Annotated[
        Path | None, typer.Option(help="Folder (default: NAME_debug next to the input).")
    ] = None,
    calibration: CalibrationOption = DEFAULT_CALIBRATION,
    model: ModelOption = None,
    verifier: VerifierOption = None,
    horizon: HorizonOption = None,
    camera_height: CameraHeightOption = None,
    traffic: TrafficOption = "right",
    max_size: MaxSizeOption = DEFAULT_MAX_SIZE,
    roll: RollOption = None,
    facing: FacingOption = "auto",
    focal_length: FocalLengthOption = None,
    dash_spacing: DashSpacingOption = None,
    rotate: RotateOption = "0",
    from_start: Annotated[
        bool,
        typer.Option(
            help="Run the clip from its first frame, so the chosen frames are as 'process' "
            "made them (the scales learned, the tracks; default: from 6 s before them)."
        ),
    ] = False,
    after: Annotated[
        Path | None,
        typer.Option(
            metavar="PREV",
            help="The video this one goes on from (see process --after): run first where the "
            "run starts at the clip's first frame.",
        ),
    ] = None,
) -> None:
    """Write every intermediate of the chosen frames as PNGs, with an index.html to step through."""
    from app.assembly import build_stages
    from app.debug import parse_frames, run_debug
    from app.outputs import check_debug_folder, check_lead
    from app.pipeline import Pipeline
    from app.sources import check_input

    span = parse_frames(frames)
    check_input(source)
    if after is not None:
        check_lead(after, source)
    folder = out if out is not None else source.with_name(f"{source.stem}_debug")
    check_debug_folder(folder, source)
    cal = _calibration(calibration)
    stages = build_stages(model=model, keep_debug=True, **_verifier(verifier))
    mounting = _mounting(
        horizon, camera_height, traffic, roll, facing, focal_length, calibration, dash_spacing,
        rotate,
    )  # fmt: skip
    pipeline = Pipeline(cal, *stages, mounting=mounting)
    written = run_debug(
        source,
        span,
        folder,
        pipeline,
        log=lambda m: typer.echo(m, err=True),
        calibration_required=_named(calibration),
        max_size=_max_size(max_size),
        from_start=from_start,
        after=after,
    )
    typer.echo(f"wrote {len(written)} files; open {folder / 'index.html'}")


@cli.command("evaluate")
def evaluate_command(
    labels: Annotated[Path, typer.Option(help="Labels JSON of the clip.")],
    record: Annotated[Path, typer.Option(help="Record written by 'process --json'.")],
    warmup: Annotated[int, typer.Option(help="Frames not scored at the start.")] = 10,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Score a record against hand-made labels (vehicles by IoU, lane x error per row)."""
    from app.evaluate import clip_frames, coverage_problem, evaluate, format_report, load_labels
    from app.record import read_record

    truth = load_labels(labels)
    frames = list(read_record(record))
    problem = coverage_problem(truth, frames, clip_frames(labels), warmup)
    if problem is not None:
        raise InputError(f"cannot score {record} against {labels}: {problem}")
    scores = evaluate(truth, frames, warmup=warmup)
    typer.echo(json.dumps(scores) if as_json else format_report(scores))


@cli.command("report")
def report_command(
    record: Annotated[
        Path, typer.Argument(metavar="RECORD", help="Record written by 'process --json'.")
    ],
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="HTML page to write (default: RECORD_report.html)."),
    ] = None,
    events: Annotated[
        Path | None,
        typer.Option(help="Events written by 'process --events' (default: found from the record)."),
    ] = None,
    video: Annotated[
        Path | None,
        typer.Option(help="The video the record was made from, for a thumbnail per event."),
    ] = None,
    calibration: CalibrationOption = DEFAULT_CALIBRATION,
    roll: Annotated[
        float | None,
        typer.Option(
            "--roll",
            metavar="DEG",
            help="The turn 'process' levelled the picture by, in degrees anticlockwise, for the "
            "thumbnails (default: the record's, stated or read off the footage).",
        ),
    ] = None,
) -> None:
    """Write a self-contained HTML report: plots over time and the events with thumbnails."""
    from app.events import find_events, signals_from_record
    from app.outputs import check_report_output
    from app.record import read_record
    from app.report import event_thumbnails, read_events, report_html
    from app.sinks import atomic_output

    check_roll(roll)
    output = output if output is not None else record.with_name(f"{record.stem}_report.html")
    check_report_output(output, [p for p in (record, events, video) if p is not None])
    rows = list(read_record(record))
    if not rows:
        raise InputError(f"record {record} has no frames; make one with 'roadview process --json'")
    if events is not None:
        found, source = read_events(events), f"from {events.name}"
    else:
        found = find_events(signals_from_record(r) for r in rows)
        source = f"found from {record.name}"
    thumbnails = {}
    if video is not None:
        thumbnails = event_thumbnails(video, rows, found, _calibration(calibration), roll)
    elif found:
        typer.echo("note: no --video given; the events have no thumbnails", err=True)
    page = report_html(f"roadview report: {record.name}", rows, found, thumbnails, source)
    try:
        with atomic_output(output) as tmp:
            tmp.write_text(page)
    except OSError as error:
        raise InputError(f"cannot write {output} ({error.strerror}); choose another -o") from None
    typer.echo(f"wrote {output} ({len(rows)} frames, {len(found)} events)")


@cli.command("train")
def train_command(
    data: Annotated[
        Path, typer.Option(help="Folder with vehicles(.zip) and non-vehicles(.zip).")
    ] = Path("data"),
    out: Annotated[Path, typer.Option(help="Model file to write.")] = Path(
        "vehicles/models/default.npz"
    ),
    hard_negatives: Annotated[
        list[Path] | None,
        typer.Option(help="Folder of extra non-vehicle patches mined from frames (repeatable)."),
    ] = None,
    jobs: Annotated[int, typer.Option(help="Parallel workers.")] = 2,
    c: Annotated[
        float | None, typer.Option("--c", help="SVM C (default: chosen by a grouped search).")
    ] = None,
    patch: Annotated[
        int,
        typer.Option(help="Patch side in pixels: 64, or 32 for the model of the smallest windows."),
    ] = 64,
    mirror: Annotated[
        bool,
        typer.Option(
            "--mirror/--no-mirror",
            help="Also train on each patch's mirror image (left- and right-hand traffic alike).",
        ),
    ] = False,
    degrade: Annotated[
        bool,
        typer.Option(
            "--degrade/--no-degrade",
            help="Also train on each patch as small compressed footage shows it (360-480 rows).",
        ),
    ] = False,
    grey: Annotated[
        bool,
        typer.Option(
            "--grey/--no-grey",
            help="Train on each patch without its colour: a model of monochrome footage.",
        ),
    ] = False,
) -> None:
    """Train the vehicle classifier (grouped C search, calibration) and save it without pickle."""
    from app.progress import Progress
    from app.sinks import atomic_output
    from vehicles.dataset import load_patch_folder, load_patches
    from vehicles.model import save_model
    from vehicles.train import TrainConfig, format_training_report, train_model

    if c is not None and c <= 0:
        raise InputError(f"--c {c} must be positive")
    if patch not in (32, 64):
        raise InputError(f"--patch {patch} is not a model size; give 64 or 32")
    patches = load_patches(data)
    extra = [patch for folder in hard_negatives or [] for patch in load_patch_folder(folder)]
    bar = Progress(len(patches) + len(extra), label="features", unit="patches/s")

    def progress(done: int, total: int) -> None:
        bar.update(done - bar.count)
        if done >= total:
            bar.close()  # the training log that follows starts on its own line

    from vehicles.features import FeatureConfig

    model = train_model(
        patches,
        # Spatial bins of 4 x 4 pixels at either size.
        FeatureConfig(patch_size=patch, spatial_size=patch // 4),
        cfg=TrainConfig(
            n_jobs=jobs,
            mirror=mirror,
            degrade=degrade,
            grey=grey,
            # A given C is the whole grid: no search.
            c_grid=TrainConfig.c_grid if c is None else (c,),
        ),
        progress=progress,
        log=lambda m: typer.echo(m, err=True),
        extra_negatives=extra,
    )
    bar.close()
    try:
        with atomic_output(out) as tmp:
            save_model(model, tmp)
    except OSError as error:
        raise InputError(f"cannot write {out} ({error.strerror}); choose another --out") from None
    typer.echo(format_training_report(model.report))
    typer.echo(f"saved {out}")


@cli.command("mine")
def mine_command(
    videos: Annotated[list[Path], typer.Argument(help="Clips without any vehicle in them.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder of patches to write.")],
    share: Annotated[
        float, typer.Option(help="Share of each clip to mine, from its start (the rest is kept).")
    ] = 0.6,
    every: Annotated[int, typer.Option(help="Mine every n-th frame.")] = 3,
    model: ModelOption = None,
    dusk: Annotated[
        bool,
        typer.Option(
            "--dusk/--no-dusk",
            help="Mine dimmed, grainy copies of each clip instead (a dim sensor at dusk and "
            "night), read as 'process' reads a dark road: for the dark verifier.",
        ),
    ] = False,
    grey: Annotated[
        bool,
        typer.Option(
            "--grey/--no-grey",
            help="Mine each clip without its colour (with a grey --model): for the grey verifiers.",
        ),
    ] = False,
) -> None:
    """Cut the windows the vehicle model is sure of in clips without vehicles into patches, for
    'train --hard-negatives': what fooled it there is learned as road."""
    from app.assembly import build_stages
    from app.mining import DUSK, mine_clips

    if not 0 < share <= 1 or every < 1:
        raise InputError("--share must be in (0, 1] and --every at least 1")
    for video in videos:
        if not video.is_file():
            raise InputError(f"{video} does not exist; give clips without vehicles to mine")
    # The 64 px model's false alarms, as mined for the shipped verifiers (both learn them).
    detector = build_stages(
        lanes=False, model=model, verify=False, small=False, lowres=False
    ).vehicles
    assert detector is not None
    dimmings = DUSK if dusk else ()
    total = mine_clips(
        videos, detector, out, share, every, log=typer.echo, dimmings=dimmings, grey=grey
    )
    typer.echo(f"wrote {total} patches to {out}")


@cli.command("evaluate-classifier")
def evaluate_classifier_command(
    data: Annotated[Path, typer.Option(help="Folder with vehicles/ and non-vehicles/ patches.")],
    model: Annotated[
        Path | None, typer.Option(help="Model file (default: the shipped one).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Accuracy, precision and recall of the classifier on folders of patches of any size."""
    from vehicles.dataset import load_patches
    from vehicles.model import load_model
    from vehicles.train import extract_features, scores

    classifier = load_model(model)
    patches = load_patches(data, classifier.config.patch_size)
    x = extract_features(patches.images, classifier.config)
    result = scores(patches.labels, classifier.predict(x))
    summary = {
        "accuracy": result["accuracy"],
        "precision": result["precision"],
        "recall": result["recall"],
        "n_vehicles": int((patches.labels == 1).sum()),
        "n_non_vehicles": int((patches.labels == 0).sum()),
    }
    report = classifier.report
    if (report.get("n_vehicles"), report.get("n_non_vehicles")) == (
        summary["n_vehicles"],
        summary["n_non_vehicles"],
    ):
        typer.echo(
            f"note: {data} holds as many vehicles and non-vehicles as the model was trained on: "
            "it is probably the training set, so these figures overstate accuracy; score a "
            "held-out folder, or see the grouped-split figures of 'roadview train'",
            err=True,
        )
    if as_json:
        typer.echo(json.dumps(summary))
    else:
        (tn, fp), (fn, tp) = result["confusion_matrix"]
        typer.echo(
            f"accuracy {100 * summary['accuracy']:.2f} %, precision {summary['precision']:.4f}, "
            f"recall {summary['recall']:.4f}\nvehicles {summary['n_vehicles']}: {tp} found, "
            f"{fn} missed; non-vehicles {summary['n_non_vehicles']}: {tn} rejected, {fp} false "
            "alarms"
        )


def _verbose(argv: list[str]) -> bool:
    """Whether --verbose/-v stands before the command name."""
    for arg in argv:
        if arg in ("--verbose", "-v"):
            return True
        if not arg.startswith("-"):
            return False
    return False


def main() -> None:
    """Entry point: run the CLI, turning expected failures into one line and a non-zero exit."""
    verbose = _verbose(sys.argv[1:])
    tune_process()
    try:
        cli()
    except USER_ERRORS as error:
        if verbose:
            traceback.print_exc()
        typer.echo(f"roadview: error: {describe(error)}", err=True)
        sys.exit(2)
    except Interrupted as interrupted:
        typer.echo(f"roadview: interrupted; {interrupted}", err=True)
        sys.exit(130)
    except KeyboardInterrupt:
        typer.echo("roadview: interrupted; no output was written", err=True)
        sys.exit(130)
    except SystemExit as exit_:
        if exit_.code == 130:  # typer turns Ctrl-C into a silent exit 130
            typer.echo("roadview: interrupted; no output was written", err=True)
        raise
    except Exception as error:
        if verbose:
            traceback.print_exc()
        typer.echo(
            f"roadview: unexpected {type(error).__name__}: {error} "
            "(rerun with --verbose for details)",
            err=True,
        )
        sys.exit(1)
