"""Layouts of the flat arrays the loop's compiled kernel (`kernel.py`) shares with
`TeleopLoop` (`core.py`) and the environments: one named index per slot, defined once.
"""

from __future__ import annotations

# Loop state (held inputs and the master controller's memory)
(
    L_THETA_Q_PREV,
    L_OMEGA_FILT,
    L_TAU_PREV,
    L_BRANCH,
    L_FORCE_RX,
    L_SPEED_CMD_RX,
    L_ROT_RATE_RX,
    L_ROTATION,
    L_HAND_TARGET,
    L_HAND_K,
    L_HAND_B,
    L_HAND_PUSH,
    L_IQ_FILT,
    L_TAU_H,
    L_TAU_TOTAL,
    L_I_CMD_MA,
    L_TICK,
    L_NOISE_POS,
    L_FORCE_EST,
    L_ROT_ACTION,
    L_SUCCESS,
    L_N_ACQ,
    L_N_EST,
    L_N_CMD,
    L_SEND_PENDING,
) = range(25)
LOOP_STATE_SIZE = 25
# Master parameters
(
    M_KS,
    M_BS,
    M_THETA_REF,
    M_GH,
    M_DEADBAND,
    M_SAT,
    M_HAPTICS_ON,
    M_LEVER,
    M_IMAX,
    M_ENC_STEP,
    M_VEL_FILTER_S,
    M_WHEEL_R,
    M_IQ_FILTER_S,
    M_DT,
    M_DIAL_EXTERNAL,
) = range(15)
M_POLY = 15  # six polynomial coefficients follow
M_POLY_END = M_POLY + 6
# In-kernel acquisition (the fast path: ideal links, see `core.TeleopLoop`)
M_FAST, M_ACQ_EVERY, M_EST_EVERY, M_KV, M_HAS_EST, M_EST_DT, M_DEFER_LAST = range(21, 28)
MASTER_PARAM_SIZE = 28
# Packet schedule rows: (tick index in the call, kind, value, value)
SCH_TICK, SCH_KIND, SCH_V1, SCH_V2 = range(4)
SCHEDULE_WIDTH = 4
# The links' arrays as `TeleopLoop._kernel_links` hands them to the kernel: queue, state
# and parameters to the master, the same to the follower, the pool of draws, its position
LK_Q_M, LK_LS_M, LK_LP_M, LK_Q_F, LK_LS_F, LK_LP_F, LK_POOL, LK_POS = range(8)
PACKET_FORCE, PACKET_COMMAND = 0.0, 1.0
# Environment output
E_PROXIMAL, E_DISTAL, E_TIP_X, E_TIP_Y, E_TIP_Z, E_BRANCH, E_SUCCESS = range(7)
ENV_OUT = 7
# Log columns (one row per tick)
LOG_COLUMNS = (
    "t_s",
    "dial_angle_rad",
    "dial_speed_rad_s",
    "dial_torque_n_m",
    "haptic_torque_n_m",
    "current_cmd_ma",
    "wheel_angle_rad",
    "wheel_speed_rad_s",
    "iq_a",
    "iq_filtered_a",
    "omega_est_rad_s",
    "proximal_force_n",
    "distal_force_n",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "success",
    "rotation_rad",
    "force_rx_n",
    "speed_cmd_rx_rad_s",
)
LOG_WIDTH = len(LOG_COLUMNS)
(
    LOG_T,
    LOG_DIAL_ANGLE,
    LOG_DIAL_SPEED,
    LOG_DIAL_TORQUE,
    LOG_HAPTIC_TORQUE,
    LOG_CURRENT_CMD,
    LOG_WHEEL_ANGLE,
    LOG_WHEEL_SPEED,
    LOG_IQ,
    LOG_IQ_FILT,
    LOG_OMEGA_EST,
    LOG_PROXIMAL,
    LOG_DISTAL,
    LOG_TIP_X,
    LOG_TIP_Y,
    LOG_TIP_Z,
    LOG_BRANCH,
    LOG_SUCCESS,
    LOG_ROTATION,
    LOG_FORCE_RX,
    LOG_SPEED_CMD_RX,
) = range(LOG_WIDTH)
# Samples (one row per acquisition, written by the kernel's fast path and by
# `TeleopLoop._acquire`)
SAMPLE_COLUMNS = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "reference_force_n",
    "proximal_force_n",
    "distal_force_n",
    "dial_angle_rad",
    "dial_torque_n_m",
)
"""One row per acquisition (branch as its code), under the names the LCCA task stores,
exports and draws them by: `reference_force_n` is the true proximal force (the
simulation's, or a reference sensor's), `proximal_force_n` the estimate from the motor
current that the dial renders."""
SAMPLE_WIDTH = len(SAMPLE_COLUMNS)
(
    S_T,
    S_INSERTION,
    S_ROTATION,
    S_TIP_X,
    S_TIP_Y,
    S_TIP_Z,
    S_BRANCH,
    S_PROXIMAL,
    S_PROXIMAL_EST,
    S_DISTAL,
    S_DIAL_ANGLE,
    S_DIAL_TORQUE,
) = range(SAMPLE_WIDTH)
