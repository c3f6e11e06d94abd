"""Training with scikit-learn's own estimators: Pipeline(StandardScaler, LinearSVC), C chosen by
GridSearchCV over GroupKFold (the scaler is fitted inside each fold), Platt-calibrated by
CalibratedClassifierCV(method="sigmoid") on out-of-fold decisions, and an honest report (grouped
and random splits). The fitted estimators are exported as plain arrays (`VehicleModel`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from numpy.typing import NDArray
from sklearn.calibration import CalibratedClassifierCV
from sklearn.metrics import accuracy_score, confusion_matrix, precision_recall_fscore_support
from sklearn.model_selection import GridSearchCV, GroupKFold, GroupShuffleSplit, train_test_split
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import LinearSVC

from vehicles.augment import degraded, greyed, mirrored
from vehicles.dataset import PatchSet
from vehicles.features import FeatureConfig, patch_features
from vehicles.model import VehicleModel

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class TrainConfig:
    """How a model is trained."""

    c_grid: tuple[float, ...] = (3e-5, 1e-4, 3e-4, 1e-3)
    folds: int = 5  # each fold trains on 80 % of the groups; 3 folds chose C by noise
    test_size: float = 0.2
    seed: int = 0
    n_jobs: int = 2
    max_iter: int = 5000
    # Each patch also trains as its mirror image (in its group): a model that scores a view and
    # its mirror image alike, for traffic keeping left as well as right (see the README for why
    # the shipped models are not).
    mirror: bool = False
    # Each patch also trains as a small, compressed video frame shows it (`vehicles.augment`):
    # colour at half resolution and block compression, as in footage of 360-480 rows.
    degrade: bool = False
    # Every patch trains without its colour, and only so: the models of monochrome footage.
    grey: bool = False


def _features_chunk(images: NDArray[np.uint8], config: FeatureConfig) -> NDArray[np.float32]:
    import cv2

    cv2.setNumThreads(1)
    return np.stack([patch_features(image, config) for image in images])


def extract_features(
    images: NDArray[np.uint8],
    config: FeatureConfig,
    n_jobs: int = 2,
    progress: Progress | None = None,
    chunk: int = 1000,
) -> NDArray[np.float32]:
    """Feature rows of many patches, computed in parallel chunks."""
    starts = range(0, len(images), chunk)
    results = Parallel(n_jobs=n_jobs, return_as="generator")(
        delayed(_features_chunk)(images[s : s + chunk], config) for s in starts
    )
    rows: list[NDArray[np.float32]] = []
    for block in results:
        rows.append(block)
        if progress is not None:
            progress(sum(len(r) for r in rows), len(images))
    return np.concatenate(rows) if rows else np.zeros((0, config.length), np.float32)


def svm_pipeline(c: float = 1.0, max_iter: int = 5000) -> Pipeline:
    """Standardisation and a linear SVM, one estimator (so each fold fits its own scaler)."""
    return Pipeline(
        [
            ("scale", StandardScaler()),
            ("svm", LinearSVC(C=c, dual=True, max_iter=max_iter, random_state=0)),
        ]
    )


def search_c(
    x: NDArray[np.float32], y: NDArray[np.int8], groups: NDArray[np.int64], cfg: TrainConfig
) -> tuple[float, dict[str, float]]:
    """The C of the best grouped cross-validated accuracy (the smallest on a tie) and every C's
    mean accuracy over the folds."""
    search = GridSearchCV(
        svm_pipeline(max_iter=cfg.max_iter),
        {"svm__C": list(cfg.c_grid)},
        cv=GroupKFold(n_splits=cfg.folds),
        scoring="accuracy",
        n_jobs=cfg.n_jobs,
        refit=False,
    )
    search.fit(x, y, groups=groups)
    accuracy = {
        f"{c:g}": float(a)
        for c, a in zip(
            search.cv_results_["param_svm__C"], search.cv_results_["mean_test_score"], strict=True
        )
    }
    best = max(cfg.c_grid, key=lambda c: (accuracy[f"{c:g}"], -c))
    return best, accuracy


def fit_calibrated(
    x: NDArray[np.float32],
    y: NDArray[np.int8],
    groups: NDArray[np.int64],
    c: float,
    cfg: TrainConfig,
) -> CalibratedClassifierCV:
    """The SVM pipeline fitted on every row, with a sigmoid fitted on its grouped out-of-fold
    decision values (one estimator, not an ensemble, so it exports as one linear model)."""
    splits = list(GroupKFold(n_splits=cfg.folds).split(x, y, groups))
    calibrated = CalibratedClassifierCV(
        svm_pipeline(c, cfg.max_iter), method="sigmoid", cv=splits, ensemble=False
    )
    return calibrated.fit(x, y)


def export(
    calibrated: CalibratedClassifierCV, config: FeatureConfig, report: dict[str, Any]
) -> VehicleModel:
    """The fitted estimators as the plain arrays the dense search and the model file use."""
    (member,) = calibrated.calibrated_classifiers_
    pipeline: Pipeline = member.estimator
    scaler: StandardScaler = pipeline.named_steps["scale"]
    svm: LinearSVC = pipeline.named_steps["svm"]
    (sigmoid,) = member.calibrators
    return VehicleModel(
        config=config,
        weights=np.asarray(svm.coef_[0], dtype=np.float64),
        intercept=float(svm.intercept_[0]),
        mean=np.asarray(scaler.mean_, dtype=np.float64),
        scale=np.asarray(scaler.scale_, dtype=np.float64),
        platt_a=float(sigmoid.a_),
        platt_b=float(sigmoid.b_),
        report=report,
    )


def scores(y_true: NDArray[np.int8], y_pred: NDArray[np.int8]) -> dict[str, Any]:
    """Accuracy, precision, recall, F1 (vehicle class) and the confusion matrix."""
    p, r, f, _ = precision_recall_fscore_support(y_true, y_pred, average="binary", zero_division=0)
    return {
        "accuracy": float(accuracy_score(y_true, y_pred)),
        "precision": float(p),
        "recall": float(r),
        "f1": float(f),
        "confusion_matrix": confusion_matrix(y_true, y_pred, labels=[0, 1]).tolist(),
        "n": len(y_true),
    }


def train_model(
    patches: PatchSet,
    config: FeatureConfig | None = None,
    cfg: TrainConfig | None = None,
    progress: Progress | None = None,
    log: Callable[[str], None] = lambda message: None,
    extra_negatives: Sequence[NDArray[np.uint8]] = (),
) -> VehicleModel:
    """Train on a grouped split, report honestly, and return the model (refit on every patch)."""
    config = config if config is not None else FeatureConfig()
    cfg = cfg if cfg is not None else TrainConfig()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    images = patches.images
    y = patches.labels.astype(np.int8)
    groups = patches.groups
    if len(extra_negatives):
        extra = np.stack(list(extra_negatives))
        images = np.concatenate([images, extra])
        y = np.concatenate([y, np.zeros(len(extra), np.int8)])
        groups = np.concatenate([groups, groups.max() + 1 + np.arange(len(extra)) // 30])
    if cfg.grey:
        images = greyed(images)
    x = extract_features(images, config, cfg.n_jobs, progress)
    n = len(x)
    # A copy (mirrored, degraded) joins its original's group: split, searched and scored with
    # it; the accuracies are measured on originals alone.
    copies = [make for wanted, make in ((cfg.mirror, mirrored), (cfg.degrade, degraded)) if wanted]
    for make in copies:
        x = np.concatenate([x, extract_features(make(images), config, cfg.n_jobs)])
    y, groups = np.tile(y, 1 + len(copies)), np.tile(groups, 1 + len(copies))

    def with_copies(index: NDArray[np.int64]) -> NDArray[np.int64]:
        return np.concatenate([index + k * n for k in range(1 + len(copies))])

    timings["features_s"] = time.perf_counter() - t0
    log(f"features: {x.shape[0]} x {x.shape[1]} in {timings['features_s']:.1f} s")

    t0 = time.perf_counter()
    train, test = next(
        GroupShuffleSplit(1, test_size=cfg.test_size, random_state=cfg.seed).split(
            x[:n], y[:n], groups[:n]
        )
    )
    train = with_copies(train)
    best_c, cv_accuracy = search_c(x[train], y[train], groups[train], cfg)
    timings["search_s"] = time.perf_counter() - t0
    log(f"C search {cv_accuracy} -> C = {best_c:g} in {timings['search_s']:.1f} s")

    t0 = time.perf_counter()
    held_out = fit_calibrated(x[train], y[train], groups[train], best_c, cfg)
    grouped = scores(y[test], held_out.predict(x[test]))
    rtrain, rtest = train_test_split(
        np.arange(n), test_size=cfg.test_size, random_state=cfg.seed, stratify=y[:n]
    )
    rtrain = with_copies(rtrain)
    plain = svm_pipeline(best_c, cfg.max_iter).fit(x[rtrain], y[rtrain])
    random_split = scores(y[rtest], plain.predict(x[rtest]))
    timings["evaluate_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    final = fit_calibrated(x, y, groups, best_c, cfg)
    timings["final_fit_s"] = time.perf_counter() - t0
    (member,) = final.calibrated_classifiers_
    (sigmoid,) = member.calibrators
    report = {
        "grouped_split": grouped,
        "random_split": random_split,
        "chosen_c": best_c,
        "cv_accuracy_by_c": cv_accuracy,
        "feature_length": config.length,
        "n_vehicles": int((y[:n] == 1).sum()),
        "n_non_vehicles": int((y[:n] == 0).sum()),
        "mirrored": cfg.mirror,
        "degraded": cfg.degrade,
        "grey": cfg.grey,
        "n_hard_negatives": len(extra_negatives),
        "n_groups": len(np.unique(groups)),
        "platt": [float(sigmoid.a_), float(sigmoid.b_)],
        "timings_s": {k: round(v, 2) for k, v in timings.items()},
        "seed": cfg.seed,
    }
    return export(final, config, report)


def format_training_report(report: dict[str, Any]) -> str:
    """Human-readable summary of a training report."""
    lines = []
    for name in ("grouped_split", "random_split"):
        s = report[name]
        (tn, fp), (fn, tp) = s["confusion_matrix"]
        lines.append(
            f"{name.replace('_', ' ')} test: accuracy {100 * s['accuracy']:.2f} %, precision "
            f"{s['precision']:.4f}, recall {s['recall']:.4f}, F1 {s['f1']:.4f} "
            f"(n={s['n']}; TN {tn}, FP {fp}, FN {fn}, TP {tp})"
        )
    cv = ", ".join(f"C={c}: {100 * a:.2f} %" for c, a in report["cv_accuracy_by_c"].items())
    lines.append(
        f"C chosen by grouped {len(report['cv_accuracy_by_c'])}-value search: "
        f"{report['chosen_c']:g} ({cv})"
    )
    lines.append(
        f"feature length {report['feature_length']}; {report['n_vehicles']} vehicles, "
        f"{report['n_non_vehicles']} non-vehicles ({report['n_hard_negatives']} hard "
        f"negatives) in {report['n_groups']} groups"
    )
    copies = [name for name in ("mirrored", "degraded") if report.get(name)]
    if copies:
        lines.append("each also trained " + " and ".join(copies) + ", in its group")
    t = report["timings_s"]
    lines.append("time: " + ", ".join(f"{k.removesuffix('_s')} {v:.1f} s" for k, v in t.items()))
    return "\n".join(lines)
