"""The force estimator end to end: physics (eq. 1) -> GRU residual (eqs. 3-4) -> EKF.

`ForceEstimator.predict` runs over a whole recording; `ForceEstimator.stream()` gives a
`CausalEstimator` that takes one new sample at a time, as the 50 Hz pipeline does, and
produces the same numbers (a test holds them to 1e-12 N). `train_estimator` fits all
three stages to one bench recording; `save`/`load` keep them in a model folder:

| file | what |
|---|---|
| `physics.json` | fitted eq. 1 parameters (SI) |
| `gru.pt` | GRU weights, a PyTorch state dict for `GruNet` |
| `standardisation.json` | window, hidden size, input means/SDs, target scale |
| `ekf.json` | EKF noise covariances |
| `summary.json` | train/validation RMSE of each stage, epochs, sample rate, data digest |
| `calibration.json` | only for a calibrated model: eq. 1 plus the effects of a
  `study calibrate` report, the physics stage in place of eq. 1 (`extended.py`) |
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np
import pandas as pd

from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.ekf import (
    EKF_STATE_SIZE,
    EkfSettings,
    ekf_update,
    filter_forces,
    rest_variances,
    settings_vector,
)
from teleop_core.estimation.extended import ExtendedPhysics, physics_force
from teleop_core.estimation.gru import (
    GruConfig,
    GruModel,
    Standardisation,
    _window_forward,
    block_split,
    load_weights,
    save_weights,
    train_gru,
)
from teleop_core.estimation.metrics import lag_samples, rmse
from teleop_core.estimation.physics import PhysicsParams, fit_physics, force_at
from teleop_core.estimation.recording import FollowerRecording

MODEL_FILES = ("physics.json", "gru.pt", "standardisation.json", "ekf.json", "summary.json")
RATE_TOLERANCE = 0.02
"""A recording whose rate differs from the model's by more than this is resampled."""


def features_of(recording: FollowerRecording) -> Float2D:
    """Per-sample GRU inputs [I_q, theta_d, theta_dd], shape (n, 3)."""
    return np.column_stack([recording.iq, recording.omega, recording.alpha])


@dataclass
class EstimateResult:
    """Estimates for every sample with a full window; arrays of shape (n - T + 1,)."""

    t: Float1D
    f_ref: Float1D
    f_physics: Float1D
    f_hybrid: Float1D
    f_final: Float1D

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame(asdict(self))


@dataclass
class ForceEstimator:
    physics: PhysicsParams
    gru: GruModel
    ekf: EkfSettings
    sample_rate_hz: float
    pipeline_rate_hz: float = 50.0
    extension: ExtendedPhysics | None = None
    """The calibrated physics stage (issue 10) replacing eq. 1, if any."""

    @property
    def window(self) -> int:
        return self.gru.window

    @property
    def dt_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    def conform(self, recording: FollowerRecording) -> FollowerRecording:
        """The recording at the model's sample rate (resampled only if it differs)."""
        rate = recording.sample_rate_hz
        if abs(rate / self.sample_rate_hz - 1.0) > RATE_TOLERANCE:
            return recording.resampled(self.sample_rate_hz)
        return recording

    def predict(self, recording: FollowerRecording) -> EstimateResult:
        """Estimate the force over a recording already at the model's rate."""
        T = self.window
        if len(recording) < T:
            raise TeleopInputError(
                f"recording {recording.name} has {len(recording)} samples; expected at least "
                f"the estimator's window of {T}"
            )
        f_phys_all = physics_force(self.physics, self.extension, recording)
        delta = self.gru.predict(features_of(recording))
        f_physics = f_phys_all[T - 1 :]
        f_hybrid = f_physics + delta  # F*_GRU = F_physics + dF_resistance   (eq. 4)
        f_final = filter_forces(
            self.ekf, self.physics, self.dt_s, f_physics, f_hybrid, recording.omega[T - 1 :]
        )
        return EstimateResult(
            recording.t[T - 1 :], recording.f_ref[T - 1 :], f_physics, f_hybrid, f_final
        )

    def stream(self) -> CausalEstimator:
        if self.extension is not None:
            effects = ", ".join(self.extension.families)
            raise TeleopInputError(
                f"this estimator's physics stage is calibrated ({effects}): its effects "
                "need the whole recording, so it runs with predict(), not one sample at a time"
            )
        return CausalEstimator(self)

    def save(self, folder: Path, summary: dict[str, Any]) -> None:
        """Write the model folder, all or nothing (through a temporary sibling folder)."""
        folder = Path(folder)
        if not folder.parent.is_dir():
            raise TeleopInputError(f"folder {folder.parent} for the model does not exist")
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
        try:
            _write_json(tmp / "physics.json", self.physics.to_dict())
            save_weights(self.gru, str(tmp / "gru.pt"))
            _write_json(
                tmp / "standardisation.json",
                {
                    "window": self.window,
                    "hidden_size": int(self.gru.weights.w_hh.shape[1]),
                    "target": self.gru.target,
                    "sample_rate_hz": self.sample_rate_hz,
                    "pipeline_rate_hz": self.pipeline_rate_hz,
                    "features": ["iq", "omega", "alpha"],
                    **self.gru.standardisation.to_dict(),
                },
            )
            _write_json(tmp / "ekf.json", self.ekf.to_dict())
            _write_json(tmp / "summary.json", summary)
            if self.extension is not None:
                _write_json(tmp / "calibration.json", self.extension.to_dict())
            if folder.exists():
                shutil.rmtree(folder)
            tmp.rename(folder)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

    @classmethod
    def load(cls, folder: Path) -> ForceEstimator:
        folder = Path(folder)
        if not folder.is_dir():
            raise TeleopInputError(
                f"model folder {folder} does not exist; "
                "expected the --out of `study estimator train`"
            )
        missing = [f for f in MODEL_FILES if not (folder / f).is_file()]
        if missing:
            raise TeleopInputError(
                f"model folder {folder} has no {missing[0]}; expected a folder written by "
                "`study estimator train`"
            )
        try:
            physics = PhysicsParams(**_read_json(folder / "physics.json"))
            meta = _read_json(folder / "standardisation.json")
            std = Standardisation(
                tuple(meta["feature_mean"]),
                tuple(meta["feature_std"]),
                float(meta["target_mean"]),
                float(meta["target_std"]),
            )
            gru = GruModel(
                load_weights(str(folder / "gru.pt")), std, int(meta["window"]), meta["target"]
            )
            ekf = EkfSettings(**_read_json(folder / "ekf.json"))
            extension = None
            if (folder / "calibration.json").is_file():
                extension = ExtendedPhysics.from_dict(_read_json(folder / "calibration.json"))
            return cls(
                physics,
                gru,
                ekf,
                float(meta["sample_rate_hz"]),
                float(meta["pipeline_rate_hz"]),
                extension,
            )
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            if isinstance(exc, TeleopInputError):
                raise
            raise TeleopInputError(f"model folder {folder} is damaged: {exc}") from None


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise TeleopInputError(f"{path} is not valid JSON: {exc}") from None


class CausalEstimator:
    """The estimator fed one sample at a time; `update` returns None until a window is full.

    Its state lives in arrays and its steps are numba functions (`stream_push`,
    `stream_estimate`), so that the closed loop's compiled kernel can run the same
    estimator between its events; `arrays()` hands them over.
    """

    def __init__(self, estimator: ForceEstimator) -> None:
        self.est = estimator
        std = estimator.gru.standardisation
        w = estimator.gru.weights
        self.buffer = np.zeros((estimator.window, 3))
        self.state = np.zeros(STREAM_STATE_SIZE)
        self.ekf_state = np.zeros(EKF_STATE_SIZE)
        self.mean = np.asarray(std.feature_mean, dtype=np.float64)
        self.std = np.asarray(std.feature_std, dtype=np.float64)
        self.physics = estimator.physics.vector()
        self.ekf_settings = settings_vector(estimator.ekf)
        self.weights = (w.w_ih, w.w_hh, w.b_ih, w.b_hh, w.w_out, float(w.b_out))
        self.target = np.array([std.target_std, std.target_mean], dtype=np.float64)
        self.dt_s = estimator.dt_s
        self._out = np.zeros(3)

    def push(self, t: float, iq: float, omega: float, alpha: float | None = None) -> None:
        """Add a sample (s, A, rad/s, optionally rad/s^2) to the window without estimating:
        the 50 Hz pipeline sees every 100 Hz sample but estimates on every other one."""
        given = alpha is not None
        stream_push(
            self.state, self.buffer, self.mean, self.std, t, iq, omega,
            alpha if given else 0.0, given,
        )  # fmt: skip

    def estimate(self) -> tuple[float, float, float] | None:
        """(F_physics, F*_GRU, F*_Final) in N from the samples pushed so far, or None
        while the window fills."""
        ok = stream_estimate(
            self.state, self.buffer, self.physics, *self.weights, self.target,
            self.ekf_state, self.ekf_settings, self.dt_s, self._out,
        )  # fmt: skip
        if not ok:
            return None
        return float(self._out[0]), float(self._out[1]), float(self._out[2])

    def update(
        self, t: float, iq: float, omega: float, alpha: float | None = None
    ) -> tuple[float, float, float] | None:
        """Add a sample (s, A, rad/s, optionally rad/s^2) and estimate.

        Returns (F_physics, F*_GRU, F*_Final) in N, or None while the window fills.
        """
        self.push(t, iq, omega, alpha)
        return self.estimate()


# stream state: samples pushed, last (t, omega) and whether there is one, latest sample
S_COUNT, S_LAST_T, S_LAST_OMEGA, S_HAS_LAST, S_IQ, S_OMEGA, S_ALPHA = range(7)
STREAM_STATE_SIZE = 7


@numba.njit(cache=True)
def stream_push(
    st: np.ndarray,
    buf: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    t: float,
    iq: float,
    omega: float,
    alpha: float,
    alpha_given: bool,
) -> None:  # pragma: no cover - compiled; exercised through CausalEstimator
    if not alpha_given:
        # Backward difference, as FollowerRecording derives alpha.
        alpha = 0.0 if st[S_HAS_LAST] == 0.0 else (omega - st[S_LAST_OMEGA]) / (t - st[S_LAST_T])
    st[S_LAST_T], st[S_LAST_OMEGA], st[S_HAS_LAST] = t, omega, 1.0
    st[S_IQ], st[S_OMEGA], st[S_ALPHA] = iq, omega, alpha
    n = buf.shape[0]
    for i in range(n - 1):
        buf[i, 0], buf[i, 1], buf[i, 2] = buf[i + 1, 0], buf[i + 1, 1], buf[i + 1, 2]
    buf[n - 1, 0] = (iq - mean[0]) / std[0]
    buf[n - 1, 1] = (omega - mean[1]) / std[1]
    buf[n - 1, 2] = (alpha - mean[2]) / std[2]
    st[S_COUNT] += 1.0


@numba.njit(cache=True)
def stream_estimate(
    st: np.ndarray,
    buf: np.ndarray,
    pv: np.ndarray,
    w_ih: np.ndarray,
    w_hh: np.ndarray,
    b_ih: np.ndarray,
    b_hh: np.ndarray,
    w_out: np.ndarray,
    b_out: float,
    target: np.ndarray,
    ekf_state: np.ndarray,
    ekf_settings: np.ndarray,
    dt_s: float,
    out: np.ndarray,
) -> bool:  # pragma: no cover - compiled; exercised through CausalEstimator
    """Physics, GRU and EKF on the current window; False while it fills."""
    if st[S_COUNT] < buf.shape[0]:
        return False
    iq, omega, alpha = st[S_IQ], st[S_OMEGA], st[S_ALPHA]
    f_physics = force_at(pv, iq, omega, alpha)
    # F*_GRU = F_physics + GRU residual (eq. 3), de-standardised
    y = _window_forward(buf, w_ih, w_hh, b_ih, b_hh, w_out, b_out)
    f_hybrid = f_physics + y * target[0] + target[1]
    out[0] = f_physics
    out[1] = f_hybrid
    out[2] = ekf_update(ekf_state, ekf_settings, pv, dt_s, f_physics, f_hybrid, omega)
    return True


@dataclass
class TrainingSummary:
    window: int
    epochs_run: int
    best_epoch: int
    sample_rate_hz: float
    train_samples: int
    validation_samples: int
    train_rmse_n: dict[str, float]
    validation_rmse_n: dict[str, float]
    history: dict[str, list[float]]
    ekf_rest_samples_found: bool
    ekf_lag_s: float
    recording: str
    recording_sha256: str
    seed: int
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def tune_process_noise(
    physics: PhysicsParams,
    base: EkfSettings,
    dt_s: float,
    f_physics: Float1D,
    f_hybrid: Float1D,
    omega: Float1D,
    f_ref: Float1D,
    max_lag_samples: float,
) -> tuple[EkfSettings, float]:
    """Choose Q on training data: the lowest error against F_ref among the settings that
    trail the hybrid estimate by at most `max_lag_samples` (one pipeline period).

    Seed 000, IV-C tuned Q "to minimise tracking delay", capped where noise grew; here
    the cap is the lag and the choice the error. Returns the settings and their lag.
    """
    best: tuple[float, EkfSettings, float] | None = None
    for q in np.logspace(-5, 0, 21):
        settings = EkfSettings(
            **{**base.to_dict(), "q_physics_n2": float(q), "q_hybrid_n2": float(q)}
        )
        final = filter_forces(settings, physics, dt_s, f_physics, f_hybrid, omega)
        lag = lag_samples(final, f_hybrid)
        if lag > max_lag_samples:
            continue
        error = rmse(final, f_ref)
        if best is None or error < best[0]:
            best = (error, settings, lag)
    if best is None:  # pragma: no cover - the largest Q follows the hybrid estimate closely
        raise TeleopInputError("no process noise keeps the EKF within one pipeline period")
    return best[1], best[2]


def train_estimator(
    recording: FollowerRecording,
    config: GruConfig | None = None,
    *,
    seed: int = 0,
    wheel_radius_m: float = 0.010,
    sign_speed_rad_s: float = 0.3,
    pipeline_rate_hz: float = 50.0,
    physics: PhysicsParams | None = None,
    ekf_q_n2: float | None = None,
    progress: Callable[[int, float, float], None] | None = None,
    extension: ExtendedPhysics | None = None,
) -> tuple[ForceEstimator, TrainingSummary]:
    """Fit eq. 1, train the GRU on its residual, and set up the EKF, on one recording.

    `physics` given (e.g. from a calibration) skips the eq. 1 fit; `ekf_q_n2` given
    fixes the EKF process noise (both states) instead of tuning it. The physics fit,
    the GRU's standardisation and the EKF noise all use the training blocks only.
    `extension` (a `study calibrate` report, `extended.py`) replaces eq. 1 by the
    calibrated model, whose eq. 1 part also serves the EKF, and the GRU learns what
    that model still misses.
    """
    config = config or GruConfig()
    notes: list[str] = []
    dt = np.diff(recording.t)
    if np.max(np.abs(dt / np.median(dt) - 1.0)) > 0.1:
        recording = recording.resampled(recording.sample_rate_hz)
        notes.append(f"irregular sampling: resampled to {recording.sample_rate_hz:.6g} Hz")
    T = config.window
    n_windows = len(recording) - T + 1
    if n_windows < 2 * config.blocks:
        raise TeleopInputError(
            f"recording {recording.name} has {len(recording)} samples; expected at least "
            f"{2 * config.blocks + T - 1} for a window of {T} and {config.blocks} blocks"
        )
    train_idx, val_idx = block_split(n_windows, T, config, seed)
    train_mask = np.zeros(len(recording), bool)
    train_mask[train_idx + T - 1] = True
    if extension is not None:
        physics = extension.base
        notes.append(
            f"physics stage calibrated by {extension.source or 'a report'}: eq. 1 + "
            + (", ".join(extension.families) or "no effect")
        )
    if physics is None:
        physics = fit_physics(
            recording,
            wheel_radius_m=wheel_radius_m,
            sign_speed_rad_s=sign_speed_rad_s,
            mask=train_mask,
        )
    f_phys_all = physics_force(physics, extension, recording)
    residual = recording.f_ref - f_phys_all  # r_t = F_ref - F_physics   (eq. 13)
    gru, history, _, _ = train_gru(
        features_of(recording),
        residual,
        config,
        seed=seed,
        split=(train_idx, val_idx),
        progress=progress,
    )
    rate = recording.sample_rate_hz
    rest = rest_variances(
        recording.iq[train_mask], recording.omega[train_mask], recording.alpha[train_mask]
    )
    physics_error = float(np.var(residual[train_mask]))
    base = EkfSettings(
        r_physics_model_n2=max(physics_error, 1e-6), r_gru_n2=max(history.best_val_rmse**2, 1e-6)
    )
    if rest is None:
        notes.append("the wheel is never at rest: EKF R from the default sensor noise")
    else:
        base = EkfSettings(
            **{**base.to_dict(), "r_iq_a2": max(rest[0], 1e-9), "r_omega_rad2_s2": rest[1]}
        )
    estimator = ForceEstimator(physics, gru, base, rate, pipeline_rate_hz, extension)
    result = estimator.predict(recording)
    f_physics, f_hybrid = result.f_physics[train_idx], result.f_hybrid[train_idx]
    omega = recording.omega[T - 1 :][train_idx]
    if ekf_q_n2 is None:
        settings, lag = tune_process_noise(
            physics,
            base,
            1.0 / rate,
            f_physics,
            f_hybrid,
            omega,
            result.f_ref[train_idx],
            max_lag_samples=rate / pipeline_rate_hz,
        )
    else:
        q = {"q_physics_n2": ekf_q_n2, "q_hybrid_n2": ekf_q_n2}
        settings = EkfSettings(**{**base.to_dict(), **q})
        final = filter_forces(settings, physics, 1.0 / rate, f_physics, f_hybrid, omega)
        lag = lag_samples(final, f_hybrid)
    estimator = ForceEstimator(physics, gru, settings, rate, pipeline_rate_hz, extension)
    # Only the EKF stage changed: refilter instead of running the GRU over the data again.
    result.f_final = filter_forces(
        settings, physics, 1.0 / rate, result.f_physics, result.f_hybrid, recording.omega[T - 1 :]
    )

    def stage_rmse(rows: np.ndarray) -> dict[str, float]:
        return {
            "physics": rmse(result.f_physics[rows], result.f_ref[rows]),
            "hybrid": rmse(result.f_hybrid[rows], result.f_ref[rows]),
            "final": rmse(result.f_final[rows], result.f_ref[rows]),
        }

    summary = TrainingSummary(
        window=T,
        epochs_run=len(history.val_rmse),
        best_epoch=history.best_epoch,
        sample_rate_hz=rate,
        train_samples=len(train_idx),
        validation_samples=len(val_idx),
        train_rmse_n=stage_rmse(train_idx),
        validation_rmse_n=stage_rmse(val_idx),
        history={"train_rmse_n": history.train_rmse, "validation_rmse_n": history.val_rmse},
        ekf_rest_samples_found=rest is not None,
        ekf_lag_s=lag / rate,
        recording=recording.name,
        recording_sha256=recording.sha256(),
        seed=seed,
        notes=notes,
    )
    return estimator, summary
