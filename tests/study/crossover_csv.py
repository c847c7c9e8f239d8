"""A 20/8/8 AB/BA crossover of LCCA trials as the export writes them, drawn with numpy:
the study the crossover checks and the export round trip are tested on, with a period
effect and a carry-over planted on request (shares of the mean completion time)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from study.protocol.exchange import PROVENANCE_COLUMNS, TRIAL_COLUMNS

GROUPS = {"outsider": 20, "novice": 8, "expert": 8}
MEAN_S = 30.0


def crossover_trials(
    seed: int, period: float = 0.0, carry_over: float = 0.0, driver: str = "simulated"
) -> pd.DataFrame:
    """One row per trial (3 per block, blocks VO/HV in AB or BA order, alternating
    within each group): completion time MEAN_S + group + HV (-2 s) + participant
    (sd 3 s) + noise (sd 3 s); `period` x MEAN_S added to every second-block trial and
    `carry_over` x MEAN_S to VO after HV (the differential carry-over of
    `study.analysis.crossover`)."""
    rng = np.random.default_rng(seed)
    rows = []
    number = 0
    for group, n in GROUPS.items():
        shift = {"outsider": 4.0, "novice": 0.0, "expert": -4.0}[group]
        for i in range(n):
            number += 1
            order = ("VO", "HV") if i % 2 == 0 else ("HV", "VO")
            person = rng.normal(0.0, 3.0)
            for block, condition in enumerate(order, start=1):
                for trial in range(1, 4):
                    time_s = MEAN_S + shift + person + rng.normal(0.0, 3.0)
                    time_s += -2.0 if condition == "HV" else 0.0
                    time_s += period * MEAN_S if block == 2 else 0.0
                    time_s += carry_over * MEAN_S if (block, condition) == (2, "VO") else 0.0
                    rows.append(
                        {
                            "participant": f"P{number:03d}",
                            "group": group,
                            "task": "lcca",
                            "condition": condition,
                            "trial": trial,
                            "completion_time_s": round(max(time_s, 1.0), 3),
                            "peak_proximal_force_n": round(abs(rng.normal(0.8, 0.2)), 4),
                            "peak_distal_force_n": round(abs(rng.normal(0.3, 0.1)), 4),
                            "success": "true",
                            "block": block,
                            "data_source": "simulated" if driver == "simulated" else "measured",
                            "driver": driver,
                            "withdrawn": "false",
                            "valid": "true",
                            "invalid_reason": "",
                            "included": "yes",
                        }
                    )
    return pd.DataFrame(rows, columns=[*TRIAL_COLUMNS, *PROVENANCE_COLUMNS])
