"""`roadview batch`: many videos on Dask's distributed scheduler, resumable, with a Parquet table.

Each video is one Dask task that runs the same pipeline as `roadview process`, in-process (no
forked helpers inside a Dask worker); parallelism comes from many videos at once. A task writes its
video, its JSON-lines record and its rows of the frame and vehicle tables atomically; the driver
keeps the manifest (one row per input) up to date after every finished task, so an interrupted
run resumes where it stopped.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from app.atomic import atomic_output
from app.errors import InputError

VIDEO_SUFFIXES = frozenset(
    {".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm", ".ts", ".mts", ".flv", ".wmv", ".mpg"}
)
TABLE = "table"  # DIR/table/{frames,vehicles}/*.parquet and DIR/table/manifest.parquet


@dataclass(frozen=True)
class BatchInput:
    """One input video and where its outputs go, relative to the output folder."""

    path: Path
    relative: Path  # the input's path below the folder it was found in (or its name)


@dataclass(frozen=True)
class BatchOptions:
    """What every task does (the same for every video of a run)."""

    out: Path
    video: bool = True
    calibration: str | None = None  # a calibration file, or None for no undistortion
    model: str | None = None  # None: the shipped model


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


def outputs_of(entry: BatchInput, out: Path) -> tuple[Path, Path]:
    """The annotated video and the record of one input, mirroring its relative path."""
    base = out / entry.relative
    return base.with_name(f"{base.stem}_roadview.mp4"), base.with_name(f"{base.stem}.jsonl")


def _key(entry: BatchInput) -> str:
    """File name of the input's table parts: its relative path, flattened."""
    return hashlib.blake2b(str(entry.relative).encode(), digest_size=8).hexdigest()


def process_one(entry: BatchInput, options: BatchOptions, size: int, digest: str) -> ManifestRow:
    """Run one video (inside a Dask worker); a bad input becomes a failed row, never an error."""
    started = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        frames, seconds = _run_video(entry, options)
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
        )
    except InputError as error:
        message = str(error)
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
    )


def _run_video(entry: BatchInput, options: BatchOptions) -> tuple[int, float]:
    """Process one video as `roadview process` does, then write its table parts."""
    from app.assembly import build_stages, make_compositor
    from app.pipeline import Pipeline, process_video
    from app.runtime import tune_process
    from camera_cal import load_calibration

    tune_process()
    video, record = outputs_of(entry, options.out)
    table = options.out / TABLE
    targets = [
        video,
        record,
        *(table / t / f"{_key(entry)}.parquet" for t in ("frames", "vehicles")),
    ]
    for target in targets:  # a killed earlier try leaves its temporary files: remove them
        for stale in target.parent.glob(f".{target.stem}.*.tmp{target.suffix}"):
            stale.unlink(missing_ok=True)
    calibration = load_calibration(Path(options.calibration)) if options.calibration else None
    stages = build_stages(model=Path(options.model) if options.model else None)
    with Pipeline(calibration, stages=stages) as pipeline:
        summary = process_video(
            entry.path, video if options.video else None, pipeline, record, make_compositor()
        )
    rows = [json.loads(line) for line in record.read_text().splitlines()]
    write_table_parts(options.out / TABLE, _key(entry), str(entry.relative), rows)
    span = rows[-1]["time_s"] - rows[0]["time_s"] if len(rows) > 1 else 0.0
    fps = (len(rows) - 1) / span if span > 0 else 25.0
    return summary.frames, summary.frames / fps


def write_table_parts(table: Path, key: str, video: str, rows: list[dict[str, Any]]) -> None:
    """One input's rows of the frames and vehicles tables, each an atomically written Parquet."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    frames = pa.table(
        {
            "video": [video] * len(rows),
            "frame": [r["frame"] for r in rows],
            "time_s": [r["time_s"] for r in rows],
            "lane_found": [r.get("lane") is not None for r in rows],
            "curvature_m": [(r.get("lane") or {}).get("curvature_m") for r in rows],
            "offset_m": [(r.get("lane") or {}).get("offset_m") for r in rows],
            "vehicles": [len(r.get("vehicles", [])) for r in rows],
        },
        schema=pa.schema(
            [
                ("video", pa.string()),
                ("frame", pa.int64()),
                ("time_s", pa.float64()),
                ("lane_found", pa.bool_()),
                ("curvature_m", pa.float64()),
                ("offset_m", pa.float64()),
                ("vehicles", pa.int64()),
            ]
        ),
    )
    found = [(r["frame"], v) for r in rows for v in r.get("vehicles", [])]
    vehicles = pa.table(
        {
            "video": [video] * len(found),
            "frame": [f for f, _ in found],
            "id": [v["id"] for _, v in found],
            "x1": [v["box"][0] for _, v in found],
            "y1": [v["box"][1] for _, v in found],
            "x2": [v["box"][2] for _, v in found],
            "y2": [v["box"][3] for _, v in found],
            "score": [v["score"] for _, v in found],
        },
        schema=pa.schema(
            [
                ("video", pa.string()),
                ("frame", pa.int64()),
                ("id", pa.int64()),
                ("x1", pa.float64()),
                ("y1", pa.float64()),
                ("x2", pa.float64()),
                ("y2", pa.float64()),
                ("score", pa.float64()),
            ]
        ),
    )
    for name, data in (("frames", frames), ("vehicles", vehicles)):
        with atomic_output(table / name / f"{key}.parquet") as tmp:
            pq.write_table(data, tmp)


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


def run_batch(
    entries: list[BatchInput],
    options: BatchOptions,
    client: Any,
    force: bool = False,
    on_row: Callable[[ManifestRow], None] = lambda row: None,
) -> BatchSummary:
    """Submit every input not already done to the Dask `client` and keep the manifest current."""
    from distributed import as_completed

    table = options.out / TABLE
    earlier = read_manifest(table)
    manifest: dict[str, ManifestRow] = dict(earlier)
    started = time.perf_counter()
    futures = []
    skipped = 0
    for entry in entries:
        size = entry.path.stat().st_size if entry.path.exists() else 0
        digest = fingerprint(entry.path) if entry.path.is_file() else ""
        old = earlier.get(str(entry.path))
        video, record = outputs_of(entry, options.out)
        if (
            not force
            and old is not None
            and old.status in ("done", "skipped")
            and old.fingerprint == digest
            and record.exists()
            and (video.exists() or not options.video)
        ):
            manifest[str(entry.path)] = ManifestRow(**{**asdict(old), "status": "skipped"})
            skipped += 1
            continue
        futures.append(
            client.submit(
                process_one, entry, options, size, digest, key=f"video-{_key(entry)}", pure=False
            )
        )
    done = failed = frames = 0
    video_seconds = 0.0
    try:
        for future in as_completed(futures):
            row: ManifestRow = future.result()
            manifest[row.path] = row
            write_manifest(table, manifest.values())
            if row.status == "done":
                done += 1
                frames += row.frames
                video_seconds += row.video_seconds
            else:
                failed += 1
            on_row(row)
    finally:
        for future in futures:
            future.cancel()
        write_manifest(table, manifest.values()) if manifest else None
    return BatchSummary(done, failed, skipped, video_seconds, frames, time.perf_counter() - started)


def iter_rows(summary: BatchSummary) -> Iterator[str]:
    """The closing summary, line by line."""
    rate = summary.frames / summary.wall_seconds if summary.wall_seconds > 0 else 0.0
    yield (
        f"videos: {summary.done} done, {summary.failed} failed, {summary.skipped} skipped; "
        f"{summary.video_seconds / 3600:.3f} h of video in {summary.wall_seconds:.1f} s "
        f"({rate:.1f} frames/s)"
    )
