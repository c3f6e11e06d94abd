"""Features, training, the model file, and the shipped classifier on real patches."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vehicles.augment import Degradation, degrade_patch, degraded, greyed
from vehicles.dataset import PatchSet, group_key, load_patches
from vehicles.features import FeatureConfig, feature_maps, mirror_order, patch_features
from vehicles.model import (
    ModelError,
    default_lowres_path,
    default_model_path,
    default_small_paths,
    load_model,
    save_model,
)
from vehicles.train import TrainConfig, extract_features, train_model


@pytest.fixture(scope="module")
def patches(data_dir: Path) -> PatchSet:
    return load_patches(data_dir)


def test_dataset_counts_and_groups(patches: PatchSet) -> None:
    assert (patches.labels == 1).sum() == 8792 and (patches.labels == 0).sum() == 8968
    assert patches.images.shape[1:] == (64, 64, 3)
    # Consecutive GTI frames share a group; another folder never does.
    assert group_key("vehicles/GTI_Far/image0031.png") == group_key(
        "vehicles/GTI_Far/image0032.png"
    )
    assert group_key("vehicles/GTI_Far/image0031.png") != group_key(
        "vehicles/GTI_Left/image0031.png"
    )
    assert 300 < len(np.unique(patches.groups)) < 2000


@pytest.mark.parametrize(
    "config",
    [
        FeatureConfig(),
        FeatureConfig(color_space="LUV", orientations=8, spatial_size=32, hist_bins=16),
    ],
)
def test_feature_length_and_determinism(patches: PatchSet, config: FeatureConfig) -> None:
    image = patches.images[0]
    a, b = patch_features(image, config), patch_features(image.copy(), config)
    assert a.shape == (config.length,) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()
    # The HOG part is made of L2-Hys blocks: each block has unit norm or is empty.
    hog = a[: config.lengths[0]].reshape(-1, 3, config.cells_per_block**2 * config.orientations)
    norms = np.linalg.norm(hog, axis=2)
    assert np.all((np.abs(norms - 1) < 1e-3) | (norms < 1e-3))


def test_hog_agrees_with_scikit_images_reference(patches: PatchSet) -> None:
    """Our HOG (gradients within each cell, votes split between two bins) describes a patch as
    `skimage.feature.hog` does: block by block, channel by channel, the two correlate."""
    from skimage.feature import hog

    config = FeatureConfig()
    k, bins, cells = config.cells_per_block, config.orientations, config.patch_size // 8 - 1

    def both(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ycc = cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb).astype(np.float32)
        ours = patch_features(image, config)[: config.lengths[0]]
        ours = ours.reshape(cells, cells, 3, k, k, bins).transpose(2, 0, 1, 3, 4, 5)
        ref = np.stack(
            [
                hog(
                    ycc[:, :, c],
                    orientations=bins,
                    pixels_per_cell=(8, 8),
                    cells_per_block=(k, k),
                    block_norm="L2-Hys",
                    feature_vector=False,
                )
                for c in range(3)
            ]
        )
        return ours.reshape(3, -1), ref.reshape(3, -1)

    sample = patches.images[:: len(patches.images) // 40][:40]
    pairs = [both(image) for image in sample]
    same = [np.corrcoef(o[c], r[c])[0, 1] for o, r in pairs for c in range(3)]
    other = [
        np.corrcoef(pairs[i][0][c], pairs[i - 1][1][c])[0, 1] for i in range(40) for c in range(3)
    ]
    assert np.mean(same) > 0.8 and np.min(same) > 0.55
    assert np.mean(other) < np.mean(same) - 0.3  # another patch's reference HOG does not match


def test_other_patch_sizes_are_resized(patches: PatchSet) -> None:
    big = cv2.resize(patches.images[5], (128, 128), interpolation=cv2.INTER_CUBIC)
    assert patch_features(big, FeatureConfig()).shape == (FeatureConfig().length,)


def test_dense_path_equals_patch_path(data_dir: Path) -> None:
    frame = cv2.cvtColor(cv2.imread(str(data_dir / "test_images" / "test1.jpg")), cv2.COLOR_BGR2RGB)
    config = FeatureConfig()
    band = frame[384:528]
    maps = feature_maps(band, config)
    for cell_y, cell_x in [(0, 0), (2, 101), (10, 152), (5, 57)]:
        y, x = cell_y * 8, cell_x * 8
        patch = np.ascontiguousarray(band[y : y + 64, x : x + 64])
        np.testing.assert_array_equal(maps.window(cell_y, cell_x), patch_features(patch, config))


@pytest.mark.parametrize(
    "config",
    [FeatureConfig(), FeatureConfig(patch_size=32, spatial_size=8), FeatureConfig(orientations=8)],
)
def test_a_mirror_images_features_are_the_patchs_own_reordered(
    patches: PatchSet, config: FeatureConfig
) -> None:
    """Flipped left to right, a patch's features are its own features in `mirror_order`: exactly
    the same values (gradients are taken within cells), each where the mirror image puts it; the
    order is its own inverse, and moves every HOG and spatial value of an asymmetric patch."""
    order = mirror_order(config)
    np.testing.assert_array_equal(order[order], np.arange(config.length))
    for image in patches.images[::2000]:
        size = (config.patch_size, config.patch_size)
        patch = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA))
        features = patch_features(patch, config)
        flipped = patch_features(np.ascontiguousarray(patch[:, ::-1]), config)
        np.testing.assert_allclose(flipped, features[order], atol=1e-5)
        assert not np.allclose(flipped, features, atol=1e-3)
    shaped = config.lengths[0] + config.lengths[1]  # HOG and spatial values; histograms after
    moved = order != np.arange(config.length)
    assert moved[:shaped].mean() > 0.8 and not moved[shaped:].any()


def _subset(patches: PatchSet, groups: np.ndarray, per_class: int, seed: int) -> PatchSet:
    rng = np.random.default_rng(seed)
    chosen = []
    for label in (0, 1):
        pool = np.flatnonzero((patches.labels == label) & np.isin(patches.groups, groups))
        chosen.append(rng.choice(pool, per_class, replace=False))
    return patches.subset(np.concatenate(chosen))


def test_training_on_a_small_subset(patches: PatchSet, tmp_path: Path) -> None:
    groups = np.unique(patches.groups)
    rng = np.random.default_rng(1)
    rng.shuffle(groups)
    train_groups, test_groups = groups[: len(groups) // 2], groups[len(groups) // 2 :]
    train = _subset(patches, train_groups, 400, seed=2)
    test = _subset(patches, test_groups, 300, seed=3)
    model = train_model(train, cfg=TrainConfig(c_grid=(1e-3, 1e-2), folds=2, n_jobs=1))
    x_test = extract_features(test.images, model.config, n_jobs=1)
    accuracy = (model.predict(x_test) == test.labels).mean()
    assert accuracy > 0.90
    assert model.report["chosen_c"] in (1e-3, 1e-2)
    assert set(model.report) >= {"grouped_split", "random_split", "timings_s", "feature_length"}
    # Calibrated probabilities rise with the decision value and cross 0.5 near zero.
    proba = model.probability(np.array([-3.0, 0.0, 3.0]))
    assert proba[0] < 0.2 < 0.8 < proba[2] and 0.2 < proba[1] < 0.8
    path = tmp_path / "model.npz"
    save_model(model, path)
    loaded = load_model(path)
    np.testing.assert_array_equal(loaded.predict(x_test), model.predict(x_test))
    np.testing.assert_allclose(loaded.predict_proba(x_test), model.predict_proba(x_test))
    assert loaded.config == model.config


def test_a_model_trained_on_mirror_images_too_scores_a_view_as_its_mirror(
    patches: PatchSet,
) -> None:
    """With `mirror`, each patch also trains as its mirror image: the model scores a car seen
    from behind-left as the same car from behind-right (traffic keeping left or right); one
    trained on the patches as they are does not."""
    groups = np.unique(patches.groups)[::2]
    train = _subset(patches, groups, 300, seed=4)
    probe = _subset(patches, np.unique(patches.groups)[1::2], 100, seed=5).images
    gaps = {}
    for mirror in (False, True):
        model = train_model(
            train, cfg=TrainConfig(c_grid=(1e-3,), folds=2, n_jobs=1, mirror=mirror)
        )
        x = extract_features(probe, model.config, n_jobs=1)
        x_mirrored = extract_features(probe[:, :, ::-1], model.config, n_jobs=1)
        gaps[mirror] = np.abs(model.decision_function(x) - model.decision_function(x_mirrored))
        assert model.report["mirrored"] is mirror
        assert model.report["n_vehicles"] + model.report["n_non_vehicles"] == len(train)
    assert np.median(gaps[True]) < 0.01 < 0.1 < np.median(gaps[False])


def test_shipped_model_on_a_fixed_subset(patches: PatchSet) -> None:
    model = load_model(default_model_path())
    subset = patches.subset(np.arange(0, len(patches), 20))
    x = extract_features(subset.images, model.config, n_jobs=1)
    assert (model.predict(x) == subset.labels).mean() >= 0.98
    # The honest figure recorded at training time: accuracy on held-out groups.
    assert model.report["grouped_split"]["accuracy"] >= 0.985


@pytest.mark.parametrize("path", default_small_paths())
def test_shipped_small_models(patches: PatchSet, path: Path) -> None:
    """The 32 px model of the smallest windows and its verifier: as accurate on held-out groups
    as the 64 px model (98.90 %) with a fifth of the features."""
    model = load_model(path)
    assert model.config.patch_size == 32
    subset = patches.subset(np.arange(0, len(patches), 20))
    x = extract_features(subset.images, model.config, n_jobs=1)
    assert (model.predict(x) == subset.labels).mean() >= 0.98
    assert model.report["grouped_split"]["accuracy"] >= 0.985


def test_small_model_dense_scores_equal_window_by_window(data_dir: Path) -> None:
    """The dense search reads a 32 px model's windows as it reads the 64 px model's."""
    model = load_model(default_small_paths()[0])
    config = model.config
    band = np.ascontiguousarray(
        np.asarray(cv2.imread(str(data_dir / "test_images" / "test1.jpg")))[400:480, :640, ::-1]
    )
    maps = feature_maps(band, config)
    for cell_y, cell_x in [(0, 0), (3, 41), (6, 76)]:
        y, x = cell_y * 8, cell_x * 8
        patch = np.ascontiguousarray(band[y : y + 32, x : x + 32])
        np.testing.assert_array_equal(maps.window(cell_y, cell_x), patch_features(patch, config))


def test_bad_model_files_fail_clearly(tmp_path: Path) -> None:
    good = default_model_path().read_bytes()
    cases = {
        "missing.npz": None,
        "garbage.npz": b"definitely not a zip file",
        "truncated.npz": good[: len(good) // 2],
    }
    for name, content in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(ModelError, match="model"):
            load_model(path)


def test_mismatched_and_foreign_model_files(tmp_path: Path) -> None:
    model = load_model(default_model_path())
    import dataclasses

    short = dataclasses.replace(model, weights=model.weights[:-5])
    save_model(short, tmp_path / "short.npz")
    with pytest.raises(ModelError, match="shape"):
        load_model(tmp_path / "short.npz")
    np.savez(tmp_path / "foreign.npz", weights=np.zeros(3))
    with pytest.raises(ModelError, match="not a roadview"):
        load_model(tmp_path / "foreign.npz")
    import vehicles.model as vm

    original = vm.FORMAT_VERSION
    try:
        vm.FORMAT_VERSION = original + 1
        save_model(model, tmp_path / "future.npz")
    finally:
        vm.FORMAT_VERSION = original
    with pytest.raises(ModelError, match="format version"):
        load_model(tmp_path / "future.npz")


def test_exported_model_gives_scikit_learns_probabilities() -> None:
    """The arrays in the model file reproduce the calibrated scikit-learn estimator exactly."""
    from vehicles.train import export, fit_calibrated

    rng = np.random.default_rng(0)
    config = FeatureConfig()
    x = rng.normal(size=(600, config.length)).astype(np.float32)
    x[:, 5] *= 30  # a badly scaled feature: the scaler inside the pipeline must be exported too
    y = (x[:, 0] + 0.5 * rng.normal(size=600) > 0).astype(np.int8)
    calibrated = fit_calibrated(x, y, np.arange(600) // 10, 1e-3, TrainConfig())
    model = export(calibrated, config, {})
    expected = calibrated.predict_proba(x[:50])[:, 1]
    np.testing.assert_allclose(
        model.probability(model.decision_function(x[:50])), expected, atol=1e-7
    )


def test_a_degraded_patch_loses_detail_and_colour_resolution_as_small_footage_does() -> None:
    """`degrade_patch` keeps the patch's size; shrunk to 20 px its fine texture is mostly gone,
    and even at full size and high quality a colour pattern one pixel fine is averaged away
    (4:2:0), as in H.264 footage, while the brightness stays."""
    rng = np.random.default_rng(0)
    texture = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    small = degrade_patch(texture, side=20, quality=85)
    assert small.shape == texture.shape and small.dtype == np.uint8

    def detail(image: np.ndarray) -> float:
        grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float64)
        return float(np.abs(cv2.Laplacian(grey, cv2.CV_64F)).mean())

    assert detail(small) < 0.3 * detail(texture)
    ycrcb = np.full((64, 64, 3), 128, np.uint8)
    ycrcb[:, ::2, 1], ycrcb[:, 1::2, 1] = 100, 156  # red-difference stripes one pixel wide
    stripes = cv2.cvtColor(ycrcb, cv2.COLOR_YCrCb2RGB)
    kept = cv2.cvtColor(degrade_patch(stripes, side=64, quality=95), cv2.COLOR_RGB2YCrCb)
    column_cr = kept[8:-8, 8:-8, 1].astype(np.float64).mean(axis=0)
    assert np.abs(np.diff(column_cr)).mean() < 0.2 * 56
    assert abs(kept[:, :, 0].astype(np.float64).mean() - 128) < 4


def test_a_model_trained_on_degraded_copies_too_reads_small_compressed_cars(
    patches: PatchSet,
) -> None:
    """With `degrade`, each patch also trains as small compressed footage shows it: on patches
    of held-out groups degraded so (other draws), such a model is more accurate than one trained
    on the patches as they are, and scores them closer to their sharp originals."""
    groups = np.unique(patches.groups)[::2]
    train = _subset(patches, groups, 300, seed=4)
    probe = _subset(patches, np.unique(patches.groups)[1::2], 150, seed=5)
    worse = degraded(probe.images, Degradation(min_quality=30, max_quality=50, seed=9))
    accuracy, gaps = {}, {}
    for degrade in (False, True):
        model = train_model(
            train, cfg=TrainConfig(c_grid=(1e-3,), folds=2, n_jobs=1, degrade=degrade)
        )
        x = extract_features(probe.images, model.config, n_jobs=1)
        x_worse = extract_features(worse, model.config, n_jobs=1)
        accuracy[degrade] = float((model.predict(x_worse) == probe.labels).mean())
        gaps[degrade] = float(
            np.median(np.abs(model.decision_function(x) - model.decision_function(x_worse)))
        )
        assert model.report["degraded"] is degrade
    assert accuracy[True] >= accuracy[False] + 0.05, accuracy
    assert gaps[True] < 0.6 * gaps[False], gaps


def test_a_model_trained_without_colour_reads_monochrome_patches(patches: PatchSet) -> None:
    """With `grey`, every patch trains without its colour (its luma in all three channels, as a
    monochrome camera's frames decode): on patches of held-out groups so, such a model is far
    more accurate than one trained in colour, which takes grey cars for road."""
    groups = np.unique(patches.groups)[::2]
    train = _subset(patches, groups, 300, seed=4)
    probe = _subset(patches, np.unique(patches.groups)[1::2], 150, seed=5)
    grey = greyed(probe.images)
    assert grey.shape == probe.images.shape
    assert (grey[..., 0] == grey[..., 1]).all() and (grey[..., 1] == grey[..., 2]).all()
    accuracy = {}
    for without_colour in (False, True):
        model = train_model(
            train, cfg=TrainConfig(c_grid=(1e-3,), folds=2, n_jobs=1, grey=without_colour)
        )
        x = extract_features(grey, model.config, n_jobs=1)
        accuracy[without_colour] = float((model.predict(x) == probe.labels).mean())
        assert model.report["grey"] is without_colour
    assert accuracy[True] >= accuracy[False] + 0.1, accuracy


def test_shipped_low_resolution_model(patches: PatchSet) -> None:
    """The model for pictures of few rows was trained also on degraded copies, and is as
    accurate on the sharp patches of held-out groups as the issue asks (98.5 %)."""
    model = load_model(default_lowres_path())
    assert model.report["degraded"] is True and model.config == load_model().config
    subset = patches.subset(np.arange(0, len(patches), 20))
    x = extract_features(subset.images, model.config, n_jobs=1)
    assert (model.predict(x) == subset.labels).mean() >= 0.98
    assert model.report["grouped_split"]["accuracy"] >= 0.985
