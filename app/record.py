"""The per-frame JSON-lines record: one object per frame, in undistorted-frame pixels."""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TextIO

from app.errors import InputError
from app.stages import StageResult


def frame_record(
    index: int, time_s: float, size: tuple[int, int], results: Mapping[str, StageResult]
) -> dict[str, Any]:
    """The record object for one frame; a stage that did not run has no field at all.

    The fields are documented in README ("The record") and in `record.schema.json`.
    """
    record: dict[str, Any] = {"frame": index, "time_s": round(time_s, 4), "size": list(size)}
    for key, result in results.items():
        record[key] = result.to_record()
    return record


def write_record_line(handle: TextIO, record: Mapping[str, Any]) -> None:
    """Append one compact JSON line."""
    handle.write(json.dumps(record, separators=(",", ":")))
    handle.write("\n")


def read_record(path: Path) -> Iterator[dict[str, Any]]:
    """Frame objects of a record file, with a clear error on a malformed line."""
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as error:
        raise InputError(
            f"cannot read record {path} ({error.strerror}); make one with 'roadview process --json'"
        ) from None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError:
            raise InputError(
                f"{path}:{number} is not a JSON line; pass a record "
                "written by 'roadview process --json'"
            ) from None
        if not isinstance(obj, dict) or "frame" not in obj:
            raise InputError(f"{path}:{number} has no 'frame' field; not a roadview record")
        yield obj
