"""Patch features: HOG on every channel, spatial binning, colour histograms.

One code path serves 64x64 training patches and the detector's dense search. Every feature is built
from per-cell quantities (gradients are taken within each cell), so a window's features read from a
whole image band equal those of the same window cut out as a patch.

Feature order of a patch, each block flattened in C order:
1. HOG: blocks (rows, cols) x channel x block cells (2 x 2) x orientation bins, L2-Hys normalised;
2. spatial: the patch resized to spatial_size x spatial_size (area averaging) x channel;
3. histograms: channel x hist_bins counts over 0..255 of the spatially binned pixels.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

COLOR_CODES = {
    "RGB": None,
    "YCrCb": cv2.COLOR_RGB2YCrCb,
    "LUV": cv2.COLOR_RGB2Luv,
    "HLS": cv2.COLOR_RGB2HLS,
    "HSV": cv2.COLOR_RGB2HSV,
    "YUV": cv2.COLOR_RGB2YUV,
    "LAB": cv2.COLOR_RGB2Lab,
}
HYS_CLIP = 0.2
EPS = 1e-6
STRIPE_VALUES = 1 << 15  # pixel values (all channels) a stripe of `cell_hog` takes at most

FloatArray = NDArray[np.float32]


@dataclass(frozen=True)
class FeatureConfig:
    """Every parameter of the patch features; it travels with the model that was trained on it."""

    color_space: str = "YCrCb"
    orientations: int = 9
    pixels_per_cell: int = 8
    cells_per_block: int = 2
    spatial_size: int = 16
    hist_bins: int = 32
    patch_size: int = 64

    def __post_init__(self) -> None:
        if self.color_space not in COLOR_CODES:
            raise ValueError(f"color_space must be one of {sorted(COLOR_CODES)}")
        if self.patch_size % self.pixels_per_cell:
            raise ValueError("patch_size must be a multiple of pixels_per_cell")
        if self.patch_size % self.spatial_size or self.pixels_per_cell % (
            self.patch_size // self.spatial_size
        ):
            raise ValueError("spatial bins must tile the patch and align with cells")
        if 256 % self.hist_bins:
            raise ValueError("hist_bins must divide 256")

    @property
    def cells_per_patch(self) -> int:
        """Cells along one side of a patch."""
        return self.patch_size // self.pixels_per_cell

    @property
    def blocks_per_patch(self) -> int:
        """Blocks along one side of a patch (stride one cell)."""
        return self.cells_per_patch - self.cells_per_block + 1

    @property
    def block_length(self) -> int:
        """HOG values of one block position, all channels."""
        return 3 * self.cells_per_block**2 * self.orientations

    @property
    def spatial_factor(self) -> int:
        """Pixels per spatial bin along one side."""
        return self.patch_size // self.spatial_size

    @property
    def lengths(self) -> tuple[int, int, int]:
        """Lengths of the HOG, spatial and histogram parts."""
        return (
            self.blocks_per_patch**2 * self.block_length,
            self.spatial_size**2 * 3,
            3 * self.hist_bins,
        )

    @property
    def length(self) -> int:
        """Length of a whole feature vector."""
        return sum(self.lengths)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return asdict(self)


def convert_color(rgb: NDArray[np.uint8], color_space: str) -> NDArray[np.uint8]:
    """An RGB uint8 image in the feature colour space (still uint8)."""
    code = COLOR_CODES[color_space]
    return rgb if code is None else np.asarray(cv2.cvtColor(rgb, code))


@lru_cache(maxsize=64)
def _cell_base(h: int, w: int, c: int, cell: int, bins: int) -> NDArray[np.intp]:
    """Flat index (cell row, cell col, channel) * bins of every pixel, as an (h, w * c) array."""
    rows = np.arange(h) // cell
    cols = np.arange(w) // cell
    base = ((rows[:, None, None] * (w // cell) + cols[None, :, None]) * c + np.arange(c)) * bins
    base = base.reshape(h, w * c).astype(np.intp)
    base.setflags(write=False)
    return base


@lru_cache(maxsize=8)
def _wrap_table(bins: int) -> NDArray[np.intp]:
    """Bin number of each integer bin position in [0, 3 * bins)."""
    return np.arange(3 * bins, dtype=np.intp) % bins


def cell_gradients(image: FloatArray, cell: int) -> tuple[FloatArray, FloatArray]:
    """x and y gradients taken within each cell (one-sided at cell edges), per channel.

    Central differences inside a cell, forward/backward differences on its first/last pixel, as
    numpy.gradient does on each cell alone, so no pixel outside a cell affects its histogram.
    """
    h, w, c = image.shape
    flat = image.reshape(h, w * c)
    gx = np.asarray(cv2.filter2D(flat, -1, _difference_kernel(c), borderType=cv2.BORDER_REPLICATE))
    gx = gx.reshape(h, w, c)
    gx[:, 0::cell] = image[:, 1::cell] - image[:, 0::cell]
    gx[:, cell - 1 :: cell] = image[:, cell - 1 :: cell] - image[:, cell - 2 :: cell]
    gy = np.asarray(
        cv2.filter2D(flat, -1, _difference_kernel(1).T, borderType=cv2.BORDER_REPLICATE)
    )
    gy = gy.reshape(h, w, c)
    gy[0::cell] = image[1::cell] - image[0::cell]
    gy[cell - 1 :: cell] = image[cell - 1 :: cell] - image[cell - 2 :: cell]
    return gx, gy


@lru_cache(maxsize=8)
def _difference_kernel(c: int) -> NDArray[np.float32]:
    """Central difference along a row of `c` interleaved channels: [-0.5, 0 x (2c - 1), 0.5]."""
    kernel = np.zeros((1, 2 * c + 1), dtype=np.float32)
    kernel[0, 0], kernel[0, -1] = -0.5, 0.5
    kernel.setflags(write=False)
    return kernel


def cell_hog(image: FloatArray, config: FeatureConfig) -> FloatArray:
    """Orientation histograms per cell: (cells_y, cells_x, channels, orientations).

    Each pixel votes its gradient magnitude into the two nearest unsigned orientation bins.
    A cell's histogram depends on its own pixels alone, so a wide band is taken in stripes of
    whole cell rows, each small enough for its temporaries to stay in the cache: the same
    values, in half the time on a band 1,536 px wide.
    """
    cell = config.pixels_per_cell
    h, w, c = image.shape
    rows = cell * max(1, STRIPE_VALUES // (w * c * cell))
    if h <= rows:
        return _cell_hog(image, config)
    return np.concatenate([_cell_hog(image[top : top + rows], config) for top in range(0, h, rows)])


def _cell_hog(image: FloatArray, config: FeatureConfig) -> FloatArray:
    """`cell_hog` of a stripe in one pass."""
    cell, bins = config.pixels_per_cell, config.orientations
    h, w, c = image.shape
    gx, gy = cell_gradients(image, cell)
    magnitude, angle = cv2.cartToPolar(gx.reshape(h, -1), gy.reshape(h, -1), angleInDegrees=True)
    # Angles are in [0, 360); shifting by `bins` keeps positions positive. All float32: mixing in
    # integer arrays would promote the votes to float64 and double the cost.
    position = np.asarray(angle, dtype=np.float32) * np.float32(bins / 180.0)
    position += np.float32(bins - 0.5)
    floor = np.floor(position)
    mag = np.asarray(magnitude, dtype=np.float32)
    upper_vote = mag * (position - floor)
    lower_vote = mag - upper_vote
    index = (_cell_base(h, w, c, cell, bins) + _wrap_table(bins)[floor.astype(np.intp)]).ravel()
    n = (h // cell) * (w // cell) * c * bins
    shape = (h // cell, w // cell, c, bins)
    hist = np.bincount(index, lower_vote.ravel(), n).reshape(shape)
    # Upper votes go to the next bin: counted at the lower bin's index, then shifted one bin on
    # (the same additions in the same order, without a second index array).
    hist += np.roll(np.bincount(index, upper_vote.ravel(), n).reshape(shape), 1, axis=3)
    return hist.astype(np.float32)


def block_normalize(cells: FloatArray, config: FeatureConfig) -> FloatArray:
    """L2-Hys normalised blocks: (blocks_y, blocks_x, block_length), stride one cell."""
    k = config.cells_per_block
    cy, cx, c, bins = cells.shape
    by, bx = cy - k + 1, cx - k + 1
    parts = [cells[i : i + by, j : j + bx] for i in range(k) for j in range(k)]
    # (by, bx, channel, cell-in-block, bin)
    blocks: FloatArray = np.stack(parts, axis=3).reshape(by, bx, c, k * k * bins)
    blocks = blocks / np.sqrt((blocks**2).sum(axis=3, keepdims=True) + EPS**2)
    blocks = np.minimum(blocks, HYS_CLIP)
    blocks = blocks / np.sqrt((blocks**2).sum(axis=3, keepdims=True) + EPS**2)
    return blocks.reshape(by, bx, c * k * k * bins).astype(np.float32)


def cell_color_histograms(small: NDArray[np.uint8], config: FeatureConfig) -> FloatArray:
    """Colour histograms per cell, (cells_y, cells_x, channels * hist_bins), of the binned image.

    Counting the spatially binned pixels (4 x 4 averages) instead of every pixel costs a sixteenth
    and describes the colour distribution as well.
    """
    cell = config.pixels_per_cell // config.spatial_factor
    bins = config.hist_bins
    h, w, c = small.shape
    base = _cell_base(h, w, c, cell, bins)
    value_bin = (np.arange(256, dtype=np.intp) * bins) >> 8
    index = base + value_bin[small.reshape(h, w * c)]
    n = (h // cell) * (w // cell) * c * bins
    hist = np.bincount(index.ravel(), minlength=n).astype(np.float32)
    return hist.reshape(h // cell, w // cell, c * bins)


def binned_image(image: NDArray[np.uint8], config: FeatureConfig) -> NDArray[np.uint8]:
    """The image averaged over spatial bins (area interpolation): (h / f, w / f, channels)."""
    f = config.spatial_factor
    h, w = image.shape[:2]
    small = cv2.resize(image, (w // f, h // f), interpolation=cv2.INTER_AREA)
    return np.asarray(small, dtype=np.uint8).reshape(h // f, w // f, -1)


@dataclass(frozen=True, eq=False)
class FeatureMaps:
    """Per-cell feature maps of one image band, from which any cell-aligned window can be read."""

    blocks: FloatArray  # (blocks_y, blocks_x, block_length)
    spatial: FloatArray  # (cells_y * cell / factor, cells_x * cell / factor, 3)
    histograms: FloatArray  # (cells_y, cells_x, 3 * hist_bins)
    config: FeatureConfig

    def window(self, cell_y: int, cell_x: int) -> FloatArray:
        """The feature vector of the patch whose top-left cell is (cell_y, cell_x)."""
        cfg = self.config
        nb, nc = cfg.blocks_per_patch, cfg.cells_per_patch
        hog = self.blocks[cell_y : cell_y + nb, cell_x : cell_x + nb].ravel()
        s = cfg.pixels_per_cell // cfg.spatial_factor
        ss = cfg.spatial_size
        spatial = self.spatial[cell_y * s : cell_y * s + ss, cell_x * s : cell_x * s + ss].ravel()
        hist = self.histograms[cell_y : cell_y + nc, cell_x : cell_x + nc].sum(axis=(0, 1))
        return np.concatenate([hog, spatial, hist]).astype(np.float32)


def feature_maps(rgb: NDArray[np.uint8], config: FeatureConfig) -> FeatureMaps:
    """Feature maps of an RGB band; its size is cropped down to whole cells."""
    cell = config.pixels_per_cell
    h, w = rgb.shape[0] // cell * cell, rgb.shape[1] // cell * cell
    converted = convert_color(np.ascontiguousarray(rgb[:h, :w]), config.color_space)
    cells = cell_hog(converted.astype(np.float32), config)
    small = binned_image(converted, config)
    return FeatureMaps(
        blocks=block_normalize(cells, config),
        spatial=small.astype(np.float32),
        histograms=cell_color_histograms(small, config),
        config=config,
    )


def mirror_order(config: FeatureConfig) -> NDArray[np.intp]:
    """The permutation that turns a patch's features into its mirror image's:
    `patch_features(patch[:, ::-1])` equals `patch_features(patch)[mirror_order(config)]`.

    Mirrored, a block's column and its cells' columns reverse and each orientation bin swaps
    with its reflection about the vertical (gradients are taken within cells, one-sided at
    their edges, so the swap is exact); spatial bins reverse their columns; the histograms stay.
    It is its own inverse, so it also mirrors a linear model's weights: a mirrored window
    scores with `weights[mirror_order(config)]`.
    """
    nb, k, bins = config.blocks_per_patch, config.cells_per_block, config.orientations
    hog = np.arange(config.lengths[0]).reshape(nb, nb, 3, k, k, bins)[:, ::-1, :, :, ::-1, ::-1]
    ss = config.spatial_size
    spatial = np.arange(config.lengths[1]).reshape(ss, ss, 3)[:, ::-1] + config.lengths[0]
    hist = np.arange(config.lengths[2]) + config.lengths[0] + config.lengths[1]
    return np.concatenate([hog.ravel(), spatial.ravel(), hist]).astype(np.intp)


def patch_features(rgb: NDArray[np.uint8], config: FeatureConfig) -> FloatArray:
    """Feature vector of one RGB patch (resized to patch_size if it is another size)."""
    size = config.patch_size
    if rgb.shape[:2] != (size, size):
        rgb = np.asarray(cv2.resize(rgb, (size, size), interpolation=cv2.INTER_AREA))
    return feature_maps(rgb, config).window(0, 0)
