"""Score a per-frame record against hand-made labels: vehicle matching by IoU, lane x errors."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from app.errors import InputError
from vehicles.detections import iou_matrix

Box = tuple[float, float, float, float]
LANE_ROWS = (670, 630, 590, 550, 510, 470)
LANE_TOLERANCE_PX = 20.0


@dataclass(frozen=True)
class LabelledVehicle:
    """A ground-truth vehicle box in one frame."""

    id: int
    box: Box
    ignore: bool


@dataclass(frozen=True)
class FrameLabels:
    """Ground truth of one frame: vehicles and lane boundary x per labelled row."""

    vehicles: tuple[LabelledVehicle, ...]
    lane: dict[str, dict[int, float]]  # side -> row -> x


def clip_frames(path: Path) -> int | None:
    """The labelled clip's length in frames (the labels file's `frames`), if it says."""
    try:
        frames = json.loads(Path(path).read_text()).get("frames")
    except (OSError, ValueError, AttributeError):
        return None
    return int(frames) if isinstance(frames, int) else None


def load_labels(path: Path) -> dict[int, FrameLabels]:
    """Labels of every frame between the first and last keyframe, interpolated as documented."""
    try:
        return load_labels_document(json.loads(Path(path).read_text()))
    except FileNotFoundError:
        raise InputError(f"labels file {path} does not exist; see data/labels/") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise InputError(f"{path} is not a labels file (see ../shared/data/README.md)") from None


def load_labels_document(document: Mapping[str, Any]) -> dict[int, FrameLabels]:
    """`load_labels` of a document already read."""
    keyframes = {int(k): v for k, v in document["keyframes"].items()}
    if not keyframes:
        return {}
    keys = sorted(keyframes)
    frames: dict[int, FrameLabels] = {k: _keyframe(keyframes[k]) for k in keys}
    for a, b in pairwise(keys):
        for frame in range(a + 1, b):
            frames[frame] = _interpolate(frames[a], frames[b], (frame - a) / (b - a))
    return frames


def _keyframe(raw: Mapping[str, Any]) -> FrameLabels:
    vehicles = tuple(
        LabelledVehicle(
            int(v["id"]),
            tuple(float(c) for c in v["box"]),  # type: ignore[arg-type]
            bool(v.get("ignore", False)),
        )
        for v in raw.get("vehicles", [])
    )
    lane_raw = raw.get("lane") or {}
    lane = {
        side: {int(row): float(x) for row, x in (lane_raw.get(side) or {}).items()}
        for side in ("left", "right")
    }
    return FrameLabels(vehicles, lane)


def _interpolate(a: FrameLabels, b: FrameLabels, t: float) -> FrameLabels:
    b_by_id = {v.id: v for v in b.vehicles}
    vehicles = []
    for va in a.vehicles:
        vb = b_by_id.get(va.id)
        if vb is None:
            continue
        box = tuple(float(x) for x in (1 - t) * np.asarray(va.box) + t * np.asarray(vb.box))
        vehicles.append(LabelledVehicle(va.id, box, va.ignore or vb.ignore))  # type: ignore[arg-type]
    lane = {
        side: {
            row: (1 - t) * x + t * b.lane[side][row]
            for row, x in a.lane[side].items()
            if row in b.lane[side]
        }
        for side in ("left", "right")
    }
    return FrameLabels(tuple(vehicles), lane)


def iou(a: Sequence[float], b: Sequence[float]) -> float:
    """Intersection over union of two [x1, y1, x2, y2] boxes."""
    return float(iou_matrix(np.asarray([a], np.float64), np.asarray([b], np.float64))[0, 0])


@dataclass(frozen=True)
class FrameMatch:
    """Outcome of matching one frame's detections at one IoU threshold."""

    true_positives: int
    false_positives: int
    false_negatives: int
    ious: tuple[float, ...]
    # (detection, labelled vehicle) index pairs of the true positives.
    pairs: tuple[tuple[int, int], ...] = ()


def match_frame(
    detections: Sequence[Sequence[float]], truth: Sequence[LabelledVehicle], threshold: float
) -> FrameMatch:
    """Greedy matching by IoU; a detection matched to an ignored vehicle counts neither way."""
    ious = iou_matrix(
        np.asarray(detections, np.float64).reshape(-1, 4),
        np.asarray([t.box for t in truth], np.float64).reshape(-1, 4),
    )
    pairs = sorted(
        ((float(ious[i, j]), i, j) for i in range(len(detections)) for j in range(len(truth))),
        reverse=True,
    )
    used_d: set[int] = set()
    used_t: set[int] = set()
    tp_ious: list[float] = []
    matched: list[tuple[int, int]] = []
    for value, i, j in pairs:
        if value < threshold:
            break
        if i in used_d or j in used_t:
            continue
        used_d.add(i)
        used_t.add(j)
        if not truth[j].ignore:
            tp_ious.append(value)
            matched.append((i, j))
    fp = len(detections) - len(used_d)
    fn = sum(1 for j, t in enumerate(truth) if not t.ignore and j not in used_t)
    return FrameMatch(len(tp_ious), fp, fn, tuple(tp_ious), tuple(matched))


def _lane_x(polyline: Sequence[Sequence[float]] | None, row: int) -> float | None:
    """x of a polyline at image row `row`, or None where the polyline does not reach it."""
    if not polyline or len(polyline) < 2:
        return None
    pts = np.asarray(polyline, dtype=np.float64)
    order = np.argsort(pts[:, 1])
    ys, xs = pts[order, 1], pts[order, 0]
    if row < ys[0] - 0.5 or row > ys[-1] + 0.5:
        return None
    return float(np.interp(row, ys, xs))


def coverage_problem(
    labels: Mapping[int, FrameLabels],
    records: Sequence[Mapping[str, Any]],
    clip_frames: int | None,
    warmup: int,
) -> str | None:
    """Why a record cannot be scored against these labels, or None when it can.

    A record must hold every labelled frame that is scored, must not run past the labelled clip's
    length, and every labelled box and lane point must lie inside its frames.
    """
    if not records:
        return "the record is empty; make one with 'roadview process VIDEO --json RECORD'"
    frames = sorted(int(r["frame"]) for r in records)
    scored = sorted(f for f in labels if f >= warmup)
    present = set(frames)
    missing = [f for f in scored if f not in present]
    if missing and frames[0] == 0 and clip_frames is not None and frames[-1] < clip_frames - 1:
        return (
            f"the record has frames 0-{frames[-1]} but the labelled clip has {clip_frames} "
            "frames; the record is of another video, or was cut short with --end"
        )
    if missing:
        return (
            f"the record holds frames {frames[0]}-{frames[-1]} but the labels score frames "
            f"{scored[0]}-{scored[-1]} ({len(missing)} of them missing); process the whole clip "
            "(no --start/--end) and evaluate again"
        )
    if clip_frames is not None and frames[-1] >= clip_frames:
        return (
            f"the record runs to frame {frames[-1]} but the labelled clip has {clip_frames} "
            "frames; the record is of another video"
        )
    sizes = {tuple(r["size"]) for r in records if "size" in r}
    if len(sizes) == 1:
        width, height = sizes.pop()
        xs = [c for f in scored for v in labels[f].vehicles for c in v.box[0::2]]
        ys = [c for f in scored for v in labels[f].vehicles for c in v.box[1::2]]
        xs += [x for f in scored for side in labels[f].lane.values() for x in side.values()]
        ys += [y for f in scored for side in labels[f].lane.values() for y in side]
        if (xs and max(xs) > width * 1.02) or (ys and max(ys) > height * 1.02):
            return (
                f"the labels reach x {max(xs, default=0):.0f}, y {max(ys, default=0):.0f} but the "
                f"record's frames are {width}x{height}; the record is of another size or video"
            )
    return None


def evaluate(
    labels: Mapping[int, FrameLabels],
    records: Iterable[Mapping[str, Any]],
    warmup: int = 10,
    thresholds: Sequence[float] = (0.5, 0.3),
) -> dict[str, Any]:
    """Vehicle and lane scores over the labelled frames from `warmup` on."""
    by_frame = {int(r["frame"]): r for r in records}
    scored = sorted(f for f in labels if f >= warmup)
    return {
        "frames_scored": len(scored),
        "warmup": warmup,
        # A stage that did not run (its field absent from every frame) is not scored.
        "vehicles": _vehicle_scores(labels, by_frame, scored, thresholds)
        if any("vehicles" in r for r in by_frame.values())
        else None,
        "lane": _lane_scores(labels, by_frame, scored)
        if any("lane" in r for r in by_frame.values())
        else None,
    }


def _vehicle_scores(
    labels: Mapping[int, FrameLabels],
    by_frame: Mapping[int, Mapping[str, Any]],
    scored: Sequence[int],
    thresholds: Sequence[float],
) -> dict[str, Any]:
    """Precision, recall, false positives per frame and mean IoU at each IoU threshold, and
    the id switches: how often a labelled vehicle is matched by a track of another id than
    at its last match (a vehicle that should keep one number while in view)."""
    vehicle_scores: dict[str, Any] = {}
    for threshold in thresholds:
        tp = fp = fn = switches = 0
        ious: list[float] = []
        last_id: dict[int, int] = {}  # labelled vehicle -> the track id that last matched it
        for frame in scored:
            found = by_frame.get(frame, {}).get("vehicles") or []
            truth = labels[frame].vehicles
            m = match_frame([v["box"] for v in found], truth, threshold)
            tp, fp, fn = tp + m.true_positives, fp + m.false_positives, fn + m.false_negatives
            ious.extend(m.ious)
            for i, j in m.pairs:
                track = int(found[i].get("id", -1))
                switches += last_id.get(truth[j].id, track) != track
                last_id[truth[j].id] = track
        vehicle_scores[f"iou_{threshold:g}"] = {
            "precision": tp / (tp + fp) if tp + fp else 1.0,
            "recall": tp / (tp + fn) if tp + fn else 1.0,
            "false_positives_per_frame": fp / len(scored) if scored else 0.0,
            "mean_iou": float(np.mean(ious)) if ious else 0.0,
            "true_positives": tp,
            "false_positives": fp,
            "false_negatives": fn,
            "id_switches": switches,
        }
    return vehicle_scores


def _lane_scores(
    labels: Mapping[int, FrameLabels],
    by_frame: Mapping[int, Mapping[str, Any]],
    scored: Sequence[int],
) -> dict[str, Any]:
    """Absolute x error of the lane boundaries per labelled row; a missing lane counts outside."""
    errors: dict[int, list[float]] = {row: [] for row in LANE_ROWS}
    missing = 0
    for frame in scored:
        lane = by_frame.get(frame, {}).get("lane")
        for side in ("left", "right"):
            for row, x_true in labels[frame].lane[side].items():
                x = _lane_x(lane.get(side) if lane else None, row)
                if x is None:
                    missing += 1
                else:
                    errors.setdefault(row, []).append(abs(x - x_true))
    all_errors = np.asarray([e for row_errors in errors.values() for e in row_errors])
    total = all_errors.size + missing
    lane_scores = {
        "points": int(total),
        "missing": missing,
        "mean_abs_error_px": float(all_errors.mean()) if all_errors.size else None,
        "p95_abs_error_px": float(np.percentile(all_errors, 95)) if all_errors.size else None,
        "share_within_20px": float((all_errors <= LANE_TOLERANCE_PX).sum() / total)
        if total
        else None,
        "rows": {
            str(row): {
                "mean_abs_error_px": float(np.mean(e)),
                "p95_abs_error_px": float(np.percentile(e, 95)),
                "points": len(e),
            }
            for row, e in sorted(errors.items(), reverse=True)
            if e
        },
    }
    return lane_scores


def format_report(scores: Mapping[str, Any]) -> str:
    """A short human-readable table of the scores."""
    lines = [f"frames scored: {scores['frames_scored']} (warm-up {scores['warmup']})"]
    lines.append("vehicles:" if scores["vehicles"] else "vehicles: not in the record")
    for name, v in (scores["vehicles"] or {}).items():
        lines.append(
            f"  {name:8s} precision {v['precision']:.3f}  recall {v['recall']:.3f}  "
            f"FP/frame {v['false_positives_per_frame']:.3f}  mean IoU {v['mean_iou']:.3f}  "
            f"(TP {v['true_positives']}, FP {v['false_positives']}, FN {v['false_negatives']}; "
            f"id switches {v['id_switches']})"
        )
    lane = scores["lane"]
    if lane is None:
        lines.append("lane: not in the record")
    elif lane["mean_abs_error_px"] is None:
        lines.append(f"lane: no lane points found ({lane['missing']} missing)")
    else:
        lines.append(
            f"lane: mean |dx| {lane['mean_abs_error_px']:.2f} px, "
            f"p95 {lane['p95_abs_error_px']:.2f} px, "
            f"within 20 px {100 * lane['share_within_20px']:.2f} % of {lane['points']} "
            f"points ({lane['missing']} missing)"
        )
        for row, r in lane["rows"].items():
            lines.append(
                f"  row {row}: mean {r['mean_abs_error_px']:.2f} px, "
                f"p95 {r['p95_abs_error_px']:.2f} px"
            )
    return "\n".join(lines)
