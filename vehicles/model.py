"""The vehicle classifier: standardised features, linear SVM weights, Platt calibration.

Saved without pickle: an .npz of plain arrays plus a JSON header (format version, feature config,
training report, library versions). Loading checks the version and every shape.
"""

from __future__ import annotations

import io
import json
import platform
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vehicles.features import FeatureConfig

FORMAT = "roadview-vehicle-model"
FORMAT_VERSION = 1
ARRAYS = ("weights", "mean", "scale", "scalars")


class ModelError(Exception):
    """A model file is missing, corrupt, or of another version; the message states the facts."""


def default_model_path() -> Path:
    """The committed model that `roadview process` uses unless told otherwise."""
    return Path(__file__).with_name("models") / "default.npz"


def default_verifier_path() -> Path:
    """The committed verifier: the model trained also on hard negatives (see `make train`)."""
    return Path(__file__).with_name("models") / "verifier.npz"


def default_dark_verifier_path() -> Path:
    """The committed verifier of dark roads: it also learned the false alarms of dimmed, grainy
    copies of clips without vehicles, as a dim sensor films them (see `make train`)."""
    return Path(__file__).with_name("models") / "dark_verifier.npz"


def default_lowres_path() -> Path:
    """The committed model for footage of few rows: trained also on each patch as such footage
    shows it (colour at half resolution, block compression; see `make train`)."""
    return Path(__file__).with_name("models") / "lowres.npz"


def default_small_paths() -> tuple[Path, Path]:
    """The committed 32 px model for the smallest windows, and its verifier (see `make train`)."""
    folder = Path(__file__).with_name("models")
    return folder / "small.npz", folder / "small_verifier.npz"


def default_grey_paths() -> tuple[tuple[Path, Path], tuple[Path, Path]]:
    """The committed models of monochrome footage, each with its verifier: the 64 px and the
    32 px one, trained on grey copies of the patches (see `make train`)."""
    folder = Path(__file__).with_name("models")
    return (
        (folder / "grey.npz", folder / "grey_verifier.npz"),
        (folder / "grey_small.npz", folder / "grey_small_verifier.npz"),
    )


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """Linear classifier on standardised patch features with calibrated probabilities."""

    config: FeatureConfig
    weights: NDArray[np.float64]  # on standardised features
    intercept: float
    mean: NDArray[np.float64]
    scale: NDArray[np.float64]
    platt_a: float  # P(vehicle) = 1 / (1 + exp(platt_a * decision + platt_b))
    platt_b: float
    report: dict[str, Any] = field(default_factory=dict)

    def decision_function(self, features: NDArray[np.floating[Any]]) -> NDArray[np.float64]:
        """Signed distance to the SVM hyperplane for each row of raw features."""
        w, b = self.folded()
        return np.asarray(features, dtype=np.float64) @ w + b

    def folded(self) -> tuple[NDArray[np.float64], float]:
        """Weights and intercept that apply to raw (unstandardised) features directly."""
        w = self.weights / self.scale
        return w, float(self.intercept - w @ self.mean)

    def probability(self, decision: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """Calibrated probability of a vehicle for decision values."""
        z = np.clip(self.platt_a * np.asarray(decision, dtype=np.float64) + self.platt_b, -50, 50)
        return np.asarray(1.0 / (1.0 + np.exp(z)))

    def decision_at(self, probability: float) -> float:
        """The decision value whose calibrated probability is `probability` (in (0, 1)), less a
        hair, so that every decision reaching that probability, rounded as it may be, reaches it."""
        return float((np.log(1.0 / probability - 1.0) - self.platt_b) / self.platt_a) - 1e-6

    def predict_proba(self, features: NDArray[np.floating[Any]]) -> NDArray[np.float64]:
        """Calibrated probability of a vehicle for each row of raw features."""
        return self.probability(self.decision_function(features))

    def predict(self, features: NDArray[np.floating[Any]]) -> NDArray[np.int8]:
        """1 for vehicle, 0 otherwise (decision value above zero)."""
        return (self.decision_function(features) > 0).astype(np.int8)


def _versions() -> dict[str, str]:
    import cv2
    import sklearn

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "scikit-learn": sklearn.__version__,
    }


def save_model(model: VehicleModel, path: Path) -> None:
    """Write the model to `path` as .npz of arrays plus a JSON header (the caller makes the write
    atomic)."""
    header = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "feature_config": model.config.to_dict(),
        "feature_length": model.config.length,
        "intercept": model.intercept,
        "platt_a": model.platt_a,
        "platt_b": model.platt_b,
        "report": model.report,
        "versions": _versions(),
    }
    arrays = {
        "weights": model.weights.astype(np.float64),
        "mean": model.mean.astype(np.float64),
        "scale": model.scale.astype(np.float64),
        "scalars": np.array([model.intercept, model.platt_a, model.platt_b]),
        "header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8),
    }
    with Path(path).open("wb") as handle:
        np.savez_compressed(handle, **arrays)  # type: ignore[arg-type]


def load_model(path: Path | None = None) -> VehicleModel:
    """Read a model file (the shipped one by default), checking format, version and shapes;
    never unpickles."""
    path = Path(path) if path is not None else default_model_path()
    if not path.is_file():
        raise ModelError(f"model file {path} does not exist")
    try:
        with np.load(io.BytesIO(path.read_bytes()), allow_pickle=False) as npz:
            arrays = {name: np.asarray(npz[name]) for name in (*ARRAYS, "header")}
        header = json.loads(arrays["header"].tobytes().decode())
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, UnicodeDecodeError):
        raise ModelError(f"model file {path} is corrupt or not a roadview model") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise ModelError(f"{path} is not a roadview vehicle model")
    if header.get("format_version") != FORMAT_VERSION:
        raise ModelError(
            f"model {path} has format version {header.get('format_version')}, this roadview "
            f"reads {FORMAT_VERSION}"
        )
    try:
        config = FeatureConfig(**header["feature_config"])
    except (TypeError, ValueError, KeyError):
        raise ModelError(f"model {path} has an invalid feature config") from None
    n = config.length
    for name in ("weights", "mean", "scale"):
        if arrays[name].shape != (n,):
            raise ModelError(
                f"model {path}: {name} has shape {arrays[name].shape}, expected "
                f"({n},) for its feature config"
            )
    if arrays["scalars"].shape != (3,) or not np.all(np.isfinite(arrays["weights"])):
        raise ModelError(f"model {path} has invalid values")
    if np.any(arrays["scale"] <= 0):
        raise ModelError(f"model {path} has non-positive feature scales")
    intercept, platt_a, platt_b = (float(v) for v in arrays["scalars"])
    return VehicleModel(
        config=config,
        weights=arrays["weights"],
        intercept=intercept,
        mean=arrays["mean"],
        scale=arrays["scale"],
        platt_a=platt_a,
        platt_b=platt_b,
        report=dict(header.get("report") or {}),
    )
