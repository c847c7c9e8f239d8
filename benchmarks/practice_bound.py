"""How far the held-out prediction error of the loop on the people (`participant_fit.
effects.prediction_error`, the issue's definition) can fall when a practice effect is
added, in closed form: SIMULATED.

The definition: the RMS, over the cells of group x condition x condition order x trial
position and over the measures, of the held-out people's mean log measure minus the
model's mean there. A cell's held-out mean carries its people's own scatter, which no
model removes: its variance is s^2 / n (s: the SD of one trial's log measure across the
group's people, between and within persons; n: the cell's people, a group's half).
A model without the practice effect misses, in each cell, the effect's log shift at the
cell's position less its mean over the session (each person's traits absorb their
mean); one with the effect removes it. So, with F_m^2 the mean over the cells of the
measure m's s^2 / n and B_m^2 the mean over the cells of its missed shift squared,

    before^2 >= mean_m (F_m^2 + B_m^2),   after^2 >= mean_m F_m^2,

and the reduction 1 - after / before is at most 1 - sqrt(sum F^2 / sum (F^2 + B^2))
(the model's own error from fitting three quarters of the people adds to both, and
lowers it further). The shift: the practice family slows the preferred speed by
1 + slowing * exp(-position / decay) (`study.protocol.participant_effects`), and a
measure's log moves by its elasticity to the speed (d log measure / d log speed, the
emulator's slope at each group's prior centre) times the log of that factor.

    python benchmarks/practice_bound.py OUT.json EMULATOR.pkl FRESH.pkl [--floors T P D]

EMULATOR.pkl: a `build_emulator` pickle; FRESH.pkl: `emulator_bias.py simulate`'s
(`fresh`: simulated people with 3 trials per condition). `--floors`: each measure's
floor F_m given (e.g. a loop bench's per-measure error of the model given the true
effect) instead of computed from FRESH.pkl.
"""

from __future__ import annotations

import json
import pickle
import sys

import numpy as np

from study.analysis.participant_fit.emulator import log_moment
from study.analysis.participant_fit.estimate import prior_arrays
from study.protocol.traits import PROFILES, TRAITS

SIZES = {"outsider": 20, "novice": 8, "expert": 8}
TRIALS = 3
SLOWING, DECAY = 0.5, 2.0
TARGET = 0.30


def main(out: str, emulator_path: str, fresh_path: str, floors: list[float] | None = None) -> None:
    with open(emulator_path, "rb") as f:
        emu = pickle.load(f)
    with open(fresh_path, "rb") as f:
        fresh = pickle.load(f)["fresh"]
    measures = list(emu.measures_)
    positions = np.arange(2 * TRIALS)
    shift = np.log1p(SLOWING * np.exp(-positions / DECAY))  # log slowing of the speed
    missed = shift - shift.mean()
    speed = TRAITS.index("preferred_speed_m_s")
    floor_sq, bias_sq, elasticity = {}, {}, {}
    for m in measures:
        f2, b2, el = [], [], {}
        for g, n_group in SIZES.items():
            centre = prior_arrays(PROFILES[g])[0]
            jac = emu.jacobian(centre, 1e-3 * np.abs(centre))
            for c in ("VO", "HV"):
                j = emu.moments_.index(f"{c}:{m}")
                e = float(jac[j, speed] * centre[speed])  # d log m / d log speed
                el[f"{g} {c}"] = round(e, 3)
                logs = log_moment(fresh[(fresh["group"] == g) & (fresh["condition"] == c)][m])
                # each (order, position) cell of this group and condition: half the group
                f2 += [float(np.var(logs, ddof=1)) / (n_group / 2)] * len(positions)
                # the speed divided by the factor: the measure's log moves by -e * shift
                b2 += list((e * missed) ** 2)
        floor_sq[m], bias_sq[m], elasticity[m] = float(np.mean(f2)), float(np.mean(b2)), el
    if floors is not None:
        floor_sq = {m: f * f for m, f in zip(measures, floors, strict=True)}
    f_sum, b_time = sum(floor_sq.values()), bias_sq["completion_time_s"]
    time_only = 1 - np.sqrt(f_sum / (f_sum + b_time))
    every = 1 - np.sqrt(f_sum / (f_sum + sum(bias_sq.values())))
    # people needed (a multiple of 20/8/8) for the time-only bound to reach the target:
    # F^2 / (F^2 + B^2) <= (1 - target)^2, F^2 falling as 1 / multiple
    keep = (1 - TARGET) ** 2
    multiple = f_sum * (1 - keep) / (keep * b_time)
    report = {
        "data_source": "simulated",
        "command": "python benchmarks/practice_bound.py " + " ".join(sys.argv[1:]),
        "definition": "RMS over cells (group x condition x order x position) and measures "
        "of held-out mean log measure minus model mean; bound: 1 - sqrt(sum_m F_m^2 / "
        "sum_m (F_m^2 + B_m^2))",
        "study": {"sizes": SIZES, "trials_per_condition": TRIALS},
        "practice": {"slowing": SLOWING, "decay_trials": DECAY},
        "floors_from": "given (--floors)"
        if floors is not None
        else "the fresh people's "
        "SD of one trial's log measure per group and condition, over half the group",
        "noise_floor_rms_by_measure": {m: round(float(np.sqrt(v)), 4) for m, v in floor_sq.items()},
        "noise_floor_rms": round(float(np.sqrt(f_sum / len(measures))), 4),
        "missed_shift_rms_by_measure": {m: round(float(np.sqrt(v)), 4) for m, v in bias_sq.items()},
        "elasticity_to_speed": elasticity,
        "largest_reduction_time_only": round(float(time_only), 4),
        "largest_reduction_every_measure": round(float(every), 4),
        "target": TARGET,
        "people_multiple_for_target_time_only": round(float(multiple), 1),
        "time_alone_largest_reduction": round(
            float(
                1
                - np.sqrt(floor_sq["completion_time_s"] / (floor_sq["completion_time_s"] + b_time))
            ),
            4,
        ),
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps({k: v for k, v in report.items() if k != "elasticity_to_speed"}, indent=1))


if __name__ == "__main__":
    given = sys.argv.index("--floors") if "--floors" in sys.argv else None
    main(*sys.argv[1:4], [float(v) for v in sys.argv[given + 1 : given + 4]] if given else None)
