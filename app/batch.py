"""`roadview batch`: many videos on Dask's distributed scheduler, resumable, with a Parquet table.

Each video is one Dask task that runs the same pipeline as `roadview process`, in-process (no
forked helpers inside a Dask worker); parallelism comes from many videos at once. A task writes its
video, its JSON-lines record and its rows of the frame and vehicle tables atomically; the driver
keeps the manifest (one row per input) up to date after every finished task, so an interrupted
run resumes where it stopped.
"""

from __future__ import annotations

import functools
import hashlib
import os
import socket
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from app.errors import USER_ERRORS, InputError, Interrupted, describe
from app.events import event_record, seen_from_behind
from app.mounting import Mounting
from app.progress import Progress
from app.sinks import atomic_output

if TYPE_CHECKING:
    from vehicles.model import VehicleModel

VIDEO_SUFFIXES = frozenset(
    {".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm", ".ts", ".mts", ".flv", ".wmv", ".mpg"}
)
TABLE = "table"  # DIR/table/{frames,vehicles,events}/*.parquet and DIR/table/manifest.parquet
PARTS = ("frames", "vehicles", "events")


@dataclass(frozen=True)
class BatchInput:
    """One input video and where its outputs go, relative to the output folder."""

    path: Path
    relative: Path  # the input's path below the folder it was found in (or its name)
    # The video this one goes on from (`process --after`; see `in_drives`), or None.
    after: Path | None = None


@dataclass(frozen=True)
class BatchOptions:
    """What every task does (the same for every video of a run)."""

    out: Path
    video: bool = True
    calibration: str | None = None  # a calibration file, or None for no undistortion
    # The user named the calibration: a video it does not fit fails; else it is processed
    # without undistortion (see `app.drivers.calibration_for`).
    calibration_required: bool = True
    model: str | None = None  # None: the shipped model
    # The cameras' height, the traffic's side and the pictures' turn (see `process`).
    mounting: Mounting = field(default_factory=Mounting)
    max_size: int = 0  # videos with a longer shorter side are processed at it (see `process`)


@dataclass(frozen=True)
class ManifestRow:
    """One input's row of the manifest."""

    path: str
    size: int
    fingerprint: str
    status: str  # done / failed / skipped
    error: str
    frames: int
    video_seconds: float
    processing_seconds: float
    worker: str
    notes: str = ""  # what `process` would have said of the input (one note a line)
    settings: str = ""  # `settings_digest` of the run that made the outputs


def find_inputs(items: Iterable[Path]) -> list[BatchInput]:
    """Videos named by files, folders (searched recursively) or text files listing paths."""
    found: dict[Path, BatchInput] = {}
    for item in items:
        if item.is_dir():
            for path in sorted(p for p in item.rglob("*") if p.suffix.lower() in VIDEO_SUFFIXES):
                found.setdefault(path.resolve(), BatchInput(path, path.relative_to(item)))
        elif item.suffix.lower() == ".txt" and item.is_file():
            for line in item.read_text().splitlines():
                if line.strip() and not line.lstrip().startswith("#"):
                    path = (item.parent / line.strip()).resolve()
                    found.setdefault(path, BatchInput(path, Path(path.name)))
        elif item.exists():
            found.setdefault(item.resolve(), BatchInput(item, Path(item.name)))
        else:
            raise InputError(
                f"input {item} does not exist; pass video files, folders or a .txt list"
            )
    relatives = [entry.relative for entry in found.values()]
    if len(set(relatives)) != len(relatives):
        raise InputError(
            "two inputs would write the same outputs (same name in different places); pass "
            "their common parent folder instead"
        )
    return list(found.values())


def in_drives(entries: Sequence[BatchInput]) -> list[BatchInput]:
    """The inputs as parts of drives, as a dashcam splits one into files a minute or a few long:
    each goes on from the one before it in name order in its folder (`BatchInput.after`)."""
    chained: list[BatchInput] = []
    last_in: dict[Path, BatchInput] = {}
    for entry in sorted(entries, key=lambda e: (str(e.path.parent), e.path.name)):
        before = last_in.get(entry.path.parent)
        chained.append(replace(entry, after=None if before is None else before.path))
        last_in[entry.path.parent] = entry
    return chained


def fingerprint(path: Path, chunk: int = 1 << 20) -> str:
    """A content fingerprint: size and the first, middle and last MiB (hashing hours of video in
    full would cost more than it guards against)."""
    size = path.stat().st_size
    digest = hashlib.blake2b(str(size).encode(), digest_size=16)
    with path.open("rb") as handle:
        for offset in (0, max(0, size // 2 - chunk // 2), max(0, size - chunk)):
            handle.seek(offset)
            digest.update(handle.read(chunk))
    return digest.hexdigest()


def settings_digest(options: BatchOptions, entry: BatchInput) -> str:
    """What an input's outputs hang on besides its own content: the options that change them
    (the calibration's and the vehicle model's files by content, whether the calibration must
    fit, the mounting, the size limit) and the part of a drive it goes on from. An input done
    with other settings is done again rather than skipped."""
    from vehicles.model import default_model_path

    model = Path(options.model) if options.model else default_model_path()
    calibration = Path(options.calibration) if options.calibration else None
    parts = [repr(options.mounting), str(options.max_size), str(options.calibration_required)]
    for path in (calibration, model, entry.after):
        parts.append(f"{path}:{fingerprint(path)}" if path and path.is_file() else str(path))
    return hashlib.blake2b("\n".join(parts).encode(), digest_size=16).hexdigest()


def outputs_of(entry: BatchInput, out: Path) -> tuple[Path, Path]:
    """The annotated video and the record of one input, mirroring its relative path."""
    base = out / entry.relative
    return base.with_name(f"{base.stem}_roadview.mp4"), base.with_name(f"{base.stem}.jsonl")


def remove_temporaries(entry: BatchInput, out: Path) -> None:
    """Delete the temporary files an interrupted or killed task left for this input's outputs."""
    video, record = outputs_of(entry, out)
    parts = [out / TABLE / t / f"{_key(entry)}.parquet" for t in PARTS]
    for target in (video, record, *parts):
        for stale in target.parent.glob(f".{target.stem}.*.tmp{target.suffix}"):
            stale.unlink(missing_ok=True)


def _key(entry: BatchInput) -> str:
    """File name of the input's table parts: its relative path, flattened."""
    return hashlib.blake2b(str(entry.relative).encode(), digest_size=8).hexdigest()


def process_one(
    entry: BatchInput, options: BatchOptions, size: int, digest: str, settings: str = ""
) -> ManifestRow:
    """Run one video (inside a Dask worker); a bad input becomes a failed row, never an error."""
    started = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        frames, seconds, notes = _run_video(entry, options)
        return ManifestRow(
            str(entry.path),
            size,
            digest,
            "done",
            "",
            frames,
            seconds,
            time.perf_counter() - started,
            worker,
            "\n".join(notes),
            settings,
        )
    except USER_ERRORS as error:
        message = describe(error)
    except Exception as error:  # any failure of one input must not stop the others
        message = f"unexpected {type(error).__name__}: {error}"
    return ManifestRow(
        str(entry.path),
        size,
        digest,
        "failed",
        message,
        0,
        0.0,
        time.perf_counter() - started,
        worker,
        settings=settings,
    )


@functools.cache
def _classifier(model: str | None) -> VehicleModel:
    """The vehicle model, loaded once per worker process (0.15 s saved on every later video)."""
    from vehicles.model import load_model

    return load_model(Path(model) if model else None)


def _run_video(entry: BatchInput, options: BatchOptions) -> tuple[int, float, list[str]]:
    """Process one video as `roadview process` does, then write its table parts; its frames,
    seconds and the notes `process` would print (another camera, no colour, cuts, the height
    the lanes imply)."""
    from app.annotators import default_annotators
    from app.assembly import build_stages
    from app.drivers import process_video
    from app.record import read_record
    from app.runtime import tune_process
    from camera_cal import load_calibration

    tune_process()
    remove_temporaries(entry, options.out)  # a killed earlier try leaves them behind
    video, record = outputs_of(entry, options.out)
    calibration = load_calibration(Path(options.calibration)) if options.calibration else None
    stages = build_stages(classifier=_classifier(options.model))
    notes: list[str] = []
    # In-process: a Dask worker must not fork helpers; parallelism comes from many videos.
    summary = process_video(
        entry.path,
        video if options.video else None,
        calibration,
        *stages,
        record,
        default_annotators(),
        vehicles_in_worker=False,
        calibration_required=options.calibration_required,
        max_size=options.max_size,
        mounting=options.mounting,
        log=notes.append,
        after=entry.after,
    )
    # The tables are made from the record, so they say exactly what `process` would record.
    rows = list(read_record(record))
    events = [event_record(e) for e in summary.events]
    write_table_parts(options.out / TABLE, _key(entry), str(entry.relative), rows, events)
    return summary.frames, summary.video_seconds, notes


def _schema(*columns: tuple[str, str]) -> Any:
    import pyarrow as pa

    return pa.schema([(name, pa.type_for_alias(kind)) for name, kind in columns])


# The queryable tables: one row per frame, one per shown vehicle in a frame, one per event.
FRAME_COLUMNS = (
    ("video", "string"),
    ("frame", "int64"),
    ("time_s", "double"),
    ("shot", "int64"),
    ("lane_found", "bool"),
    ("curvature_m", "double"),
    ("offset_m", "double"),
    ("vehicles", "int64"),
    ("speed_kmh", "double"),
    ("headway_s", "double"),
    ("ttc_s", "double"),
    ("road_grey", "double"),
    ("grain", "double"),
    ("monochrome", "bool"),  # read by the grey models (the record's monochrome)
    ("horizon_y", "double"),
    ("ground_scale", "double"),
    ("length_scale", "double"),  # the road's length per metre of the view, from the dashes
    ("dash_m", "double"),  # the lane dashes' spacing as the view read it (null: not read)
    ("rear", "bool"),  # a rear camera's frame (the record's facing)
    ("roll_deg", "double"),  # the turn the frame was levelled by (stated or read; 0: none)
    ("focal_mm", "double"),  # the lens's focal length where it gave the distances (null: none)
    ("rotate_deg", "int64"),  # the quarter turn that stood the stored picture upright (0: none)
)
VEHICLE_COLUMNS = (
    ("video", "string"),
    ("frame", "int64"),
    ("id", "int64"),
    ("x1", "double"),
    ("y1", "double"),
    ("x2", "double"),
    ("y2", "double"),
    ("score", "double"),
    ("distance_m", "double"),
    ("lateral_m", "double"),
    ("lane", "string"),
    ("closing_mps", "double"),
)
EVENT_COLUMNS = (
    ("video", "string"),
    ("kind", "string"),
    ("start_s", "double"),
    ("end_s", "double"),
    ("start_frame", "int64"),
    ("end_frame", "int64"),
    ("vehicle_id", "int64"),
    ("worst", "double"),
)


def write_table_parts(
    table: Path,
    key: str,
    video: str,
    rows: list[dict[str, Any]],
    events: Sequence[dict[str, Any]] = (),
) -> None:
    """One input's rows of the frames, vehicles and events tables, each an atomically written
    Parquet file; `rows` are its record's lines, `events` its event records."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    frames = [
        {
            "video": video,
            "frame": r["frame"],
            "time_s": r["time_s"],
            "shot": r.get("shot", 0),
            "lane_found": r.get("lane") is not None,
            "curvature_m": (r.get("lane") or {}).get("curvature_m"),
            "offset_m": (r.get("lane") or {}).get("offset_m"),
            "vehicles": len(r.get("vehicles", [])),
            "speed_kmh": r.get("speed_kmh"),
            "headway_s": r.get("headway_s"),
            "ttc_s": r.get("ttc_s"),
            "road_grey": r.get("road_grey"),
            "grain": r.get("grain"),
            "monochrome": bool(r.get("monochrome")),
            "horizon_y": r.get("horizon_y"),
            "ground_scale": r.get("ground_scale"),
            "length_scale": r.get("length_scale"),
            "dash_m": r.get("dash_m"),
            "rear": seen_from_behind(r),
            "roll_deg": r.get("roll_deg", 0.0),
            "focal_mm": r.get("focal_mm"),
            "rotate_deg": r.get("rotate_deg", 0),
        }
        for r in rows
    ]
    facts = ("distance_m", "lateral_m", "lane", "closing_mps")
    vehicles = [
        {"video": video, "frame": r["frame"], "id": v["id"], "score": v["score"]}
        | dict(zip(("x1", "y1", "x2", "y2"), v["box"], strict=True))
        | {name: v.get(name) for name in facts}
        for r in rows
        for v in r.get("vehicles", [])
    ]
    for name, data, columns in (
        ("frames", frames, FRAME_COLUMNS),
        ("vehicles", vehicles, VEHICLE_COLUMNS),
        ("events", [{"video": video} | e for e in events], EVENT_COLUMNS),
    ):
        with atomic_output(table / name / f"{key}.parquet") as tmp:
            pq.write_table(pa.Table.from_pylist(data, schema=_schema(*columns)), tmp)


def current_table_parts(table: Path, key: str, video: str, record: Path) -> bool:
    """Rewrite an input's table parts that an older roadview wrote with other columns (a
    resumed run skips the input; its parts must share the others' columns, or a query over the
    folder fails or drops a column): frames and vehicles from its record, events from their
    own part. Whether any was rewritten."""
    import pyarrow.parquet as pq

    from app.record import read_record

    columns = {"frames": FRAME_COLUMNS, "vehicles": VEHICLE_COLUMNS, "events": EVENT_COLUMNS}
    parts = {name: table / name / f"{key}.parquet" for name in columns}
    stale = [
        name
        for name, path in parts.items()
        if path.exists() and pq.read_schema(path).names != [c for c, _ in columns[name]]
    ]
    if not stale:
        return False
    rows = list(read_record(record))
    events = []
    if parts["events"].exists():
        events = [
            {k: v for k, v in e.items() if k != "video"}
            for e in pq.read_table(parts["events"]).to_pylist()
        ]
    write_table_parts(table, key, video, rows, events)
    return True


def read_manifest(table: Path) -> dict[str, ManifestRow]:
    """The manifest of an earlier run, by input path (empty when there is none)."""
    path = table / "manifest.parquet"
    if not path.exists():
        return {}
    import pyarrow.parquet as pq

    return {r["path"]: ManifestRow(**r) for r in pq.read_table(path).to_pylist()}


def write_manifest(table: Path, rows: Iterable[ManifestRow]) -> None:
    """The manifest, written atomically (it is rewritten after every finished input)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = pa.Table.from_pylist([asdict(r) for r in rows])
    with atomic_output(table / "manifest.parquet") as tmp:
        pq.write_table(data, tmp)


@dataclass(frozen=True)
class BatchSummary:
    """What a batch run did."""

    done: int
    failed: int
    skipped: int
    video_seconds: float
    frames: int
    wall_seconds: float


@contextmanager
def dask_client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A client of the scheduler at `scheduler`, or of a local cluster of `workers` processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as error:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({error})") from None
        with client:
            yield client
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise InputError("--workers must be at least 1")
    cluster = LocalCluster(
        n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    with cluster, Client(cluster) as client:
        yield client


def run_batch(
    entries: list[BatchInput],
    options: BatchOptions,
    scheduler: str | None = None,
    workers: int | None = None,
    force: bool = False,
    log: Callable[[str], None] = lambda message: None,
) -> BatchSummary:
    """Run every input not already done on Dask, keeping the manifest current after each one.

    Ctrl-C cancels what is left, keeps what finished (the manifest says which) and raises
    `Interrupted`; the next run resumes.
    """
    table = options.out / TABLE
    earlier = read_manifest(table)
    manifest: dict[str, ManifestRow] = dict(earlier)
    started = time.perf_counter()
    todo: list[tuple[BatchInput, int, str, str]] = []
    skipped = 0
    for entry in entries:
        size = entry.path.stat().st_size if entry.path.exists() else 0
        digest = fingerprint(entry.path) if entry.path.is_file() else ""
        old = earlier.get(str(entry.path))
        settings = settings_digest(options, entry)
        video, record = outputs_of(entry, options.out)
        if (
            not force
            and old is not None
            and old.status in ("done", "skipped")
            and old.fingerprint == digest
            and old.settings == settings
            and record.exists()
            and (video.exists() or not options.video)
        ):
            manifest[str(entry.path)] = ManifestRow(**{**asdict(old), "status": "skipped"})
            current_table_parts(table, _key(entry), str(entry.relative), record)
            skipped += 1
        else:
            todo.append((entry, size, digest, settings))
    # Largest first: a long video started last would leave the other workers idle at the end.
    todo.sort(key=lambda item: -item[1])
    progress = BatchProgress([size for _, size, _, _ in todo])
    done = failed = frames = 0
    video_seconds = 0.0
    finished: set[str] = set()
    interrupted = False
    try:
        with dask_client(scheduler, workers) as client:
            from distributed import as_completed

            log(f"dashboard: {client.dashboard_link}")
            futures = [
                client.submit(
                    process_one,
                    entry,
                    options,
                    size,
                    digest,
                    settings,
                    key=f"video-{_key(entry)}",
                    pure=False,
                )
                for entry, size, digest, settings in todo
            ]
            try:
                for future in as_completed(futures):
                    row: ManifestRow = future.result()
                    manifest[row.path] = row
                    finished.add(row.path)
                    write_manifest(table, manifest.values())
                    if row.status == "done":
                        done += 1
                        frames += row.frames
                        video_seconds += row.video_seconds
                    else:
                        failed += 1
                        progress.note(f"failed {row.path}: {row.error}")
                    progress.finished(row)
            except KeyboardInterrupt:
                interrupted = True
                client.cancel(futures)
    except KeyboardInterrupt:  # a second Ctrl-C while the cluster shuts down
        interrupted = True
    finally:
        progress.close()
        if manifest:
            write_manifest(table, manifest.values())
    if interrupted:
        for entry, _, _, _ in todo:  # the cluster is closed: nothing writes these any more
            if str(entry.path) not in finished:
                remove_temporaries(entry, options.out)
        raise Interrupted(
            f"{done + failed} of {len(todo)} videos finished and are kept in {options.out}; "
            "run the same command again to resume"
        )
    return BatchSummary(done, failed, skipped, video_seconds, frames, time.perf_counter() - started)


class BatchProgress:
    """One bar over all inputs: videos done, frames per second of the whole cluster, and time
    left (from the bytes still to process, since videos differ in length)."""

    def __init__(self, sizes: list[int], stream: TextIO | None = None) -> None:
        self.bar = Progress(len(sizes), label="videos", stream=stream)
        self.bytes_total = max(sum(sizes), 1)
        self.bytes_done = 0
        self.frames = 0

    def finished(self, row: ManifestRow) -> None:
        """Count one finished input."""
        self.bytes_done += row.size
        self.frames += row.frames
        elapsed = time.perf_counter() - self.bar.started
        rate = self.frames / elapsed if elapsed > 0 else 0.0
        left = elapsed * (self.bytes_total - self.bytes_done) / max(self.bytes_done, 1)
        self.bar.update(detail=f"{rate:.1f} frames/s, {left:.0f} s left")

    def note(self, message: str) -> None:
        """A message on a line of its own, above the bar."""
        if self.bar.enabled:
            self.bar.stream.write("\r\033[K")
        self.bar.stream.write(message + "\n")
        self.bar.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        self.bar.close()


def summary_line(summary: BatchSummary) -> str:
    """The closing summary: counts, hours of video, throughput."""
    rate = summary.frames / summary.wall_seconds if summary.wall_seconds > 0 else 0.0
    return (
        f"videos: {summary.done} done, {summary.failed} failed, {summary.skipped} skipped; "
        f"{summary.video_seconds / 3600:.3f} h of video in {summary.wall_seconds:.1f} s "
        f"({rate:.1f} frames/s)"
    )
