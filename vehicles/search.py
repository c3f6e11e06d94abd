"""Dense multi-scale window search: a linear model scored at every window position at once.

A linear SVM's score is a dot product of its weights with the window's features. Every feature is
read from per-cell maps of the band, so the score of all windows is a correlation of the weights
with those maps: one matrix product per feature part and a few shifted sums, no loop over windows.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from vehicles.config import Band
from vehicles.features import FeatureConfig, FeatureMaps, feature_maps, mirror_order
from vehicles.model import VehicleModel


@dataclass(frozen=True, eq=False)
class LinearWeights:
    """A model's raw-feature weights split by feature part, shaped like the feature maps."""

    hog: NDArray[np.float32]  # (blocks * blocks, block_length)
    spatial: NDArray[np.float32]  # (size * size, 3)
    hist: NDArray[np.float32]  # (3 * bins,)
    bias: float
    config: FeatureConfig

    @classmethod
    def from_model(cls, model: VehicleModel) -> LinearWeights:
        """Fold the standardisation into the weights and split them."""
        cfg = model.config
        w, b = model.folded()
        n_hog, n_spatial, _ = cfg.lengths
        return cls(
            hog=w[:n_hog].reshape(cfg.blocks_per_patch**2, cfg.block_length).astype(np.float32),
            spatial=w[n_hog : n_hog + n_spatial].reshape(cfg.spatial_size**2, 3).astype(np.float32),
            hist=w[n_hog + n_spatial :].astype(np.float32),
            bias=b,
            config=cfg,
        )

    def mirrored(self) -> LinearWeights:
        """The weights that score each window's mirror image: a feature's weight moves to where
        the mirror image puts that feature (`mirror_order`); the bias stays."""
        cfg = self.config
        n_hog, n_spatial, _ = cfg.lengths
        flat = np.concatenate([self.hog.ravel(), self.spatial.ravel(), self.hist])
        flat = flat[mirror_order(cfg)]
        return LinearWeights(
            hog=flat[:n_hog].reshape(self.hog.shape),
            spatial=flat[n_hog : n_hog + n_spatial].reshape(self.spatial.shape),
            hist=flat[n_hog + n_spatial :],
            bias=self.bias,
            config=cfg,
        )


def score_windows(maps: FeatureMaps, weights: LinearWeights) -> NDArray[np.float64]:
    """Decision value of every cell-aligned window: (cells_y - n + 1, cells_x - n + 1)."""
    cfg = weights.config
    nb, nc = cfg.blocks_per_patch, cfg.cells_per_patch
    by, bx, length = maps.blocks.shape
    ny, nx = by - nb + 1, bx - nb + 1
    if ny <= 0 or nx <= 0:
        return np.zeros((0, 0))
    # HOG: each block position's dot product with each in-window block's weights.
    per_block = (maps.blocks.reshape(-1, length) @ weights.hog.T).reshape(by, bx, nb * nb)
    score = np.zeros((ny, nx), np.float64)
    for i in range(nb):
        for j in range(nb):
            score += per_block[i : i + ny, j : j + nx, i * nb + j]
    # Spatial: the same at the binned resolution, stepping s bins per cell.
    s, ss = cfg.pixels_per_cell // cfg.spatial_factor, cfg.spatial_size
    kernels = weights.spatial.reshape(ss, ss, 3)
    for c in range(3):
        # Correlation anchored at the window's top-left bin, then one value per cell step.
        full = cv2.filter2D(
            np.ascontiguousarray(maps.spatial[:, :, c]),
            cv2.CV_32F,
            kernels[:, :, c],
            anchor=(0, 0),
            borderType=cv2.BORDER_CONSTANT,
        )
        score += full[: s * (ny - 1) + 1 : s, : s * (nx - 1) + 1 : s]
    # Histograms: one weight vector for every cell of the window, so a box sum of per-cell scores.
    per_cell = maps.histograms @ weights.hist
    integral = np.pad(per_cell, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    score += (
        integral[nc:, nc:] - integral[:-nc, nc:] - integral[nc:, :-nc] + integral[:-nc, :-nc]
    )[:ny, :nx]
    return score + weights.bias


def score_windows_at(
    maps: FeatureMaps, weights: LinearWeights, rows: NDArray[np.intp], cols: NDArray[np.intp]
) -> NDArray[np.float64]:
    """Decision values of the windows whose top-left cells are (`rows`, `cols`): what
    `score_windows` gives there, for a few windows without correlating the whole band."""
    cfg = weights.config
    nb, nc = cfg.blocks_per_patch, cfg.cells_per_patch
    s, ss = cfg.pixels_per_cell // cfg.spatial_factor, cfg.spatial_size
    # Each window's blocks and spatial bins, read through strided views of the maps: (n,
    # values, rows, columns), dotted without BLAS (whose threads cost more than the sums here).
    blocks = sliding_window_view(maps.blocks, (nb, nb), axis=(0, 1))[rows, cols]
    hog = weights.hog.reshape(nb, nb, -1)
    score = np.einsum("nkij,ijk->n", blocks, hog, dtype=np.float64)
    spatial = sliding_window_view(maps.spatial, (ss, ss), axis=(0, 1))[rows * s, cols * s]
    binned = weights.spatial.reshape(ss, ss, 3)
    score += np.einsum("ncij,ijc->n", spatial, binned, dtype=np.float64)
    cells = sliding_window_view(maps.histograms, (nc, nc), axis=(0, 1))[rows, cols]
    score += np.einsum("nkij,k->n", cells, weights.hist, dtype=np.float64)
    return np.asarray(score + weights.bias, np.float64)


def _scored_at(
    maps: FeatureMaps,
    weights: LinearWeights,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    due: NDArray[np.intp],
) -> NDArray[np.float64]:
    """Decision values by `weights` of the windows `due` among those at (`rows`, `cols`), NaN
    at the others."""
    scores = np.full(len(rows), np.nan)
    if len(due):
        scores[due] = score_windows_at(maps, weights, rows[due], cols[due])
    return scores


@dataclass(frozen=True, eq=False)
class BandHits:
    """Every window of one band: boxes in frame pixels and decision values."""

    band: Band
    window_px: float
    boxes: NDArray[np.float64]  # (n, 4)
    decisions: NDArray[np.float64]  # (n,)
    # (n,) the verifier's decisions where the model's own decision reached the search's
    # `heats_from`, NaN elsewhere; None: no verifier
    verified: NDArray[np.float64] | None = None
    # (n,) the model's decisions of each window's mirror image, likewise; None: not scored
    mirrored: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class View:
    """Where vehicles can be in frames of `size`: the horizon row, the live box (x0, y0, x1,
    y1; inside black bars), `scale_height`, the height of the 16:9 picture of the tuned lens
    at this picture's scale, and `ground_scale`, a car's size at a row against the tuned
    camera's (a camera higher over the road sees a car smaller where it meets the road). Bands
    are placed relative to these, so any framing and camera height works."""

    size: tuple[int, int]
    horizon_y: float
    live: tuple[int, int, int, int]
    scale_height: float
    ground_scale: float = 1.0

    @classmethod
    def default(cls, size: tuple[int, int], reference_horizon: float) -> View:
        """The whole frame with the horizon at the `reference_horizon` fraction of its height."""
        return cls(size, reference_horizon * size[1], (0, 0, *size), float(size[1]))


def band_geometry(
    band: Band, view: View, patch: int, reference_horizon: float
) -> tuple[int, int, int, int, float]:
    """(x0, y0, x1, y1) of the band in the frame and its scale (window px / patch px).

    A band's fractions are of the view's scale height, its rows measured from the horizon (a
    band tuned with the horizon at `reference_horizon` of the height): a car's size in pixels is
    proportional to how far below the horizon it meets the road, whatever the lens, so a band
    keeps its windows on the cars they fit when the horizon or the size changes. The ground
    scale shrinks the windows and keeps the rows: a car meeting the road at a row is that much
    smaller seen from higher up."""
    lx0, ly0, lx1, ly1 = view.live
    lw, sh = lx1 - lx0, view.scale_height
    window = band.window * sh * view.ground_scale
    scale = window / patch
    y0 = max(round(view.horizon_y + (band.top - reference_horizon) * sh), ly0)
    y1 = round(view.horizon_y + (band.bottom - reference_horizon) * sh)
    y1 = min(max(y1, y0 + round(window)), ly1)
    x0, x1 = lx0 + round(band.left * lw), lx0 + round(band.right * lw)
    return x0, y0, x1, y1, scale


def search_band(
    frame: NDArray[np.uint8],
    band: Band,
    weights: LinearWeights,
    view: View,
    reference_horizon: float,
    verifier: LinearWeights | None = None,
    mirrored: LinearWeights | None = None,
    heats_from: float = 0.0,
) -> BandHits | None:
    """Score every window of one band (HOG computed once for the band at its scale) by
    `weights`, and the windows whose decision reaches `heats_from` (a few: the rest could not
    heat anyway) also by the `verifier` on the same features and by the `mirrored` weights
    (`LinearWeights.mirrored`), when given; None when the band does not fit in the live picture
    or its windows would be smaller than its `min_window_px`."""
    cfg = weights.config
    x0, y0, x1, y1, scale = band_geometry(band, view, cfg.patch_size, reference_horizon)
    window = scale * cfg.patch_size
    if y1 - y0 < window * 0.99 or window < band.min_window_px * 0.99:
        return None
    # A band may reach past the live picture's sides so cars entering it are covered: pad by
    # mirroring the picture there. A car cut by the edge and mirrored looks like a whole car (cars
    # are nearly symmetric); a smeared border column looks like nothing the classifier knows.
    lx0, _, lx1, _ = view.live
    pad_left, pad_right = max(0, lx0 - x0), max(0, x1 - lx1)
    crop = frame[y0:y1, max(lx0, x0) : min(lx1, x1)]
    if pad_left or pad_right:
        crop = cv2.copyMakeBorder(crop, 0, 0, pad_left, pad_right, cv2.BORDER_REFLECT)
    size = (
        max(cfg.patch_size, round((x1 - x0) / scale)),
        max(cfg.patch_size, round((y1 - y0) / scale)),
    )
    interpolation = cv2.INTER_AREA if scale > 1 else cv2.INTER_LINEAR
    scaled = np.asarray(cv2.resize(crop, size, interpolation=interpolation))
    maps = feature_maps(scaled, cfg)
    step = band.step_cells
    decision = score_windows(maps, weights)[::step, ::step]
    cy, cx = np.mgrid[0 : decision.shape[0], 0 : decision.shape[1]] * step
    due = np.flatnonzero(decision.ravel() >= heats_from)
    # The verifier and the mirror image read the few windows that could heat, not the band:
    # scoring the band again cost as much as the model's own score (2 ms a frame at 720p).
    rows, cols = cy.ravel(), cx.ravel()
    verified = None if verifier is None else _scored_at(maps, verifier, rows, cols, due)
    flipped = None if mirrored is None else _scored_at(maps, mirrored, rows, cols, due)
    # Scaled-band pixels back to frame pixels (resize maps pixel edges linearly).
    sx, sy = (x1 - x0) / size[0], (y1 - y0) / size[1]
    px, py = cols * cfg.pixels_per_cell, rows * cfg.pixels_per_cell
    boxes = np.stack(
        [
            x0 + px * sx,
            y0 + py * sy,
            x0 + (px + cfg.patch_size) * sx,
            y0 + (py + cfg.patch_size) * sy,
        ],
        axis=1,
    )
    return BandHits(band, scale * cfg.patch_size, boxes, decision.ravel(), verified, flipped)
