"""Training the force estimator on one bench recording: eq. 1, the GRU residual, the EKF.

Kept apart from `estimator.py` (the model, its files and its causal path) because
training owns the choices made on data: which blocks validate (`regimes.py`: every
operating regime in both parts), when the GRU stops, what the EKF's noise is and
whether the EKF is used at all. Each of these choices, left naive, rewards an
estimator that learned nothing; the rules here are the ones that prevent it:

- validation blocks represent the recording's speed bands (with reversals and rest),
  directions and load levels, and the summary gives the validation error per regime;
- the GRU trains with the paper's settings plus the regularisation of `GruConfig`,
  stopped early on that validation, on the window and, by default, the memory
  features of `memory.py` (without them it learned nothing of hysteresis that carried
  over to other blocks);
- the EKF's Q and R are tuned on the training blocks and checked on the validation
  blocks; where the filter does not improve the hybrid estimate there, it is set to
  pass the hybrid estimate through (`EkfSettings.passthrough`, which the causal path
  and the loop's kernel obey too), and the summary says so;
- the residual stage is the GRU, the boosted trees of `trees.py` on the same inputs,
  or (`auto`) whichever of the two has the lower physics+residual RMSE on the
  validation blocks, both trained on the same training blocks; the summary keeps
  both figures and the choice.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.ekf import EkfSettings, filter_forces, rest_variances
from teleop_core.estimation.extended import ExtendedPhysics, find_effects, physics_force
from teleop_core.estimation.gru import GruConfig, GruModel, TrainingHistory
from teleop_core.estimation.memory import memory_inputs
from teleop_core.estimation.metrics import lag_samples, rmse
from teleop_core.estimation.model import EstimateResult, ForceEstimator, features_of
from teleop_core.estimation.ranges import InputRange
from teleop_core.estimation.regimes import (
    RegimeRules,
    SplitReport,
    label_samples,
    regime_rmse,
    representative_split,
)
from teleop_core.estimation.trees import TreesConfig, TreesModel, train_trees
from teleop_core.follower.physics import PhysicsParams, fit_physics
from teleop_core.follower.recording import FollowerRecording
from teleop_core.progress import Progress, no_progress

RESIDUAL_CHOICES = ("gru", "trees", "auto")
"""`study estimator train --residual`: the GRU, the trees, or the better on validation."""
R_PHYSICS_SCALES = (1.0, 4.0, 16.0)
"""Multiples of eq. 1's training error variance tried as the EKF's physics-model R."""


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
    validation_rmse_by_regime_n: dict[str, dict[str, float]] = field(default_factory=dict)
    """Per regime label (`regimes.LABELS`): validation samples and RMSE of each stage."""
    split: dict[str, Any] = field(default_factory=dict)
    """The validation blocks and each regime's share overall, in training, in validation."""
    regime_rules: dict[str, float] = field(default_factory=dict)
    ekf_check: dict[str, Any] = field(default_factory=dict)
    """Validation RMSE of the hybrid estimate and of the filter, and whether it passes through."""
    config: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    residual: dict[str, Any] = field(default_factory=dict)
    """The residual stage asked for (`requested`), the one kept (`chosen`), and the
    validation RMSE of physics+residual for each stage trained (`validation_rmse_n`)."""

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
    r_physics_scales: tuple[float, ...] = (1.0,),
) -> tuple[EkfSettings, float]:
    """Choose Q (and the physics-model R, among `r_physics_scales` times the base's) on
    training data: the lowest error against F_ref among the settings that trail the
    hybrid estimate by at most `max_lag_samples` (one pipeline period).

    [endovascular], IV-C tuned Q "to minimise tracking delay", capped where noise grew; here
    the cap is the lag and the choice the error. Returns the settings and their lag.
    """
    best: tuple[float, EkfSettings, float] | None = None
    for scale in r_physics_scales:
        for q in np.logspace(-5, 0, 21):
            settings = replace(
                base,
                q_physics_n2=float(q),
                q_hybrid_n2=float(q),
                r_physics_model_n2=base.r_physics_model_n2 * scale,
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


def _effects_note(found: ExtendedPhysics | None, report: dict[str, Any]) -> str:
    """What the effect search (`find_effects`) did, for the summary's notes."""
    held = report["held_out"]
    where = (
        f"on the held-out end of the training recording ({held['start_s']:.1f}-"
        f"{held['end_s']:.1f} s): RMSE {report['rmse_before']:.4f} N with eq. 1"
    )
    if found is None:
        return f"effects: none added to eq. 1 {where}; the GRU learns the whole residual"
    return (
        f"effects found and added to eq. 1 before the GRU: {', '.join(found.families)} "
        f"{where}, {report['rmse_after']:.4f} N with them (verdict {report['verdict']})"
    )


def _ekf_base(
    recording: FollowerRecording, train_mask: np.ndarray, residual: Float1D, gru_val_rmse: float
) -> tuple[EkfSettings, bool]:
    """R from the training blocks: sensor noise at rest, eq. 1's and the GRU's own error."""
    rest = rest_variances(
        recording.iq[train_mask], recording.omega[train_mask], recording.alpha[train_mask]
    )
    base = EkfSettings(
        r_physics_model_n2=max(float(np.var(residual[train_mask])), 1e-6),
        r_gru_n2=max(gru_val_rmse**2, 1e-6),
    )
    if rest is not None:
        base = replace(base, r_iq_a2=max(rest[0], 1e-9), r_omega_rad2_s2=rest[1])
    return base, rest is not None


def train_estimator(
    recording: FollowerRecording,
    config: GruConfig | None = None,
    *,
    seed: int = 0,
    wheel_radius_m: float = PhysicsParams.wheel_radius_m,
    sign_speed_rad_s: float = PhysicsParams.sign_speed_rad_s,
    pipeline_rate_hz: float = ForceEstimator.pipeline_rate_hz,
    physics: PhysicsParams | None = None,
    ekf_q_n2: float | None = None,
    progress: Progress = no_progress,
    extension: ExtendedPhysics | None = None,
    effects: bool = False,
    residual_stage: str = "gru",
    trees: TreesConfig | None = None,
) -> tuple[ForceEstimator, TrainingSummary]:
    """Fit eq. 1, train the GRU on its residual, and set up the EKF, on one recording.

    `physics` given (e.g. from a calibration) skips the eq. 1 fit; `ekf_q_n2` given
    fixes the EKF process noise (both states) instead of tuning it. The physics fit,
    the GRU's standardisation and input range and the EKF noise use the training blocks
    only; the validation blocks choose the GRU's epoch and whether the EKF is used.
    `extension` (a `study calibrate` report, `extended.py`) replaces eq. 1 by the
    calibrated model, whose eq. 1 part also serves the EKF, and the GRU learns what
    that model still misses. `effects` (without `extension` or `physics`) runs the
    calibration loop on the recording first (`extended.find_effects`): the effects it
    adds to eq. 1 are the first part of the correction, the GRU learns the rest, and
    F_physics stays eq. 1 fitted alone. `residual_stage` is `gru`, `trees` (`trees.py`,
    with `trees`'s settings) or `auto`: both, on the same training blocks, and the one
    with the lower validation RMSE of physics+residual is kept.
    """
    if residual_stage not in RESIDUAL_CHOICES:
        raise TeleopInputError(
            f"residual stage {residual_stage!r}; expected one of {', '.join(RESIDUAL_CHOICES)}"
        )
    config = config or GruConfig()
    recording, notes = _regularly_sampled(recording)
    T = config.window
    blocks = _validation_blocks(recording, config, seed)
    notes += blocks.notes
    train_idx, val_idx = blocks.train_idx, blocks.val_idx
    physics, extension, physics_notes = _physics_stage(
        recording,
        blocks.train_mask,
        physics,
        extension,
        effects=effects,
        wheel_radius_m=wheel_radius_m,
        sign_speed_rad_s=sign_speed_rad_s,
        progress=progress,
    )
    notes += physics_notes
    f_phys_all = physics_force(physics, extension, recording)
    residual = recording.f_ref - f_phys_all  # r_t = F_ref - F_physics   (eq. 13)
    features = features_of(recording)
    # [I_q, theta_d, theta_dd] and the memory features of config.memory (memory.py)
    inputs = memory_inputs(recording.t, features, config.memory)
    stages = _residual_stages(
        inputs, residual, config, blocks, residual_stage, trees, seed=seed, progress=progress
    )
    # physics+residual against F_ref on the validation windows: the residual's own error,
    # from each stage's float64 prediction (the GRU's history is PyTorch's float32)
    target = residual[T - 1 :]
    stage_val = {
        name: rmse(model.predict(inputs)[val_idx], target[val_idx])
        for name, (model, _) in stages.items()
    }
    chosen = min(stage_val, key=stage_val.__getitem__)
    gru, history = stages[chosen]
    if residual_stage == "auto":
        notes.append(
            f"residual stage chosen on the validation blocks: {chosen} (physics+residual "
            + ", ".join(f"{name} {v:.4f} N" for name, v in stage_val.items())
            + ")"
        )
    rate = recording.sample_rate_hz
    train_samples = np.unique((train_idx[:, None] + np.arange(T)).ravel())
    input_range = InputRange.fit(features[train_samples])
    base, rest_found = _ekf_base(recording, blocks.train_mask, residual, history.best_val_rmse)
    if not rest_found:
        notes.append("the wheel is never at rest: EKF R from the default sensor noise")
    estimator = ForceEstimator(physics, gru, base, rate, pipeline_rate_hz, extension, input_range)
    result = estimator.predict(recording)
    omega = recording.omega[T - 1 :]
    settings, lag = _process_noise(
        physics, base, result, omega, train_idx, rate, pipeline_rate_hz, ekf_q_n2
    )
    # The filter runs over the whole recording (its state carries across the blocks),
    # and is judged on the validation blocks against the hybrid estimate it filters.
    result.f_final = _filtered(settings, physics, rate, result, omega)
    ekf_check = _ekf_check(result, val_idx)
    if ekf_check["passthrough"]:
        settings = replace(settings, passthrough=True)
        result.f_final = result.f_hybrid.copy()
        lag = 0.0
        notes.append(
            f"the EKF did not improve the hybrid estimate on the validation blocks "
            f"({ekf_check['validation_rmse_filtered_n']:.4f} N against "
            f"{ekf_check['validation_rmse_hybrid_n']:.4f} N): it passes the hybrid "
            "estimate through"
        )
    estimator = ForceEstimator(
        physics, gru, settings, rate, pipeline_rate_hz, extension, input_range
    )
    val_masks = {label: m[T - 1 :][val_idx] for label, m in blocks.masks.items()}
    summary = TrainingSummary(
        window=T,
        epochs_run=len(history.val_rmse),
        best_epoch=history.best_epoch,
        sample_rate_hz=rate,
        train_samples=len(train_idx),
        validation_samples=len(val_idx),
        train_rmse_n=_stage_rmse(result, train_idx),
        validation_rmse_n=_stage_rmse(result, val_idx),
        history={"train_rmse_n": history.train_rmse, "validation_rmse_n": history.val_rmse},
        ekf_rest_samples_found=rest_found,
        ekf_lag_s=lag / rate,
        recording=recording.name,
        recording_sha256=recording.sha256(),
        seed=seed,
        validation_rmse_by_regime_n=regime_rmse(
            val_masks,
            result.f_ref[val_idx],
            physics=result.f_physics[val_idx],
            hybrid=result.f_hybrid[val_idx],
            final=result.f_final[val_idx],
        ),
        split=dict(blocks.split),
        regime_rules=blocks.rules.to_dict(),
        ekf_check=ekf_check,
        config=asdict(config) | ({"trees": asdict(trees)} if trees is not None else {}),
        notes=notes,
        residual={
            "requested": residual_stage,
            "chosen": chosen,
            "validation_rmse_n": stage_val,
        },
    )
    return estimator, summary


def _regularly_sampled(recording: FollowerRecording) -> tuple[FollowerRecording, list[str]]:
    """`recording`, resampled at its nominal rate when a sample interval strays more than
    10 % from the median; and the note saying so."""
    dt = np.diff(recording.t)
    if np.max(np.abs(dt / np.median(dt) - 1.0)) > 0.1:
        recording = recording.resampled(recording.sample_rate_hz)
        return recording, [f"irregular sampling: resampled to {recording.sample_rate_hz:.6g} Hz"]
    return recording, []


@dataclass(frozen=True)
class _Blocks:
    """The training and validation windows of one recording (`representative_split`)."""

    train_idx: np.ndarray
    """Training windows, by their first sample."""
    val_idx: np.ndarray
    """Validation windows, by their first sample."""
    train_mask: np.ndarray
    """Per sample: it ends a training window."""
    masks: dict[str, np.ndarray]
    """Per regime label (`regimes.label_samples`): the samples in that regime."""
    split: SplitReport
    """`representative_split`'s account: the blocks, each regime's shares, those missing."""
    rules: RegimeRules
    """The speed and load thresholds the regimes were labelled with."""
    notes: list[str]
    """What the summary says about the split (regimes missing from a part)."""


def _validation_blocks(recording: FollowerRecording, config: GruConfig, seed: int) -> _Blocks:
    """Label the samples by regime and choose validation blocks that hold every regime
    (`representative_split`); a recording too short for the blocks is bad input."""
    T = config.window
    n_windows = len(recording) - T + 1
    if n_windows < 2 * config.blocks:
        raise TeleopInputError(
            f"recording {recording.name} has {len(recording)} samples; expected at least "
            f"{2 * config.blocks + T - 1} for a window of {T} and {config.blocks} blocks"
        )
    rules = RegimeRules.for_loads(recording.f_ref)
    masks = label_samples(recording.omega, recording.f_ref, recording.sample_rate_hz, rules)
    train_idx, val_idx, split = representative_split(
        masks, n_windows, T, config.blocks, config.validation_fraction, seed
    )
    notes = []
    if split["missing"]:
        notes.append(
            "no choice of validation blocks holds every regime in both parts; missing: "
            + ", ".join(split["missing"])
        )
    train_mask = np.zeros(len(recording), bool)
    train_mask[train_idx + T - 1] = True
    return _Blocks(train_idx, val_idx, train_mask, masks, split, rules, notes)


def _physics_stage(
    recording: FollowerRecording,
    train_mask: np.ndarray,
    physics: PhysicsParams | None,
    extension: ExtendedPhysics | None,
    *,
    effects: bool,
    wheel_radius_m: float,
    sign_speed_rad_s: float,
    progress: Progress,
) -> tuple[PhysicsParams, ExtendedPhysics | None, list[str]]:
    """Eq. 1 and the effects added to it: `physics` and `extension` as given, the
    effects found on the recording (`effects`), and eq. 1 fitted on the training
    samples where no parameters are given; and the notes saying which."""
    notes = []
    if extension is None and physics is None and effects:
        progress("finding the effects eq. 1 lacks")
        extension, report = find_effects(recording, wheel_radius_m=wheel_radius_m)
        notes.append(_effects_note(extension, report))
    if extension is not None and extension.stage == "physics":
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
    return physics, extension, notes


def _residual_stages(
    inputs: Float2D,
    residual: Float1D,
    config: GruConfig,
    blocks: _Blocks,
    residual_stage: str,
    trees: TreesConfig | None,
    *,
    seed: int,
    progress: Progress,
) -> dict[str, tuple[GruModel | TreesModel, TrainingHistory]]:
    """The residual stages `residual_stage` asks for, trained on the same training
    windows: the GRU (stopped early on the validation windows), the trees, or both."""
    train_idx, val_idx, T = blocks.train_idx, blocks.val_idx, config.window
    stages: dict[str, tuple[GruModel | TreesModel, TrainingHistory]] = {}
    if residual_stage in ("gru", "auto"):
        from teleop_core.estimation.gru_torch import train_gru

        net, gru_history, _, _ = train_gru(
            inputs, residual, config, seed=seed, split=(train_idx, val_idx), progress=progress
        )
        stages["gru"] = (net, gru_history)
    if residual_stage in ("trees", "auto"):
        boosted = train_trees(inputs, residual, T, config.memory, train_idx, trees, seed)
        fitted, target = boosted.predict(inputs), residual[T - 1 :]
        stages["trees"] = (
            boosted,
            TrainingHistory(
                train_rmse=[rmse(fitted[train_idx], target[train_idx])],
                val_rmse=[rmse(fitted[val_idx], target[val_idx])],
                best_epoch=1,
            ),
        )
    return stages


def _filtered(
    settings: EkfSettings,
    physics: PhysicsParams,
    rate_hz: float,
    result: EstimateResult,
    omega: Float1D,
) -> Float1D:
    """The EKF with `settings` over the whole prediction `result`."""
    return filter_forces(settings, physics, 1.0 / rate_hz, result.f_model, result.f_hybrid, omega)


def _process_noise(
    physics: PhysicsParams,
    base: EkfSettings,
    result: EstimateResult,
    omega: Float1D,
    train_idx: np.ndarray,
    rate_hz: float,
    pipeline_rate_hz: float,
    ekf_q_n2: float | None,
) -> tuple[EkfSettings, float]:
    """The EKF's settings and lag (samples): Q tuned on the training windows
    (`tune_process_noise`), or `ekf_q_n2` for both states when given."""
    if ekf_q_n2 is None:
        return tune_process_noise(
            physics,
            base,
            1.0 / rate_hz,
            result.f_model[train_idx],
            result.f_hybrid[train_idx],
            omega[train_idx],
            result.f_ref[train_idx],
            max_lag_samples=rate_hz / pipeline_rate_hz,
            r_physics_scales=R_PHYSICS_SCALES,
        )
    settings = replace(base, q_physics_n2=ekf_q_n2, q_hybrid_n2=ekf_q_n2)
    filtered = _filtered(settings, physics, rate_hz, result, omega)
    return settings, lag_samples(filtered[train_idx], result.f_hybrid[train_idx])


def _ekf_check(result: EstimateResult, val_idx: np.ndarray) -> dict[str, Any]:
    """Validation RMSE of the hybrid estimate and of the filter, and whether the filter
    passes the hybrid estimate through (it does not improve it)."""
    hybrid_val = rmse(result.f_hybrid[val_idx], result.f_ref[val_idx])
    filter_val = rmse(result.f_final[val_idx], result.f_ref[val_idx])
    return {
        "validation_rmse_hybrid_n": hybrid_val,
        "validation_rmse_filtered_n": filter_val,
        "passthrough": not filter_val < hybrid_val,
    }


def _stage_rmse(result: EstimateResult, rows: np.ndarray) -> dict[str, float]:
    """RMSE against F_ref of each stage of `result` over `rows`."""
    return {
        "physics": rmse(result.f_physics[rows], result.f_ref[rows]),
        "hybrid": rmse(result.f_hybrid[rows], result.f_ref[rows]),
        "final": rmse(result.f_final[rows], result.f_ref[rows]),
    } | (
        {}
        if result.f_effects is None
        else {"effects": rmse(result.f_effects[rows], result.f_ref[rows])}
    )
