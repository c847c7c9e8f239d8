"""Base physics models the calibration loop starts from, and the data each one reads.

A base model is linear in its coefficients: `columns(signals)` gives the regressors
whose weighted sum is the reference force (N), `physical(coef)` names the fitted
coefficients as physical parameters. This owns the link from a recording contract to
the loop's named signals (`t`, `drive`, `speed`, `accel`, `angle`), so that the loop
and the effect library never see a device's column names.

- `FollowerBase`: eq. 1 of [endovascular] solved for F, with a smoothed sign and an offset:
  F = (K_t I_q - J theta_dd - b theta_d - tau_c tanh(theta_d / w_s)) / r + F_0. The
  sign's width w_s is one of the base model's own assumptions, so
  the loop fits it on the training block (`fit_sign_speed`) before anything else: a
  drive whose Coulomb step is sharper than the estimator's 0.3 rad/s would otherwise
  leave a residual near rest that a wrong family (`stribeck`) takes.
- `MasterBase`: the dial's current-to-force calibration, one quadratic
  F = a i^2 + b i + c (i in mA), i.e. eqs. 14-15 without the loading/unloading split;
  the split is what the `hysteresis` effect should find. Its recording contract is
  `t` [s], `current_ma` [mA], `f_ref` [N] (`MASTER_COLUMNS`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.calibration.effects import (
    EFFECTS,
    FAMILIES,
    SIGN_SPEED_RAD_S,
    DriveDirectionAsymmetry,
    Effect,
    Hysteresis,
    Signals,
    smooth_sign,
)
from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import FollowerPlantParams
from teleop_core.follower.physics import RC_B, RC_F0, RC_J, RC_KT, RC_TC
from teleop_core.follower.recording import FollowerRecording, read_checked_csv
from teleop_core.recording_checks import MIN_SPREAD

MASTER_COLUMNS = ("t", "current_ma", "f_ref")
"""The master's current-force calibration recording: time, commanded current, gauge force."""


@dataclass(frozen=True)
class CalibrationData:
    """What the loop fits: named signals (each (n,)) and the reference force y (N)."""

    signals: Signals
    """Named inputs, each of shape (n,), `t` [s] among them (`effects.Signals`)."""
    y: Float1D
    """The reference force (or torque) the model predicts, shape (n,)."""
    name: str = "recording"
    """The recording's name in reports and errors."""
    held_out_blocks: int = 1
    """How many blocks the held-out share is cut into, spread evenly over the recording
    (1: one block at its end). A chirp sweeps its frequency with time, so its end holds
    only the highest frequencies and says nothing about the rest; blocked hold-out
    tests it on every part of the sweep."""
    preparation: dict[str, float] | None = None
    """How the signals were derived from the recording (the rigid axis's fitted
    derivative cutoff), reported with the result."""

    def __post_init__(self) -> None:
        n = len(self.y)
        if self.held_out_blocks < 1:
            raise TeleopInputError(
                f"held_out_blocks = {self.held_out_blocks!r}; expected a whole number >= 1"
            )
        if "t" not in self.signals or any(len(v) != n for v in self.signals.values()):
            raise TeleopInputError(
                f"calibration data {self.name}: signals {sorted(self.signals)} must include "
                f"'t' and all have the {n} samples of the reference force"
            )
        # an all-zero recording has nothing to fit: one line, not a traceback
        y = np.asarray(self.y, float)
        if n and 0.0 < float(np.ptp(y)) < MIN_SPREAD:
            raise TeleopInputError(
                f"calibration data {self.name}: the reference force (or torque) varies by "
                f"only {float(np.ptp(y)):.3g}; expected a force in SI units varying by at "
                f"least {MIN_SPREAD:g} (the fit's squares would underflow to 0)"
            )
        if n and float(np.ptp(y)) == 0.0:
            raise TeleopInputError(
                f"calibration data {self.name}: the reference force (or torque) is "
                f"{float(y[0])!r} on every sample; expected a measured force that varies "
                "(a recording that excites the model)"
            )
        inputs = {k: np.asarray(v, float) for k, v in self.signals.items() if k != "t"}
        if inputs and all(float(np.ptp(v)) == 0.0 for v in inputs.values() if len(v)):
            raise TeleopInputError(
                f"calibration data {self.name}: every signal ({', '.join(sorted(inputs))}) "
                "is constant; expected a recording that moves the axis"
            )

    def __len__(self) -> int:
        return len(self.y)


class BaseModel:
    """A base model; subclasses set the class attributes and `columns`/`physical`."""

    name: str = ""
    unit: str = "n"
    """Suffix of the output quantity in parameter names (`n_m` for torques)."""
    out: float = 1.0
    """Factor from a coefficient in N to the output quantity (r for torques)."""
    families: tuple[str, ...] = FAMILIES
    """Candidate families that apply to this model's signals."""
    plot_against: tuple[str, ...] = ("t",)
    """Signals the residual figures are drawn against."""
    overrides: dict[str, Effect] = {}  # noqa: RUF012 - read only
    """This model's own settings of a family (the master's quadratic hysteresis loop)."""
    passive_loop_sign: int | None = None
    """Sign of a physical `hysteresis` loop's half height in this model's convention
    (`plausibility.py`): +1, -1, or None where the sign is not checked."""
    output_unit: str = "N"
    """Unit of the output the model predicts, as reports print it ("N" or "N m")."""

    def units(self) -> dict[str, str]:
        """The units the recording contract gives this model's output and signals (the
        report's `units`)."""
        return {"output": self.output_unit}

    def reader_for(self, preparation: dict[str, float] | None) -> BaseModel:
        """This model as it reads another recording of the same machine (a validation
        recording): with what reading the training recording fitted
        (`CalibrationData.preparation`) fixed, so that both recordings' signals are
        derived alike; the model itself where reading fits nothing."""
        return self

    def fitted_to(
        self, data: CalibrationData, train: slice | np.ndarray, chain: Sequence = ()
    ) -> BaseModel:
        """This model with its own assumptions fitted on the `train` rows of `data`
        together with the effects of `chain` ((effect, searched value) pairs; the loop
        calls it before anything else and again after each effect it adds); the model
        itself where it has none."""
        return self

    def effect(self, family: str) -> Effect:
        """The candidate `family` (or open library term) as this model uses it."""
        # here, not at the top: importing teleop_core.calibration.library imports this module
        from teleop_core.calibration.library import OPEN_TERMS

        if family in OPEN_TERMS and family not in self.overrides:
            return OPEN_TERMS[family]
        return self.overrides.get(family, EFFECTS[family])

    def columns(self, s: Signals) -> Float2D:
        raise NotImplementedError

    def physical(self, coef: Float1D) -> dict[str, float]:
        raise NotImplementedError

    def rename(self, family: str, params: dict[str, float]) -> dict[str, float]:
        """An effect's physical parameters under this model's names (same order)."""
        return params

    def read(self, path: str | Path) -> CalibrationData:
        raise NotImplementedError


@dataclass(frozen=True)
class FollowerBase(BaseModel):
    """Eq. 1 of [endovascular] with an offset, for a follower recording (`recording.py`)."""

    wheel_radius_m: float = FollowerPlantParams.wheel_radius_m
    """r, known (the wheel's measured radius); only ratios to r are identifiable."""
    sign_speed_rad_s: float | None = None
    """w_s of the smoothed sign tanh(theta_d / w_s), rad/s; > 0. None: fitted on the
    training block by the loop (`fitted_to`), and the estimator's 0.3 rad/s where the
    model is used unfitted."""

    name = "follower"
    unit = "n_m"
    plot_against = ("t", "speed", "angle")
    overrides = {"direction_asymmetry": DriveDirectionAsymmetry()}  # noqa: RUF012 - read only
    passive_loop_sign = +1
    """The load is what the speed loop's current answers: the force leads the current
    drawn for it, so a loss between them reads as a force above eq. 1 while the current
    rises (the loop `synthetic.py` injects). A negative one is no such loss."""

    def __post_init__(self) -> None:
        if not self.wheel_radius_m > 0:
            raise TeleopInputError(f"wheel_radius_m = {self.wheel_radius_m!r}; expected > 0")
        if self.sign_speed_rad_s is not None and not self.sign_speed_rad_s > 0:
            raise TeleopInputError(
                f"sign_speed_rad_s = {self.sign_speed_rad_s!r}; expected > 0 or None (fitted)"
            )

    @property
    def sign_width_rad_s(self) -> float:
        """w_s in use: the fitted or given one, else the estimator's."""
        return SIGN_SPEED_RAD_S if self.sign_speed_rad_s is None else self.sign_speed_rad_s

    def fitted_to(
        self, data: CalibrationData, train: slice | np.ndarray, chain: Sequence = ()
    ) -> FollowerBase:
        if self.sign_speed_rad_s is not None:
            return self
        width = fit_sign_speed(self, data.signals, data.y, train, chain)
        return replace(self, sign_speed_rad_s=width)

    @property
    def out(self) -> float:  # type: ignore[override]
        return self.wheel_radius_m

    def columns(self, s: Signals) -> Float2D:
        # F = (K_t I_q - J theta_dd - b theta_d - tau_c sgn(theta_d)) / r + F_0   (eq. 1),
        # the columns of `follower.physics.regressors` (RC_*)
        w = s["speed"]
        sign = smooth_sign(w, self.sign_width_rad_s)
        return np.column_stack([s["drive"], -s["accel"], -w, -sign, np.ones_like(w)])

    def physical(self, coef: Float1D) -> dict[str, float]:
        r = self.wheel_radius_m
        return {
            "torque_constant_n_m_per_a": coef[RC_KT] * r,
            "inertia_kg_m2": coef[RC_J] * r,
            "viscous_damping_n_m_s_per_rad": coef[RC_B] * r,
            "coulomb_friction_n_m": coef[RC_TC] * r,
            "offset_n": coef[RC_F0],
        }

    def data(self, rec: FollowerRecording) -> CalibrationData:
        signals = {"t": rec.t, "drive": rec.iq, "speed": rec.omega, "accel": rec.alpha}
        signals.update(angle=rec.theta, direction=rec.omega)
        return CalibrationData(signals, rec.f_ref, rec.name)

    def read(self, path: str | Path) -> CalibrationData:
        return self.data(FollowerRecording.from_csv(path))


@dataclass(frozen=True)
class MasterBase(BaseModel):
    """One quadratic current-to-force characteristic (eqs. 14-15 without the split)."""

    name = "master"
    families = ("hysteresis", "delay", "drift", "current_nonlinearity")
    # passive_loop_sign stays None: the paper's loading and unloading branches (eqs.
    # 14-15) cross near 2 mA, so the dial's own loop changes sign over its range
    overrides = {"hysteresis": Hysteresis(degree=2)}  # noqa: RUF012 - read only
    plot_against = ("t", "drive")

    def columns(self, s: Signals) -> Float2D:
        i = s["drive"]
        # F = a i^2 + b i + c   (eqs. 14-15, one branch)
        return np.column_stack([i * i, i, np.ones_like(i)])

    def physical(self, coef: Float1D) -> dict[str, float]:
        return {"a_n_per_ma2": coef[0], "b_n_per_ma": coef[1], "c_n": coef[2]}

    def data_from_arrays(
        self, t: Float1D, current_ma: Float1D, f_ref: Float1D, name: str = "recording"
    ) -> CalibrationData:
        signals = {"t": np.asarray(t, float), "drive": np.asarray(current_ma, float)}
        return CalibrationData(signals, np.asarray(f_ref, float), name)

    def read(self, path: str | Path) -> CalibrationData:
        v = read_checked_csv(path, MASTER_COLUMNS)
        return self.data_from_arrays(v["t"], v["current_ma"], v["f_ref"], Path(path).name)


SIGN_WIDTHS_RAD_S = np.geomspace(0.002, SIGN_SPEED_RAD_S, 25)
"""Widths w_s of eq. 1's smoothed sign tried, rad/s: from a step sharper than any
speed sensor resolves up to the estimator's 0.3 rad/s, never wider. A wider "step"
is friction that changes with speed, which is the families' to name: left free, the
width goes to 2 rad/s on a recording with a nonlinear drag and stands in for it."""


def fit_sign_speed(
    model: FollowerBase,
    signals: Signals,
    y: Float1D,
    train: slice | np.ndarray,
    chain: Sequence = (),
) -> float:
    """The width w_s of eq. 1's sign as sharp as the training data allow, rad/s.

    The base model's least-squares fit on the `train` rows for each width of
    `SIGN_WIDTHS_RAD_S`; the sharpest width whose training SSE is within 0.1 % of the
    best is taken. A drive's Coulomb step is sharp; only the speed sensor's noise and
    a real pre-sliding range smear it, and those the data show. On eq. 1's own
    recordings (w_s = 0.3) it gives back 0.3; on ones with a step of 0.02 rad/s and
    the speed sensor's 0.01 rad/s noise, 0.06-0.08.

    With `chain`, the effects' columns join the fit: an effect the base model lacks
    (a ripple, a hysteresis loop) fills the training SSE so that 0.1 % of it spans
    every width, and the sharpest is taken however wrong; the loop refits the width
    once the effect is in its chain.
    """
    # the design of base + chain (`fitting.design`, which imports this module): the
    # effects' signals and columns do not depend on the width, so they are made once,
    # and so is everything of the normal equations but the sign's column and its blocks
    for effect, value in chain:
        signals = effect.transform(signals, value)
    base = model.columns(signals)
    fixed = np.column_stack(
        [np.delete(base, RC_TC, axis=1)]
        + [effect.columns(signals, value) for effect, value in chain]
    )[train]
    target = np.asarray(y, float)[train]
    scale = np.maximum(np.abs(fixed).max(axis=0), 1e-12)
    fixed = fixed / scale
    gram, rhs = fixed.T @ fixed, fixed.T @ target
    sse = []
    for width in SIGN_WIDTHS_RAD_S:
        sign = replace(model, sign_speed_rad_s=float(width)).columns(signals)[train, RC_TC]
        sse.append(_sse_with(fixed, gram, rhs, sign, target))
    near = np.flatnonzero(np.asarray(sse) <= 1.001 * min(sse))
    return float(SIGN_WIDTHS_RAD_S[near[0]])


def _sse_with(fixed: Float2D, gram: Float2D, rhs: Float1D, column: Float1D, y: Float1D) -> float:
    """Least-squares SSE of y on the scaled columns `fixed` (Gram matrix `gram`, `rhs`
    their products with y) and one more `column`: the normal equations by Cholesky with
    that column scaled alike, the SVD where they are singular or ill-conditioned."""
    c = column / max(float(np.abs(column).max()), 1e-12)
    cross = fixed.T @ c
    full = np.block([[gram, cross[:, None]], [cross[None, :], np.array([[c @ c]])]])
    X = None
    try:
        chol = np.linalg.cholesky(full)
        if np.linalg.cond(full) > 1e12:
            raise np.linalg.LinAlgError
        coef = np.linalg.solve(chol.T, np.linalg.solve(chol, np.r_[rhs, c @ y]))
    except np.linalg.LinAlgError:
        X = np.column_stack([fixed, c])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - fixed @ coef[:-1] - c * coef[-1] if X is None else y - X @ coef
    return float(e @ e)
