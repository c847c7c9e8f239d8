"""The simulated friction-wheel guidewire drive: PMSM, FOC current loop, speed loop.

What is simulated ([endovascular], III-A and IV-A; parameters in `params.py`):

- q-axis electrics, L di/dt = v - R i - e, with e = (2/3) K_t omega (amplitude-invariant
  dq frame), integrated exactly over each current-loop period; d-axis held at zero;
- the FOC current PI (tuned by pole-zero cancellation to the set bandwidth) with the
  back-EMF fed forward and the voltage limited to the supply;
- eq. 2 mechanics, J theta_dd + b theta_d + tau_friction = T_m - r F, where the friction
  is a Stribeck curve with stiction (Karnopp stick/slip: the rotor stays stuck while
  the applied torque is below the breakaway torque), larger when withdrawing, plus a
  quadratic drag, and T_m = K_t(i) i with a saturating torque constant, plus optional
  cogging; with `FollowerPlantParams.ideal()` this reduces to eqs. 1-2 exactly;
- the speed PI at the 1 kHz device rate on the AS5600 angle (12-bit quantised),
  differentiated and low-passed as the ESP32 firmware does, with anti-windup.

The inner loops are compiled with numba: a trial runs a million current-loop steps,
which Python would take seconds for; the kernel takes milliseconds. The state lives in
one float64 array so that `FollowerDrive.step` can advance one 1 kHz tick at a time
inside a closed loop, and `run` can advance a whole profile in one call, with the same
arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import FollowerControlParams, FollowerPlantParams

# State vector layout.
THETA, OMEGA, IQ, IQ_INT, W_INT, W_FILT, THETA_Q_PREV, IQ_CMD = range(8)
STATE_SIZE = 8
# Parameter vector layout (`_param_vector`, read by `follower_tick`).
(
    P_KT,
    P_WHEEL_R,
    P_INERTIA,
    P_VISCOUS,
    P_COULOMB,
    P_STATIC,
    P_STRIBECK,
    P_KSAT,
    P_COG,
    P_NCOG,
    P_R,
    P_L,
    P_VMAX,
    P_KPI,
    P_KII,
    P_DT,
    P_NSUB,
    P_KPW,
    P_KIW,
    P_TF,
    P_ILIM,
    P_DRAG2,
    P_RETRACT,
) = range(23)
PARAM_SIZE = 23
# Output layout of one tick (`follower_tick`'s `out`).
F_THETA, F_OMEGA, F_IQ, F_OMEGA_EST, F_IQ_CMD = range(5)
FOLLOWER_OUT = 5


def _param_vector(plant: FollowerPlantParams, control: FollowerControlParams) -> Float1D:
    substeps = round(control.current_loop_rate_hz / control.speed_loop_rate_hz)
    if (
        substeps < 1
        or abs(substeps * control.speed_loop_rate_hz - control.current_loop_rate_hz) > 1e-6
    ):
        raise TeleopInputError(
            f"current_loop_rate_hz {control.current_loop_rate_hz} is not a whole multiple of "
            f"speed_loop_rate_hz {control.speed_loop_rate_hz}; expected e.g. 10000 and 1000"
        )
    wc = 2 * math.pi * control.current_loop_bandwidth_hz
    p = np.empty(PARAM_SIZE)
    p[P_KT] = plant.torque_constant_n_m_per_a
    p[P_WHEEL_R] = plant.wheel_radius_m
    p[P_INERTIA] = plant.inertia_kg_m2
    p[P_VISCOUS] = plant.viscous_damping_n_m_s_per_rad
    p[P_COULOMB] = plant.coulomb_friction_n_m
    p[P_STATIC] = plant.static_friction_n_m
    p[P_STRIBECK] = plant.stribeck_speed_rad_s
    p[P_KSAT] = plant.torque_saturation_per_a2
    p[P_COG] = plant.cogging_torque_n_m
    p[P_NCOG] = float(plant.cogging_periods_per_rev)
    p[P_R] = plant.phase_resistance_ohm
    p[P_L] = plant.phase_inductance_h
    p[P_VMAX] = plant.voltage_limit_v
    p[P_KPI] = plant.phase_inductance_h * wc  # current Kp [V/A]
    p[P_KII] = plant.phase_resistance_ohm * wc  # current Ki [V/(A s)]
    p[P_DT] = 1.0 / control.speed_loop_rate_hz  # speed-loop period [s]
    p[P_NSUB] = float(substeps)
    p[P_KPW] = control.speed_kp_a_s_per_rad
    p[P_KIW] = control.speed_ki_a_per_rad
    p[P_TF] = control.velocity_filter_s
    p[P_ILIM] = control.current_limit_a
    p[P_DRAG2] = plant.quadratic_drag_n_m_s2_per_rad2
    p[P_RETRACT] = plant.retract_friction_ratio
    return p


@njit(cache=True)
def follower_tick(
    state: np.ndarray,
    p: np.ndarray,
    encoder_step_rad: float,
    omega_cmd: float,
    load_n: float,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled; exercised through FollowerDrive
    """One speed-loop tick; writes theta, omega, mean iq, omega estimate, iq command to out."""
    # (grouped: mechanics, friction, saturation and cogging, electrics and current PI,
    # speed PI, filter, limit and the withdrawal terms)
    kt, r, J, b = p[P_KT], p[P_WHEEL_R], p[P_INERTIA], p[P_VISCOUS]
    tc, ts, ws = p[P_COULOMB], p[P_STATIC], p[P_STRIBECK]
    ksat, cog, ncog = p[P_KSAT], p[P_COG], p[P_NCOG]
    R, L, vmax, kpi, kii = p[P_R], p[P_L], p[P_VMAX], p[P_KPI], p[P_KII]
    dt, nsub, kpw, kiw = p[P_DT], p[P_NSUB], p[P_KPW], p[P_KIW]
    tf, ilim, drag2, retract = p[P_TF], p[P_ILIM], p[P_DRAG2], p[P_RETRACT]
    n_sub = int(nsub)
    dte = dt / n_sub
    decay = math.exp(-R * dte / L)
    ke = (2.0 / 3.0) * kt
    lpf = tf / (tf + dt)
    # reciprocals once per tick: a division's latency would sit on every substep's chain
    inv_ws, dte_j, inv_r = 1.0 / ws, dte / J, 1.0 / R
    # Speed loop: quantised encoder angle, differentiated and low-passed.
    theta_q = math.floor(state[THETA] / encoder_step_rad) * encoder_step_rad
    w_raw = (theta_q - state[THETA_Q_PREV]) / dt
    state[THETA_Q_PREV] = theta_q
    state[W_FILT] = lpf * state[W_FILT] + (1.0 - lpf) * w_raw
    e_w = omega_cmd - state[W_FILT]
    w_int = state[W_INT] + kiw * e_w * dt
    w_int = min(max(w_int, -ilim), ilim)  # anti-windup
    state[W_INT] = w_int
    iq_cmd = min(max(kpw * e_w + w_int, -ilim), ilim)
    state[IQ_CMD] = iq_cmd
    iq_sum = 0.0
    for _ in range(n_sub):
        omega = state[OMEGA]
        iq = state[IQ]
        # FOC current PI with back-EMF feed-forward, voltage-limited.
        e_i = iq_cmd - iq
        v = kpi * e_i + state[IQ_INT] + ke * omega
        if v > vmax:
            v = vmax
        elif v < -vmax:
            v = -vmax
        else:
            state[IQ_INT] += kii * e_i * dte
        # L di/dt = v - R i - e, exact over one current-loop period.
        i_ss = (v - ke * omega) * inv_r
        iq = i_ss + (iq - i_ss) * decay
        state[IQ] = iq
        iq_sum += iq
        # Eq. 2 with T_m = K_t(i) i, cogging and the load torque r F.
        tau = kt * (1.0 - ksat * iq * iq) * iq - r * load_n
        if cog != 0.0:
            tau -= cog * math.sin(ncog * state[THETA])
        if omega == 0.0:
            breakaway = ts if tau > 0.0 else ts * retract
            if abs(tau) <= breakaway:
                continue  # stuck: friction balances the applied torque
            tau_f = breakaway if tau > 0.0 else -breakaway
        else:
            u = omega * inv_ws
            mag = tc + (ts - tc) * math.exp(-u * u)
            tau_f = mag if omega > 0.0 else -mag * retract
            tau_f += drag2 * omega * abs(omega)
        omega_new = omega + (tau - b * omega - tau_f) * dte_j
        if omega != 0.0 and omega_new * omega < 0.0:
            omega_new = 0.0  # friction cannot reverse the motion: stick at zero speed
        state[OMEGA] = omega_new
        state[THETA] += omega_new * dte
    out[F_THETA] = state[THETA]
    out[F_OMEGA] = state[OMEGA]
    out[F_IQ] = iq_sum / n_sub
    out[F_OMEGA_EST] = state[W_FILT]
    out[F_IQ_CMD] = iq_cmd


@njit(cache=True)
def _advance(
    state: np.ndarray,
    p: np.ndarray,
    encoder_step_rad: float,
    omega_cmd: np.ndarray,
    load_n: np.ndarray,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled; exercised through FollowerDrive
    for k in range(omega_cmd.shape[0]):
        follower_tick(state, p, encoder_step_rad, omega_cmd[k], load_n[k], out[k])


@dataclass
class DriveTrace:
    """The drive's internal signals at the 1 kHz speed-loop rate (ground truth of a run).

    `iq_a` is the mean q-axis current over each speed-loop period; `omega_est_rad_s` is
    the firmware's velocity estimate from the AS5600 angle.
    """

    t_s: Float1D
    theta_rad: Float1D
    omega_rad_s: Float1D
    iq_a: Float1D
    omega_est_rad_s: Float1D
    iq_cmd_a: Float1D
    omega_cmd_rad_s: Float1D
    load_force_n: Float1D


@dataclass
class FollowerDrive:
    """A simulated guidewire drive that keeps its state between calls.

    Parameters
    ----------
    plant, control
        Physical and controller parameters (`params.py`).
    encoder_counts_per_rev
        Resolution of the angle the speed loop sees (AS5600: 4096).
    """

    plant: FollowerPlantParams = field(default_factory=FollowerPlantParams)
    control: FollowerControlParams = field(default_factory=FollowerControlParams)
    encoder_counts_per_rev: int = 4096
    t_s: float = 0.0

    def __post_init__(self) -> None:
        self._p = _param_vector(self.plant, self.control)
        self._encoder_step = 2 * math.pi / self.encoder_counts_per_rev
        self.state = np.zeros(STATE_SIZE)
        self._one = np.empty((1, FOLLOWER_OUT))

    @property
    def dt_s(self) -> float:
        """Speed-loop (device physics) period, s."""
        return 1.0 / self.control.speed_loop_rate_hz

    def run(self, omega_cmd_rad_s: Float1D, load_force_n: Float1D) -> DriveTrace:
        """Advance one speed-loop tick per element of the inputs (held over the tick).

        Parameters
        ----------
        omega_cmd_rad_s : (n,) array
            Speed command, rad/s (positive advances the guidewire).
        load_force_n : (n,) array
            External force on the guidewire opposing insertion, N.
        """
        cmd = np.ascontiguousarray(omega_cmd_rad_s, dtype=np.float64)
        load = np.ascontiguousarray(load_force_n, dtype=np.float64)
        if cmd.shape != load.shape or cmd.ndim != 1:
            raise TeleopInputError(
                f"speed command shape {cmd.shape} and load shape {load.shape} differ; "
                "expected two 1-D arrays of one length"
            )
        out = np.empty((cmd.shape[0], FOLLOWER_OUT))
        _advance(self.state, self._p, self._encoder_step, cmd, load, out)
        t = self.t_s + self.dt_s * np.arange(1, cmd.shape[0] + 1)
        self.t_s = float(t[-1]) if len(t) else self.t_s
        return DriveTrace(
            t_s=t,
            theta_rad=out[:, F_THETA].copy(),
            omega_rad_s=out[:, F_OMEGA].copy(),
            iq_a=out[:, F_IQ].copy(),
            omega_est_rad_s=out[:, F_OMEGA_EST].copy(),
            iq_cmd_a=out[:, F_IQ_CMD].copy(),
            omega_cmd_rad_s=cmd.copy(),
            load_force_n=load.copy(),
        )

    def step(self, omega_cmd_rad_s: float, load_force_n: float) -> tuple[float, float, float]:
        """Advance one tick; return (theta_rad, omega_rad_s, iq_a) at its end."""
        _advance(
            self.state,
            self._p,
            self._encoder_step,
            np.array([omega_cmd_rad_s]),
            np.array([load_force_n]),
            self._one,
        )
        self.t_s += self.dt_s
        one = self._one[0]
        return float(one[F_THETA]), float(one[F_OMEGA]), float(one[F_IQ])
