"""Where a command's outputs go: default names, containers, and checks before anything is written.

Every output path is checked against the input and against the other outputs up front, so a
mistyped option can never overwrite the input or make one output replace another.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from app.errors import InputError
from app.sinks import CONTAINERS
from app.sources import IMAGE_SUFFIXES, check_input, is_image


@dataclass(frozen=True)
class Outputs:
    """The files one `process` run writes."""

    media: Path
    record: Path | None
    events: Path | None = None


def _same_path(a: Path, b: Path) -> bool:
    """Whether two paths name the same file (links and relative spellings included)."""
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def default_output(source: Path, log: Callable[[str], None]) -> Path:
    """NAME_roadview.EXT beside the input; .mp4 when roadview cannot write the input's container."""
    suffix = source.suffix.lower()
    if not is_image(source) and suffix not in CONTAINERS:
        log(f"note: roadview does not write {suffix or 'suffix-less'} videos; writing .mp4")
        suffix = ".mp4"
    return source.with_name(f"{source.stem}_roadview{suffix}")


def _check_writable_target(path: Path, what: str, option: str) -> None:
    """A file can be created at `path`: not a folder, in a folder that exists or can be made."""
    if path.is_dir():
        raise InputError(f"{what} {path} is a folder; pass a file name with {option}")
    folder = path.parent
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(
            f"cannot create the {what} folder {folder}: {existing} is a file; fix {option}"
        )
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"cannot write {what} {path}: {existing} is not writable; fix {option}")


def plan_outputs(
    source: Path,
    output: Path | None,
    record: Path | None,
    log: Callable[[str], None] = lambda message: None,
    events: Path | None = None,
) -> Outputs:
    """The output files of `process SOURCE [-o OUTPUT] [--json RECORD] [--events EVENTS]`, or an
    InputError.

    `-o` naming an existing folder puts the default name inside it.
    """
    still = is_image(source)
    if output is None:
        output = default_output(source, log)
    elif output.is_dir():
        output = output / default_output(source, log).name
    suffix = output.suffix.lower()
    if still and suffix not in IMAGE_SUFFIXES:
        raise InputError(
            f"output {output} is not an image name but the input is a still; "
            "use a .png or .jpg name with -o"
        )
    if not still and is_image(output):
        raise InputError(
            f"output {output} is an image name but the input is a video; use an .mp4 name with -o"
        )
    if not still and suffix not in CONTAINERS:
        names = ", ".join(sorted(CONTAINERS))
        raise InputError(
            f"roadview cannot write a {suffix or 'suffix-less'} video ({output}); "
            f"name the output with one of {names}"
        )
    _check_writable_target(output, "output", "-o")
    if _same_path(output, source):
        raise InputError(f"output {output} is the input; choose another -o")
    if record is not None:
        _check_writable_target(record, "record", "--json")
        if _same_path(record, source):
            raise InputError(f"--json {record} is the input; choose another record name")
        if _same_path(record, output):
            raise InputError(f"--json {record} is also the -o output; give them different names")
    if events is not None:
        if still:
            raise InputError("--events needs a video (events take time); drop it for a still")
        _check_writable_target(events, "events file", "--events")
        for other, option in ((source, "the input"), (output, "the -o output"), (record, "--json")):
            if other is not None and _same_path(events, other):
                raise InputError(f"--events {events} is also {option}; give it another name")
    return Outputs(output, record, events)


def check_lead(after: Path, source: Path) -> None:
    """`--after PREV` must name an existing video other than the input, itself a video."""
    check_input(after)
    if is_image(source):
        raise InputError("--after needs a video (a part of a drive); drop it for a still")
    if is_image(after):
        raise InputError(f"--after {after} is a still; give the video this one goes on from")
    if _same_path(after, source):
        raise InputError(f"--after {after} is the input; give the video before it")


def check_after(after: Path, source: Path, outputs: Outputs, start_s: float) -> None:
    """`process --after PREV` as `check_lead` says, naming none of the outputs, and with a
    video processed from its start (the lead-in is what comes before that)."""
    check_lead(after, source)
    named = ((outputs.media, "-o"), (outputs.record, "--json"), (outputs.events, "--events"))
    for path, option in named:
        if path is not None and _same_path(after, path):
            raise InputError(f"{option} {path} is the --after video; choose another {option}")
    if start_s > 0:
        raise InputError(
            "--after runs the video before this one's start; it cannot go with --start"
        )


def check_debug_folder(folder: Path, source: Path) -> None:
    """The debug mode's folder must not be the input or an existing file."""
    if _same_path(folder, source):
        raise InputError(f"--out {folder} is the input; choose a folder name")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--out {folder} is a file; choose a folder name")
    _check_writable_target(folder / "index.html", "debug folder", "--out")


def check_report_output(output: Path, inputs: list[Path]) -> None:
    """The report's page must be an .html file that is none of its inputs."""
    if output.suffix.lower() not in (".html", ".htm"):
        raise InputError(f"report {output} is not an .html name; pass one with -o")
    _check_writable_target(output, "report", "-o")
    for path in inputs:
        if _same_path(output, path):
            raise InputError(f"report {output} is also the input {path}; choose another -o")
