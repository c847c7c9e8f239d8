"""Behavioural features of one LCCA trial, read off its sample stream for the participant fit.

A trial's summary measures (time, peak forces) are what the study analyses, but they
mix every trait of the person who made them: a slow trial may be a slow hand, a
cautious approach, a wrong aim or a long wait before backing off. The sample stream
tells these apart, as a rater watching the recording would (what each feature follows
in `study.tasks.lcca.simulated_participant.SimulatedParticipant`, and in a person):

- `advance_speed_m_s`: the median insertion speed on the way up the aorta, more than
  `APPROACH_M` before the ostium (the preferred speed);
- `approach_m`: how far before the ostium the advance first slows below
  `SLOW_SHARE` of its speed just before (a cautious person slows earlier); only trials
  that slow before the ostium;
- `approaches`: how many times the tip is brought up to the ostium (a retry after a
  wrong aim brings it back; the steering error);
- `target_speed_ratio`: the median forward speed inside the target branch over the
  advance speed (a cautious person goes on more slowly); only trials that reach it;
- `aim_error_rad`: how far from the target branch's direction the guidewire is turned
  when the tip reaches `APPROACH_M` before the ostium (the steering error), plus
  `AIM_FLOOR_RAD` so that its log stays finite near zero;
- `turn_peak_s`: the time from the start to the first turning point of the first
  rotation (the overshoot of a correction made with the view's delay scales with the
  reaction time); only trials whose first turn exceeds `MIN_TURN_RAD`;
- `turn_swing_s`: from that turning point to the next (the overshoot's swing back: a
  correction made on a view `reaction_s` old swings for a time in proportion to it; on
  simulated people the log of it follows the log reaction time with a residual SD of
  0.04, against 0.22 for `turn_peak_s`, whose start the rate limit of a large turn
  stretches); only trials that swing back;
- `stall_s`: at each backing-off (the dial's aim turning from forward to backward),
  the time since the tip last moved a millimetre (on the screen: the wire behind it
  may still go in, buckling), averaged over the trial's backings-off on the way to the
  target after its first `START_S` (seen
  obstacles take the visual stall time, felt ones less); only trials that back off;
- `stall_backoffs`: 1 + how many of those backings-off came after at least
  `MIN_STALL_S` of stillness (whether a person waits long enough for a creeping tip to
  pass for stuck: with a long visual stall time none does); defined in every trial;
- `peak_felt_rise_n_m`: the largest rise, while the hand pushes forward, of the
  resistance felt on the dial (its torque beyond the return spring's,
  `spring_n_m_per_rad` times the angle: the rendered force, over the last 0.1 s) over
  its level 1-3 s before. A person backs off once a rise passes their threshold, so
  the largest rise they let happen follows it; defined in every trial (without haptics
  it is the spring's own noise). Plus `RISE_FLOOR_N_M`.

Every feature is a positive number in SI units (the fit takes its log) or NaN where the
trial has no such moment. The samples are put on a 100 Hz grid first, so a recording at
1 kHz and a simulation at 100 Hz give the same features.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from study.tasks.lcca.feature_names import FIT_FEATURES

GRID_S = 0.01
APPROACH_M = 0.06
"""Beyond the longest approach zone of a simulated participant (0.05 m)."""
SLOW_SHARE = 0.93
OSTIUM_BAND_M = 0.008
"""An approach reaches within this distance of the ostium."""
AIM_FLOOR_RAD = 0.05
MIN_TURN_RAD = 0.03
RISE_FLOOR_N_M = 1e-4
MIN_STALL_S = 0.15
"""A backing-off counts in `stall_backoffs` when the tip stood still at least this long."""
START_S = 2.0
FEATURES = FIT_FEATURES


def _grid(frame: pd.DataFrame, column: str, t: np.ndarray) -> np.ndarray:
    return np.interp(t, frame["t_s"].to_numpy(float), frame[column].to_numpy(float))


def _speed(x: np.ndarray, window: int = 10) -> np.ndarray:
    """Speed over `window` grid steps (0.1 s), centred."""
    v = np.full_like(x, np.nan)
    h = window // 2
    if len(x) > window:
        v[h : len(x) - h] = (x[window:] - x[:-window]) / (window * GRID_S)
    return v


def _turning_point(rot: np.ndarray, start: int, sign: float) -> int | None:
    """The first turning point of `rot` from `start` moving in `sign`'s direction: the
    furthest point before it has come back by a tenth of its excursion (and 3 mrad), so
    that a wobble of the roll on the way does not pass for it; None if it never does."""
    excursion = (rot[start:] - rot[start]) * sign
    reach = np.maximum.accumulate(excursion)
    back = np.flatnonzero(reach - excursion >= np.maximum(0.1 * reach, 0.003))
    if not len(back) or reach[back[0]] < 0.003:
        return None
    return start + int(np.argmax(excursion[: back[0] + 1]))


def lcca_features(
    frame: pd.DataFrame,
    ostium_m: float,
    target_phi_rad: float,
    target: set[str],
    spring_n_m_per_rad: float,
    route: set[str] | None = None,
) -> dict[str, float]:
    """The features (`FEATURES`) of one trial's TRIAL.csv frame; `target`: the names the
    frame's `branch` column may give the target branch, `route` the vessels on the way
    to it, the target included (default: the target only)."""
    route = set(target) if route is None else route
    out = dict.fromkeys(FEATURES, math.nan)
    if len(frame) < 20:
        return out
    t_raw = frame["t_s"].to_numpy(float)
    t = np.arange(t_raw[0], t_raw[-1], GRID_S)
    x = _grid(frame, "insertion_m", t)
    rot = _grid(frame, "rotation_rad", t)
    aim = _grid(frame, "dial_angle_rad", t)
    # the resistance felt beyond the spring, over the last 0.1 s as a hand feels it
    felt = -(_grid(frame, "dial_torque_n_m", t) + spring_n_m_per_rad * aim)
    felt = np.convolve(felt, np.ones(10) / 10)[: len(felt)]
    tip = np.column_stack([_grid(frame, f"tip_{a}_m", t) for a in "xyz"])
    index = np.clip(np.searchsorted(t_raw, t), 0, len(t_raw) - 1)
    in_target = frame["branch"].isin(list(target)).to_numpy()[index]
    v = _speed(x)
    # the advance, before the approach zone
    before = np.flatnonzero(x < ostium_m - APPROACH_M)
    reached = np.flatnonzero(x >= ostium_m - APPROACH_M)
    free = before[(v[before] > 0.001) & np.isfinite(v[before])]
    if len(free) < 10:
        return out
    speed = float(np.median(v[free]))
    out["advance_speed_m_s"] = speed
    if len(reached):
        out.update(_approach(x, rot, v, reached[0], ostium_m, target_phi_rad, speed))
    forward = in_target & (v > 0.001)
    if np.count_nonzero(forward) >= 10:
        out["target_speed_ratio"] = float(np.median(v[forward])) / speed
    out.update(_first_turn(t, rot))
    # only on the way to the target (a retreat from a side branch is no stall)
    on_route = frame["branch"].isin(list(route)).to_numpy()[index]
    out.update(_stalls(t, aim, tip, on_route))
    # the felt resistance against its mean 1-3 s before, while pushing forward
    sums = np.concatenate([[0.0], np.cumsum(felt)])
    i = np.arange(300, len(felt))
    level = (sums[i - 100] - sums[i - 300]) / 200
    rise = (felt[i] - level)[aim[i] > 0.02]
    if len(rise):
        out["peak_felt_rise_n_m"] = max(float(rise.max()), 0.0) + RISE_FLOOR_N_M
    return out


def _approach(
    x: np.ndarray,
    rot: np.ndarray,
    v: np.ndarray,
    first: int,
    ostium_m: float,
    target_phi_rad: float,
    speed: float,
) -> dict[str, float]:
    """The aim error, the approach distance and the approaches, from `first`, the first
    grid point in the approach zone."""
    out: dict[str, float] = {}
    out["aim_error_rad"] = abs(math.remainder(rot[first] - target_phi_rad, 2 * math.pi))
    out["aim_error_rad"] += AIM_FLOOR_RAD
    ref = v[max(first - 200, 0) : first]
    ref = ref[np.isfinite(ref) & (ref > 0.001)]
    slow = np.flatnonzero(v[first:] < SLOW_SHARE * (np.median(ref) if len(ref) else speed))
    if len(slow) and x[first + slow[0]] < ostium_m:
        out["approach_m"] = ostium_m - x[first + slow[0]]
    out["approaches"] = float(max(approaches(x, ostium_m), 1))
    return out


def approaches(x: np.ndarray, ostium_m: float) -> int:
    """How many times the insertion `x` comes up to the ostium (within `OSTIUM_BAND_M`)
    from behind it (1.5 bands back) or from the start: of the grid points either near
    or behind, the near ones whose previous such point is behind (or that have none)."""
    near = x >= ostium_m - OSTIUM_BAND_M
    behind = x < ostium_m - 1.5 * OSTIUM_BAND_M
    events = near[near | behind]  # True: near, False: behind (the two never overlap)
    return int(np.count_nonzero(events & np.concatenate([[True], ~events[:-1]])))


def _first_turn(t: np.ndarray, rot: np.ndarray) -> dict[str, float]:
    """The first turn: from its start to its first turning point, and on to the next."""
    out: dict[str, float] = {}
    moved = np.flatnonzero(np.abs(rot - rot[0]) > 0.005)
    if len(moved):
        sign = float(np.sign(rot[moved[0]] - rot[0]))
        peak = _turning_point(rot, 0, sign)
        if peak is not None and (rot[peak] - rot[0]) * sign >= MIN_TURN_RAD:
            out["turn_peak_s"] = t[peak] - t[0]
            swing = _turning_point(rot, peak, -sign)
            if swing is not None:
                out["turn_swing_s"] = t[swing] - t[peak]
    return out


def _stalls(
    t: np.ndarray, aim: np.ndarray, tip: np.ndarray, on_route: np.ndarray
) -> dict[str, float]:
    """Backing off: the dial's aim from forward to backward, on the route and after the
    first `START_S` (the screen lags the hand by the reaction time at the start)."""
    out: dict[str, float] = {}
    stalls = []
    for k in np.flatnonzero((aim[:-1] > 0.02) & (aim[1:] <= 0.0)):
        if not on_route[k] or t[k] - t[0] < START_S:
            continue
        moving = np.flatnonzero(np.linalg.norm(tip[: k + 1] - tip[k], axis=1) >= 0.001)
        stalls.append(t[k] - t[moving[-1]] if len(moving) else t[k] - t[0])
    if stalls:
        out["stall_s"] = float(np.mean(stalls)) + GRID_S
    out["stall_backoffs"] = 1.0 + sum(d >= MIN_STALL_S for d in stalls)
    return out
