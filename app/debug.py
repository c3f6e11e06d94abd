"""Frame-stepping debug mode: every intermediate of chosen frames as PNGs plus a contact sheet."""

from __future__ import annotations

import html
import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from app.annotators import (
    BoxAnnotator,
    compose,
    default_annotators,
    draw_boxes,
    heat_picture,
    lane_inset,
    offset_words,
)
from app.drivers import camera_for, lead_in, sky_mounting, start_part
from app.errors import InputError
from app.pipeline import HORIZON_WAIT_S, FrameOutput, FrameResult, Pipeline
from app.sinks import ensure_writable_dir, write_image
from app.sources import (
    Frame,
    decoding_notes,
    probe_video,
    turned_info,
    within_size,
)
from camera_cal import SceneGeometry
from vehicles.detections import Detections
from vehicles.detector import VehicleResult

# Seconds run before the first chosen frame so history is as in a real run: an unknown camera's
# stages wait for the horizon, its bonnet is placed within a second, and burnt-in captions are
# found after 24 samples of every 5th frame (4-5 s of driving).
WARMUP_S = HORIZON_WAIT_S + 3.0
SCALE_COLORS = [(255, 80, 80), (255, 200, 0), (80, 255, 80), (0, 200, 255), (200, 80, 255)]
CROSSING_COLOR = (255, 140, 0)  # RGB: a pedestrian crossing's bars in the lane mask picture


def parse_frames(spec: str) -> tuple[int, int]:
    """'A:B' (B excluded) or 'A' as a half-open frame range."""
    try:
        if ":" in spec:
            a, b = spec.split(":", 1)
            first, last = int(a or 0), int(b)
        else:
            first = int(spec)
            last = first + 1
    except ValueError:
        raise InputError(f"--frames {spec!r} is not A:B (e.g. 10:20) or a frame number") from None
    if first < 0 or last <= first:
        raise InputError("--frames A:B needs 0 <= A < B")
    return first, last


def _boxes(frame: Frame, detections: Detections, color: tuple[int, int, int]) -> Frame:
    """A copy of the frame with the boxes drawn by the compositor's BoxAnnotator."""
    shown = FrameResult(vehicles=VehicleResult(detections))
    return compose(frame, shown, [BoxAnnotator(color)])


def scene_picture(
    frame: Frame,
    scene: SceneGeometry,
    roll_deg: float = 0.0,
    length: tuple[float, float | None] = (1.0, None),
) -> Frame:
    """The scene geometry on the frame: the live box (green; its bottom is labelled when a
    bonnet ends it), the horizon (blue: estimated from the footage; grey: the default or
    --horizon) with the ground scale once it moved from 1 and the turn the frame was levelled
    by (`roll_deg`, stated or read), the road's vanishing point on it (a circle, once
    estimated) and the road line under the camera upright below it (dashed: the lane offset
    and the vehicles' sides are measured from it), the boxes of burnt-in captions (red), the
    road's grey level and grain once measured (and that the picture is read as monochrome,
    where it is), and the lane dashes' spacing once read with the length scale it gives
    (`length`, as the record's `length_scale` and `dash_m`)."""
    picture = frame.copy()
    x0, y0, x1, y1 = scene.live
    cv2.rectangle(picture, (x0, y0), (x1 - 1, y1 - 1), (0, 255, 0), 2)
    y = round(scene.horizon_y)
    color = (40, 120, 255) if scene.estimated else (160, 160, 160)
    cv2.line(picture, (x0, y), (x1 - 1, y), color, 2, cv2.LINE_AA)
    label = "horizon (estimated)" if scene.estimated else "horizon (default)"
    if scene.ground_scale != 1.0:
        label += f", ground scale {scene.ground_scale:.2f}"
    if roll_deg:
        label += f", levelled by {roll_deg:g} deg"
    cv2.putText(picture, label, (x0 + 10, y - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.7, color, 2)
    if scene.vanishing_x is not None:
        x = round(scene.vanishing_x)
        cv2.circle(picture, (x, y), 9, color, 2, cv2.LINE_AA)
        for top in range(y + 20, y1, 30):  # dashes 15 px long
            cv2.line(picture, (x, top), (x, min(top + 15, y1 - 1)), color, 2)
        cv2.putText(picture, "camera", (x + 8, y1 - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.6, color, 2)
    for cx0, cy0, cx1, cy1 in scene.overlays:
        cv2.rectangle(picture, (cx0, cy0), (cx1 - 1, cy1 - 1), (255, 40, 40), 2)
        cv2.putText(
            picture, "caption", (cx0, cy0 - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 40, 40), 1
        )
    if scene.road_grey is not None and scene.grain is not None:
        light = f"road grey {scene.road_grey:.0f}, grain {scene.grain:.2f}"
        light += ", monochrome (grey models)" if scene.monochrome else ""
        cv2.putText(picture, light, (x0 + 10, y0 + 30), cv2.FONT_HERSHEY_SIMPLEX, 0.7, color, 2)
    scale, dash_m = length
    if dash_m is not None:
        dashes = f"lane dashes {dash_m:.1f} m apart, length scale {scale:.2f}"
        cv2.putText(picture, dashes, (x0 + 10, y0 + 60), cv2.FONT_HERSHEY_SIMPLEX, 0.7, color, 2)
    if scene.bonnet_y is not None:
        cv2.putText(
            picture, "bonnet", (x0 + 10, y1 + 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 255, 0), 2
        )
    return picture


def lane_mask_picture(
    mask: NDArray[np.uint8], crossing: NDArray[np.bool_] | None = None
) -> NDArray[np.uint8]:
    """The lane mask in white on black; where a pedestrian crossing was read, in colour with
    its bars in orange and a caption saying why no lane is drawn."""
    picture = (mask * 255).astype(np.uint8)
    if crossing is None:
        return picture
    coloured = np.repeat(picture[:, :, None], 3, axis=2)
    coloured[crossing] = CROSSING_COLOR
    cv2.putText(
        coloured, "pedestrian crossing", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, CROSSING_COLOR, 1
    )
    return coloured


def intermediates(out: FrameOutput, composite: Frame) -> dict[str, NDArray[np.uint8]]:
    """Named pictures of every intermediate of one processed frame, in pipeline order."""
    pictures: dict[str, NDArray[np.uint8]] = {"undistorted": out.undistorted}
    if out.result.scene is not None:
        facts = out.result.facts
        length = (facts.length_scale, facts.dash_m) if facts is not None else (1.0, None)
        pictures["scene"] = scene_picture(
            out.undistorted, out.result.scene, out.result.roll_deg, length
        )
    lane = out.result.lane
    if lane is not None and lane.debug is not None:
        pictures["lane_mask"] = lane_mask_picture(lane.debug.mask, lane.debug.crossing)
        fit = lane_inset(lane)
        if fit is not None:
            for x1, y1, x2, y2 in lane.debug.left_pixels.windows + lane.debug.right_pixels.windows:
                cv2.rectangle(fit, (x1, y1), (x2, y2), (0, 255, 0), 1)
            pictures["birdseye_fit"] = fit
    vehicles = out.result.vehicles
    if vehicles is not None and vehicles.debug is not None:
        d = vehicles.debug
        # Drawn on the picture the windows read (the mean of frames, the colour smoothed).
        hits = (out.undistorted if d.seen is None else d.seen).copy()
        read = [f"the mean of {d.averaged} frames"] if d.averaged > 1 else []
        read += ["colour smoothed (grain)"] if d.smoothed else []
        if read:
            cv2.putText(
                hits,
                "windows read " + ", ".join(read),
                (10, hits.shape[0] - 14),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.7,
                (255, 255, 255),
                2,
            )
        for k, band_hits in enumerate(d.hits):
            color = SCALE_COLORS[k % len(SCALE_COLORS)]
            strong = band_hits.decisions > 0
            for box, value in zip(
                band_hits.boxes[strong], band_hits.decisions[strong], strict=True
            ):
                x1, y1, x2, y2 = (round(float(v)) for v in box)
                cv2.rectangle(hits, (x1, y1), (x2, y2), color, 1)
                cv2.putText(
                    hits, f"{value:.1f}", (x1 + 2, y1 + 12), cv2.FONT_HERSHEY_PLAIN, 0.8, color, 1
                )
            cv2.putText(
                hits,
                f"{band_hits.window_px:.0f} px",
                (10, 30 + 22 * k),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.7,
                color,
                2,
            )
        for box in d.vetoed:  # sure, but vetoed (verifier, mirror image): white, crossed
            x1, y1, x2, y2 = (round(float(v)) for v in box)
            cv2.rectangle(hits, (x1, y1), (x2, y2), (255, 255, 255), 1)
            cv2.line(hits, (x1, y1), (x2, y2), (255, 255, 255), 1)
        pictures["window_hits"] = hits
        pictures["heat_frame"] = heat_picture(d.frame_heat, d.heat_threshold)
        pictures["heat_history"] = heat_picture(d.history_heat, d.heat_threshold)
        pictures["regions"] = _boxes(out.undistorted, d.regions, (255, 255, 0))
        tracks = _boxes(out.undistorted, vehicles.detections, (255, 60, 60))
        draw_boxes(tracks, d.remembered, (150, 150, 150))  # unseen, their ids kept: grey
        pictures["tracks"] = tracks
    pictures["composite"] = composite
    return pictures


def lane_line(out: FrameOutput) -> str:
    """The lane a frame drew, as its record reads it, or why there is none; and the ground
    scale where it moved (what the frame's pictures were made with)."""
    found = out.result.lane
    lane = None if found is None else found.lane
    if lane is not None:
        text = f"lane {lane.width_m:.2f} m wide, the camera {offset_words(lane.offset_m)}"
    elif found is not None and (doubts := [n for n in found.status if n.startswith("no lane")]):
        text = doubts[-1]
    else:
        text = "no lane"
    scene = out.result.scene
    if scene is not None and scene.ground_scale != 1.0:
        text += f"; ground scale {scene.ground_scale:.3f}"
    return text


def contact_sheet(frames: list[int], names: list[str]) -> str:
    """An index.html that steps through frames (buttons or arrow keys) showing every picture."""
    data = json.dumps({"frames": frames, "names": names})
    cells = "".join(
        f'<figure><img id="{html.escape(n)}"><figcaption>{html.escape(n)}</figcaption></figure>'
        for n in names
    )
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>roadview debug</title>
<style>body{{font-family:sans-serif;background:#222;color:#eee;margin:1em}}
figure{{display:inline-block;margin:4px;width:32%}}img{{width:100%}}
button{{font-size:1.1em}}</style></head>
<body><h1>roadview debug: frame <span id="n"></span></h1>
<p><button onclick="go(-1)">&larr; previous</button> <button onclick="go(1)">next &rarr;</button>
 (arrow keys step)</p>
<div>{cells}</div>
<script>
const D = {data}; let i = 0;
function show() {{
  const f = String(D.frames[i]).padStart(6, "0");
  document.getElementById("n").textContent = D.frames[i];
  for (const [k, n] of D.names.entries()) {{
    document.getElementById(n).src = `frame_${{f}}/${{String(k + 1).padStart(2, "0")}}_${{n}}.png`;
  }}
}}
function go(d) {{ i = Math.min(D.frames.length - 1, Math.max(0, i + d)); show(); }}
document.addEventListener("keydown", e => {{
  if (e.key === "ArrowLeft") go(-1); if (e.key === "ArrowRight") go(1); }});
show();
</script></body></html>
"""


def run_debug(
    source: Path,
    frames: tuple[int, int],
    out_dir: Path,
    pipeline: Pipeline,
    log: Callable[[str], None] = print,
    calibration_required: bool = True,
    max_size: int = 0,
    from_start: bool = False,
    after: Path | None = None,
) -> list[Path]:
    """Process the clip up to the chosen frames and write their intermediates; returns files.
    The pipeline's calibration is left out for a clip of another aspect ratio unless
    `calibration_required` (see `calibration_for`); a clip whose shorter side exceeds
    `max_size` pixels (0: none) is seen at that size, as `process` sees it. The clip is run
    from `WARMUP_S` before the first chosen frame, or `from_start`: then every history (the
    ground and length scales, the lines', the tracks') is the one `process` had there. A run
    from the clip's first frame goes on from `after`, the part of the drive before it, as
    `process --after` does (its last `LEAD_IN_S` run first)."""
    probed = probe_video(source)
    pipeline.mounting = sky_mounting(source, probed, pipeline.mounting, log, after)
    info = within_size(turned_info(probed, pipeline.mounting.rotate_deg), max_size)
    for note in decoding_notes(info):
        log(f"note: {source.name}: {note}")
    pipeline.calibration, pipeline.mounting = camera_for(
        pipeline.calibration, pipeline.mounting, info, source.name, calibration_required, log
    )
    first, last = frames
    if first >= info.n_frames:
        raise InputError(f"--frames starts at {first} but {source} has {info.n_frames} frames")
    last = min(last, info.n_frames)
    ensure_writable_dir(out_dir)
    start = 0 if from_start else max(0, first - round(WARMUP_S * info.fps))
    lead = None
    if after is not None and start == 0:
        lead = lead_in(after, info, source, max_size, log, pipeline.mounting.rotate_deg)
    elif after is not None:
        log(
            f"note: the run starts {start / info.fps:.1f} s into {source.name}, so {after.name} "
            "is not run first (--from-start runs it first)"
        )
    frames_from, led = start_part(pipeline, source, info, start, last, lead)
    annotators = default_annotators(insets=True)
    written: list[Path] = []
    names: list[str] = []
    done: list[int] = []
    for offset, frame in enumerate(frames_from(0, last)):
        index = start + offset - led  # negative in the lead-in
        out = pipeline.run(frame)
        if index < first:
            continue
        pictures = intermediates(out, compose(out.undistorted, out.result, annotators))
        folder = out_dir / f"frame_{index:06d}"
        folder.mkdir(exist_ok=True)
        for k, (name, picture) in enumerate(pictures.items(), start=1):
            path = folder / f"{k:02d}_{name}.png"
            write_image(
                path,
                picture
                if picture.ndim == 3
                else np.asarray(cv2.cvtColor(picture, cv2.COLOR_GRAY2RGB)),
            )
            written.append(path)
        names = list(pictures)
        done.append(index)
        shot = f" (shot {out.result.shot} of the edited footage)" if out.result.shot else ""
        log(f"frame {index}: {len(pictures)} pictures{shot}; {lane_line(out)}")
    index_path = out_dir / "index.html"
    index_path.write_text(contact_sheet(done, names))
    written.append(index_path)
    return written
