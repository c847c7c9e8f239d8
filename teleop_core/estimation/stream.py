"""The causal estimator's steps as numba functions over flat arrays (`CausalEstimator`
in `model.py` holds the arrays): the closed loop's compiled kernel calls them too, so
this module imports only the numeric stages, not the model folder's reader.

The memory features (`memory.py`) are computed here too, before the GRU: their moving
averages live in the stream state after its fixed fields, one per row of the memory
table `mem` ([input column, 1 / tau]; no rows for a model without them), and each
pushed sample's features fill the window's columns after [I_q, theta_d, theta_dd]."""

from __future__ import annotations

import numpy as np

from teleop_core._jit import njit
from teleop_core.estimation.ekf import ekf_update
from teleop_core.estimation.gru import _window_forward
from teleop_core.estimation.memory import ema_step
from teleop_core.follower.physics import force_at

# stream state: samples pushed, last (t, omega) and whether there is one, latest sample
S_COUNT, S_LAST_T, S_LAST_OMEGA, S_HAS_LAST, S_IQ, S_OMEGA, S_ALPHA = range(7)
STREAM_STATE_SIZE = 7
"""Fixed fields; the memory features' averages follow (`CausalEstimator` sizes `st`)."""
# window columns (standardised features) and the target's de-standardisation
X_IQ, X_OMEGA, X_ALPHA = range(3)
N_FEATURES = 3
T_STD, T_MEAN = range(2)
# what `stream_estimate` writes to `out`: F_physics, F*_GRU and F*_Final
EST_PHYSICS, EST_HYBRID, EST_FINAL = range(3)
ESTIMATE_OUT = 3


_Z1, _Z1_32, _Z2_32 = np.zeros(1), np.zeros(1, np.float32), np.zeros((1, 1), np.float32)
NO_STREAM_ARRAYS = (
    np.zeros((1, N_FEATURES)),
    _Z1,
    _Z1,
    _Z1,
    np.zeros((0, 2)),
    _Z1,
    _Z2_32,
    _Z2_32,
    _Z1_32,
    _Z1_32,
    _Z1_32,
    0.0,
    _Z1,
    _Z1,
    _Z1,
)
"""`CausalEstimator.kernel_arrays()` without an estimator: dummies of the same types, so
one compiled loop kernel serves both."""


@njit(cache=True)
def stream_push(
    st: np.ndarray,
    buf: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    mem: np.ndarray,
    t: float,
    iq: float,
    omega: float,
    alpha: float,
    alpha_given: bool,
) -> None:  # pragma: no cover - compiled; exercised through CausalEstimator
    """Add one sample to the window, in place (`CausalEstimator.push`).

    Parameters
    ----------
    st : numpy.ndarray
        The stream state (`STREAM_STATE_SIZE` fields, then the memory averages).
    buf : numpy.ndarray
        The window of standardised features, shape (T, 3 + memory features); shifted
        by one row, the sample written last.
    mean, std : numpy.ndarray
        The features' standardisation.
    mem : numpy.ndarray
        The memory table, one row [input column, 1 / tau (1/s)] per memory feature.
    t : float
        The sample's time, s.
    iq : float
        Motor current I_q, A.
    omega : float
        Velocity theta_d, rad/s.
    alpha : float
        Acceleration theta_dd, rad/s^2 (ignored unless `alpha_given`).
    alpha_given : bool
        False: `alpha` is the backward difference of `omega` (0 for the first sample).
    """
    first = st[S_HAS_LAST] == 0.0
    dt = 0.0 if first else t - st[S_LAST_T]
    if not alpha_given:
        # Backward difference, as FollowerRecording derives alpha.
        alpha = 0.0 if first else (omega - st[S_LAST_OMEGA]) / dt
    st[S_LAST_T], st[S_LAST_OMEGA], st[S_HAS_LAST] = t, omega, 1.0
    st[S_IQ], st[S_OMEGA], st[S_ALPHA] = iq, omega, alpha
    n = buf.shape[0]
    for i in range(n - 1):
        buf[i, X_IQ], buf[i, X_OMEGA], buf[i, X_ALPHA] = (
            buf[i + 1, X_IQ],
            buf[i + 1, X_OMEGA],
            buf[i + 1, X_ALPHA],
        )
        for j in range(mem.shape[0]):
            buf[i, N_FEATURES + j] = buf[i + 1, N_FEATURES + j]
    buf[n - 1, X_IQ] = (iq - mean[X_IQ]) / std[X_IQ]
    buf[n - 1, X_OMEGA] = (omega - mean[X_OMEGA]) / std[X_OMEGA]
    buf[n - 1, X_ALPHA] = (alpha - mean[X_ALPHA]) / std[X_ALPHA]
    for j in range(mem.shape[0]):
        # x - EMA_tau(x), the average's first value the sample itself (memory.ema_residuals)
        x = st[S_IQ + int(mem[j, 0])]
        e = x if first else ema_step(st[STREAM_STATE_SIZE + j], x, dt, mem[j, 1])
        st[STREAM_STATE_SIZE + j] = e
        c = N_FEATURES + j
        buf[n - 1, c] = (x - e - mean[c]) / std[c]
    st[S_COUNT] += 1.0


@njit(cache=True)
def stream_estimate(
    st: np.ndarray,
    buf: np.ndarray,
    pv: np.ndarray,
    w_ih_t: np.ndarray,
    w_hh_t: np.ndarray,
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
    """Physics, GRU and EKF on the current window (`CausalEstimator.estimate`).

    Parameters
    ----------
    st, buf : numpy.ndarray
        The stream state and window `stream_push` fills.
    pv : numpy.ndarray
        Eq. 1's parameters as a vector (`PhysicsParams.vector`).
    w_ih_t, w_hh_t, b_ih, b_hh, w_out : numpy.ndarray
        The GRU's weights in float32, matrices transposed (`GruWeights.kernel_weights`).
    b_out : float
        The GRU's output bias.
    target : numpy.ndarray
        [std, mean] of the residual target, N, to de-standardise the GRU's output.
    ekf_state, ekf_settings : numpy.ndarray
        The EKF's state (updated in place) and its settings vector.
    dt_s : float
        The sample period, s.
    out : numpy.ndarray
        Length `ESTIMATE_OUT`: receives ``F_physics``, ``F*_GRU`` and ``F*_Final``, N, at
        `EST_PHYSICS`, `EST_HYBRID`, `EST_FINAL`.

    Returns
    -------
    bool
        True when `out` holds an estimate; False while the window fills.
    """
    if st[S_COUNT] < buf.shape[0]:
        return False
    iq, omega, alpha = st[S_IQ], st[S_OMEGA], st[S_ALPHA]
    f_physics = force_at(pv, iq, omega, alpha)
    # F*_GRU = F_physics + GRU residual (eq. 3), de-standardised
    y = float(_window_forward(buf, w_ih_t, w_hh_t, b_ih, b_hh, w_out, b_out))
    f_hybrid = f_physics + y * target[T_STD] + target[T_MEAN]
    out[EST_PHYSICS] = f_physics
    out[EST_HYBRID] = f_hybrid
    out[EST_FINAL] = ekf_update(ekf_state, ekf_settings, pv, dt_s, f_physics, f_hybrid, omega)
    return True
