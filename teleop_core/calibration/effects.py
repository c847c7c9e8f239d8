"""The library of candidate effects a base physics model may lack.

Each effect adds regressor columns to the base model's design (or, for `delay`, shifts
the drive-side signals), so that for a fixed value of its one searched parameter the
whole model stays linear in its coefficients and is fitted by least squares; the
searched parameter (a Stribeck speed, an exponent, a period, a loop width, a lag, a
thermal time constant) is found by a grid plus a bounded scalar refinement in
`loop.py`. The coefficients come out in force units (N, what the reference sensor
measures); `physical` turns them into the effect's physical parameters, where `out`
is the base model's conversion from force to its output quantity (the wheel radius
for the follower's torques, 1 for models fitted in N directly).

The families and their names are the report's contract:

| family                 | adds                                   | searched        |
|------------------------|----------------------------------------|-----------------|
| `stribeck`             | -exp(-(w/w_s)^2) sgn(w)                | w_s, rad/s      |
| `viscous_nonlinear`    | -sgn(w) abs(w)^p                       | p               |
| `direction_asymmetry`  | friction and damping (and, on the      | -               |
|                        | follower, drive gain) while w < 0      |                 |
| `position_periodic`    | sin, cos of 2 pi theta / P             | P, rad          |
| `hysteresis`           | play operator of the drive current     | half-width      |
| `delay`                | signals taken at t - d                 | d, s            |
| `drift`                | -i (1 - exp(-t / tau))                 | tau, s          |
| `current_nonlinearity` | sgn(i) abs(i)^p (torque per amp vs i)  | p               |

The play operator is a hand-written numba loop: scipy and statsmodels have no
hysteresis operator, and it has to run over tens of thousands of samples per grid value.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D, Float2D
from teleop_core.follower.physics import PhysicsParams

Signals = dict[str, Float1D]
"""Named signals of a recording: `t` [s], `drive` (current or command), and where the
model has them `speed` [rad/s], `accel` [rad/s^2], `angle` [rad], `direction` (of
motion or command), `linear` (a linear model's response)."""

SIGN_SPEED_RAD_S = PhysicsParams.sign_speed_rad_s
"""Speed of the smoothed sign tanh(w / w0), as in the estimator's eq. 1 (physics.py)."""


def smooth_sign(speed: Float1D, width_rad_s: float = SIGN_SPEED_RAD_S) -> Float1D:
    """sgn(w) smoothed as tanh(w / w_s); by default the estimator's w_s = 0.3 rad/s."""
    return np.tanh(speed / width_rad_s)


@njit(cache=True)
def play_operator(x: np.ndarray, half_width: float) -> np.ndarray:  # pragma: no cover
    """Direction state h in [-1, 1] of a play (backlash) operator on x.

    z follows x only when x leaves the band [z - a, z + a]; h = (x - z) / a is +1 after
    x has risen by 2a, -1 after it has fallen by 2a, and moves linearly in between.
    """
    h = np.empty(x.shape[0])
    z = x[0]
    for k in range(x.shape[0]):
        # z_k = clip(z_{k-1}, x_k - a, x_k + a)
        z = min(max(z, x[k] - half_width), x[k] + half_width)
        h[k] = (x[k] - z) / half_width
    return h


def noise_sd(x: Float1D) -> float:
    """Robust SD of white noise on a smooth signal: 1.4826 MAD of its differences / sqrt 2."""
    d = np.diff(x)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


class Effect:
    """One candidate family; stateless, so one instance serves every fit."""

    family: ClassVar[str]
    needs: ClassVar[tuple[str, ...]] = ("drive",)
    searched: ClassVar[str | None] = None
    """Name (with unit) of the searched parameter, or None for a linear effect."""
    log_search: ClassVar[bool] = True
    refine: ClassVar[bool] = True
    """Whether the best grid value is refined by a bounded scalar search."""
    saved_settings: ClassVar[dict[str, Any]] = {}
    """What a saved model's entry says of this form of the family (`CalibratedModel`)."""
    saved_before: ClassVar[Effect | None] = None
    """The form a saved entry without those settings was fitted with."""

    def grid(self, s: Signals) -> Float1D:
        """Values of the searched parameter to try (empty for a linear effect)."""
        return np.empty(0)

    def transform(self, s: Signals, value: float) -> Signals:
        """The signals the model sees with this effect (unchanged except for `delay`)."""
        return s

    def columns(self, s: Signals, value: float) -> Float2D:
        """Regressor columns (n, k), each multiplying one coefficient in N."""
        raise NotImplementedError

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        """Physical parameters from the coefficients, the searched value and `out`."""
        raise NotImplementedError


class Stribeck(Effect):
    family = "stribeck"
    needs = ("speed",)
    searched = "stribeck_speed_rad_s"

    def grid(self, s: Signals) -> Float1D:
        return np.geomspace(0.03, 10.0, 28)

    def columns(self, s: Signals, value: float) -> Float2D:
        w = s["speed"]
        # friction excess over Coulomb: (tau_s - tau_c) exp(-(w / w_s)^2) sgn(w)
        return (-np.exp(-((w / value) ** 2)) * smooth_sign(w))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"static_minus_coulomb_{unit}": coef[0] * out, "stribeck_speed_rad_s": value}


class ViscousNonlinear(Effect):
    family = "viscous_nonlinear"
    needs = ("speed",)
    searched = "exponent"
    log_search = False

    def grid(self, s: Signals) -> Float1D:
        return np.linspace(1.3, 3.5, 12)

    def columns(self, s: Signals, value: float) -> Float2D:
        w = s["speed"]
        # drag c sgn(w) |w|^p on top of the linear b w
        return (-np.sign(w) * np.abs(w) ** value)[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"drag_{unit}_per_rad_s_pow_p": coef[0] * out, "exponent": value}


class DirectionAsymmetry(Effect):
    """`direction` is the motion (the follower's wheel speed) or, for a clamped device,
    the commanded force through its linear model; `direction_sign`, when the model
    gives one, is its smoothed sign on the model's own scale."""

    family = "direction_asymmetry"
    needs: ClassVar[tuple[str, ...]] = ("direction",)

    def columns(self, s: Signals, value: float) -> Float2D:
        w = s["direction"]
        sign = s["direction_sign"] if "direction_sign" in s else smooth_sign(w)
        # extra Coulomb and viscous friction (or transmission loss) while w < 0
        return np.column_stack([-np.minimum(sign, 0.0), -np.minimum(w, 0.0)])

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {
            f"extra_coulomb_reverse_{unit}": coef[0] * out,
            f"extra_viscous_reverse_{unit}_s_per_rad": coef[1] * out,
        }


def reverse_gain_sign_width(speed: Float1D) -> float:
    """Width of the smoothed sign that switches a reverse gain on, in the speed's units:
    three noise SDs of the recorded speed (`noise_sd`), and at least a thousandth of its
    range. Sharper than eq. 1's 0.3 rad/s: the current a gain multiplies is largest
    where the axis pushes slowly against its load, and a wider step there left the
    gain's switch at each reversal to another term (a narrow backlash)."""
    top = float(np.percentile(np.abs(speed), 99)) if len(speed) else 0.0
    return max(3.0 * noise_sd(speed), 1e-3 * top, 1e-12)


class DriveDirectionAsymmetry(DirectionAsymmetry):
    """On a model whose drive is a current that acts in either direction of motion (the
    follower's): besides the friction and damping in reverse, the drive's own gain in
    reverse (a torque per amp, or a transmission's efficiency, that differs with the
    direction). Without it a gain that differs by direction left its shape (a force
    proportional to the current, in reverse only) to the speed families."""

    needs: ClassVar[tuple[str, ...]] = ("direction", "drive")
    saved_settings: ClassVar[dict[str, Any]] = {"reverse_gain": True}

    def columns(self, s: Signals, value: float) -> Float2D:
        w = s["direction"]
        sign = s["direction_sign"] if "direction_sign" in s else smooth_sign(w)
        # extra Coulomb, viscous friction and drive gain while w < 0
        gain = -np.minimum(smooth_sign(w, reverse_gain_sign_width(w)), 0.0) * s["drive"]
        return np.column_stack([-np.minimum(sign, 0.0), -np.minimum(w, 0.0), gain])

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {
            **super().physical(coef[:2], value, out, unit),
            f"extra_gain_reverse_{unit}_per_drive_unit": coef[2] * out,
        }


class PositionPeriodic(Effect):
    """Cogging or eccentricity; the period is found from a Lomb-Scargle periodogram of
    the residual against angle (`loop.py`), so `grid` lists only the searched band."""

    family = "position_periodic"
    needs = ("angle",)
    searched = "period_rad"

    def grid(self, s: Signals) -> Float1D:
        return periods_to_search(s["angle"])

    def columns(self, s: Signals, value: float) -> Float2D:
        phase = 2 * np.pi * s["angle"] / value
        return np.column_stack([np.sin(phase), np.cos(phase)])

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        # a sin x + b cos x = A sin(x + phi)
        return {
            f"amplitude_{unit}": math.hypot(coef[0], coef[1]) * out,
            "phase_rad": math.atan2(coef[1], coef[0]),
            "period_rad": value,
        }


def periods_to_search(angle: Float1D) -> Float1D:
    """Periods from 2 pi (once a turn) down to 2 pi / 300, spaced for the angle covered."""
    span = max(float(np.ptp(angle)), 2 * np.pi)
    k = np.arange(1.0, 300.0, np.pi / span / 2.0)  # wavenumber, rad^-1; 4x oversampled
    return 2 * np.pi / k


class Hysteresis(Effect):
    """`degree`: the loop's half-height is a polynomial of this degree in the drive (0:
    a constant, as Coulomb friction gives; 2: two calibrated quadratics, as eqs. 14-15)."""

    family = "hysteresis"
    searched = "loop_half_width_drive_units"

    def __init__(self, degree: int = 0) -> None:
        self.degree = degree

    def grid(self, s: Signals) -> Float1D:
        # A band narrower than the current's noise only follows the noise: start at
        # four noise SDs.
        x = s["drive"]
        top = max(float(np.std(x)), 1e-9)
        floor = min(4.0 * noise_sd(x), 0.5 * top)
        return np.geomspace(max(floor, 1e-3 * top), top, 20)

    def columns(self, s: Signals, value: float) -> Float2D:
        # The state from the samples before the present one: the present current's
        # measurement noise is in the base model's current column already, and a state
        # that followed it would act as a noise filter rather than as a hysteresis.
        x = s["drive"]
        h = play_operator(np.ascontiguousarray(x), value)
        h = np.r_[0.0, h[:-1]]
        # half the loop's height, a polynomial in the drive (two calibrated branches
        # such as eqs. 14-15 differ by a quadratic in the current)
        return np.column_stack([h * x**j for j in range(self.degree + 1)])

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        names = [f"half_loop_{unit}"] + [
            f"half_loop_{unit}_per_drive_unit{j if j > 1 else ''}"
            for j in range(1, self.degree + 1)
        ]
        params = {name: c * out for name, c in zip(names, coef, strict=True)}
        return {**params, "loop_half_width_drive_units": value}


MAX_LAG_S = 0.1
"""Longest lag searched, s: sensor and electrical lags are tens of ms. A longer one is
a dynamic the base model lacks, and on a slow ramp it would pass for hysteresis."""


class Delay(Effect):
    """Whole-sample lags only: a fractional lag interpolates between samples, which
    averages the current's noise away and would look like an improvement on any
    recording; the lag's resolution is one sample period."""

    family = "delay"
    searched = "lag_s"
    refine = False
    SHIFTED: ClassVar[tuple[str, ...]] = (
        "drive",
        "speed",
        "accel",
        "angle",
        "direction",
        "direction_sign",
        "linear",
    )

    def grid(self, s: Signals) -> Float1D:
        dt = float(np.median(np.diff(s["t"])))
        return np.arange(1.0, max(2, round(MAX_LAG_S / dt)) + 1.0) * dt

    def transform(self, s: Signals, value: float) -> Signals:
        t = s["t"]
        shifted = {k: np.interp(t - value, t, v) for k, v in s.items() if k in self.SHIFTED}
        return {**s, **shifted}

    def columns(self, s: Signals, value: float) -> Float2D:
        return np.empty((len(s["t"]), 0))

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {"lag_s": value}


class Drift(Effect):
    family = "drift"
    searched = "time_constant_s"

    def grid(self, s: Signals) -> Float1D:
        span = float(s["t"][-1] - s["t"][0])
        return np.geomspace(max(0.02 * span, 1e-3), 20.0 * span, 20)

    def columns(self, s: Signals, value: float) -> Float2D:
        t = s["t"] - s["t"][0]
        # K(t) = K (1 - kappa (1 - exp(-t / tau))): torque per amp falling as it heats
        return (-s["drive"] * (1.0 - np.exp(-t / value)))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"gain_drop_{unit}_per_drive_unit": coef[0] * out, "time_constant_s": value}


class CurrentNonlinearity(Effect):
    """K(i) i = K i + k sgn(i) |i|^p: the torque per amp changing with the current (k < 0:
    magnetic saturation). The exponent is searched: a saturation bends the curve from a
    power near 2 (a soft knee) to well above 3 (a sharp one), and a fixed cube left the
    rest of a softer bend for a wrong family (load-dependent friction) to take."""

    family = "current_nonlinearity"
    searched = "exponent"
    log_search = False
    LEGACY_EXPONENT: ClassVar[float] = 3.0
    """The exponent of a model saved before the exponent was searched (value nan)."""

    def grid(self, s: Signals) -> Float1D:
        return np.linspace(1.5, 5.0, 15)

    def columns(self, s: Signals, value: float) -> Float2D:
        p = self.LEGACY_EXPONENT if math.isnan(value) else value
        i = s["drive"]
        return (np.sign(i) * np.abs(i) ** p)[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        p = self.LEGACY_EXPONENT if math.isnan(value) else value
        return {f"gain_{unit}_per_drive_unit_pow_p": coef[0] * out, "exponent": p}


DriveDirectionAsymmetry.saved_before = DirectionAsymmetry()

EFFECTS: dict[str, Effect] = {
    e.family: e
    for e in (
        Stribeck(),
        ViscousNonlinear(),
        DirectionAsymmetry(),
        PositionPeriodic(),
        Hysteresis(),
        Delay(),
        Drift(),
        CurrentNonlinearity(),
    )
}
"""Every candidate family by its report name."""
FAMILIES = tuple(EFFECTS)
