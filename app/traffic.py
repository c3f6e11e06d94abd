"""Traffic keeping left (the UK, Ireland, India, Japan, Australia, ...): the vehicle stage sees
each frame mirrored, as a road where traffic keeps right, and its boxes are mirrored back.

The vehicle stage was tuned on traffic keeping right: its smallest windows search the side where
far-away and oncoming cars are, and its classifier learned that side's barriers and verges as
road. Mirrored, footage of traffic keeping left is what it knows (measured on the labelled clips
mirrored: see the README's quality table)."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
from numpy.typing import NDArray

from vehicles.detections import Detections
from vehicles.detector import VehicleDebug, VehicleDetector, VehicleResult

Box = tuple[int, int, int, int]


def mirrored_boxes(boxes: NDArray[np.float64], width: int) -> NDArray[np.float64]:
    """(n, 4) boxes [x0, y0, x1, y1] of a frame `width` pixels wide, where they lie in its mirror
    image (pixel-edge coordinates: column x becomes width - x)."""
    given = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    out = given.copy()
    out[:, 0] = width - given[:, 2]
    out[:, 2] = width - given[:, 0]
    return out


def mirrored_box(box: Box, width: int) -> Box:
    """One integer box (x0, y0, x1, y1) of the frame, in its mirror image."""
    x0, y0, x1, y1 = box
    return (width - x1, y0, width - x0, y1)


def mirrored_detections(detections: Detections, width: int) -> Detections:
    """The same detections (scores, ids) with their boxes mirrored."""
    return Detections(mirrored_boxes(detections.boxes, width), detections.scores, detections.ids)


def mirrored_debug(debug: VehicleDebug, width: int) -> VehicleDebug:
    """Every intermediate mirrored back: window boxes, regions, vetoed windows, remembered
    vehicles, and the heat maps (kept over the live picture, which mirrors onto the live
    picture)."""
    return VehicleDebug(
        tuple(replace(hit, boxes=mirrored_boxes(hit.boxes, width)) for hit in debug.hits),
        np.ascontiguousarray(debug.frame_heat[:, ::-1]),
        np.ascontiguousarray(debug.history_heat[:, ::-1]),
        mirrored_detections(debug.regions, width),
        debug.heat_threshold,
        mirrored_boxes(debug.vetoed, width),
        remembered=mirrored_detections(debug.remembered, width),
    )


class KeepLeft:
    """A vehicle stage for traffic keeping left: `detector` (its history included) sees every
    frame and the scene's placement mirrored; what it finds is mirrored back."""

    def __init__(self, detector: VehicleDetector) -> None:
        self.detector = detector

    def process(
        self,
        frame: NDArray[np.uint8],
        horizon_y: float | None = None,
        live: Box | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        overlays: tuple[Box, ...] = (),
        ground_scale: float = 1.0,
        road_grey: float | None = None,
        grain: float | None = None,
        monochrome: bool = False,
    ) -> VehicleResult:
        """`VehicleDetector.process` of the mirrored frame, mirrored back."""
        width = frame.shape[1]
        found = self.detector.process(
            np.asarray(cv2.flip(frame, 1)),
            horizon_y,
            None if live is None else mirrored_box(live, width),
            scale_height,
            None if vanishing_x is None else width - vanishing_x,
            tuple(mirrored_box(box, width) for box in overlays),
            ground_scale,
            road_grey,
            grain,
            monochrome,
        )
        return VehicleResult(
            mirrored_detections(found.detections, width),
            None if found.debug is None else mirrored_debug(found.debug, width),
        )

    def reset(self, fps: float | None = None) -> None:
        """Forget the detector's history (see `VehicleDetector.reset`)."""
        self.detector.reset(fps)
