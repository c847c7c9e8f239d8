"""The fitted model's predicted means: the emulator's, corrected by its discrepancy from
the people simulated from the fit (`summaries.emulator_discrepancy`, `_model_row`),
checked against hand-computed values on a toy emulator whose offset from the
"simulator" is known."""

from __future__ import annotations

import json
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit.summaries import (
    TRAIT_COLUMN,
    _model_row,
    emulator_discrepancy,
    summaries,
)
from study.protocol.traits import TRAITS


class LinearEmulator:
    """Expected force = 1 + 10 * the first trait in VO, 0.5 + 10 * the first trait in HV."""

    moments_: ClassVar[list[str]] = ["VO:force_n", "HV:force_n"]

    def means(self, traits: np.ndarray) -> np.ndarray:
        speed = traits[:, 0]
        return np.column_stack([1.0 + 10 * speed, 0.5 + 10 * speed])


def simulated_people(offset: dict[str, float], noise: np.ndarray) -> pd.DataFrame:
    """Four people of one group, two trials per condition; trait 0 differs between them
    (so the people's own means spread), the trials are the emulator's mean plus
    `offset[condition]` plus `noise` (person, condition, trial)."""
    rows = []
    speeds = [0.01, 0.02, 0.04, 0.08]
    for i, speed in enumerate(speeds):
        traits = {f"{TRAIT_COLUMN}{t}": 0.5 for t in TRAITS}
        traits[f"{TRAIT_COLUMN}{TRAITS[0]}"] = speed
        for c, condition in enumerate(("VO", "HV")):
            base = (1.0 if condition == "VO" else 0.5) + 10 * speed
            for k in range(2):
                rows.append(
                    {
                        "group": "novice",
                        "participant": f"S{i:03d}",
                        "condition": condition,
                        "force_n": base + offset[condition] + noise[i, c, k],
                        **traits,
                    }
                )
    return pd.DataFrame(rows)


def test_the_discrepancy_is_the_offset_and_its_se_the_trials_noise_only() -> None:
    noise = np.array(
        [
            [[0.02, -0.02], [0.01, 0.03]],
            [[0.00, 0.04], [-0.02, 0.00]],
            [[-0.03, -0.01], [0.02, 0.02]],
            [[0.01, 0.01], [0.00, -0.04]],
        ]
    )
    frame = simulated_people({"VO": 0.2, "HV": -0.1}, noise)
    found = emulator_discrepancy(frame, ["force_n"], ["novice"], LinearEmulator())
    # by hand: each person's residual in VO is 0.2 + the mean of their two VO noises
    vo = 0.2 + noise[:, 0].mean(axis=1)  # 0.2, 0.22, 0.18, 0.21
    hv = -0.1 + noise[:, 1].mean(axis=1)  # -0.08, -0.11, -0.08, -0.12
    for label, r in (("VO", vo), ("HV", hv), ("HV-VO", hv - vo)):
        shift, se, n = found[("novice", "force_n", label)]
        assert n == 4
        assert shift == pytest.approx(r.mean(), abs=1e-12)
        assert se == pytest.approx(r.std(ddof=1) / 2.0, abs=1e-12)
    assert found[("novice", "force_n", "VO")][0] == pytest.approx(0.2025, abs=1e-12)
    # the difference in the analysis's sign, HV - VO
    assert found[("novice", "force_n", "HV-VO")][0] == pytest.approx(-0.0975 - 0.2025, abs=1e-12)
    # the people's spread (trait 0 from 0.01 to 0.08: 0.7 N) does not enter the SE: the
    # SE of their plain mean is over ten times larger
    plain = frame[frame["condition"] == "VO"].groupby("participant")["force_n"].mean()
    assert found[("novice", "force_n", "VO")][1] < plain.std(ddof=1) / 2.0 / 10


def test_the_model_row_moves_by_the_discrepancy_and_widens_by_its_t_interval() -> None:
    draws = np.concatenate([[1.0], np.linspace(0.8, 1.3, 401)])
    low, high = 0.8125, 1.2875  # the replicates' 2.5 and 97.5 percentiles
    row = _model_row(draws, (0.1, 0.05, 10))
    half = 2.2621572 * 0.05  # t(0.975, 9) * SE
    assert row["emulator"] == 1.0
    assert row["emulator_ci"] == pytest.approx([low, high], abs=1e-12)
    assert row["mean"] == pytest.approx(1.1, abs=1e-12)
    assert row["ci_low"] == pytest.approx(1.1 - np.sqrt((1.0 - low) ** 2 + half**2), abs=1e-7)
    assert row["ci_high"] == pytest.approx(1.1 + np.sqrt((high - 1.0) ** 2 + half**2), abs=1e-7)
    # without a discrepancy: the emulator's own prediction and percentile interval
    plain = _model_row(draws, None)
    assert (plain["mean"], plain["ci_low"], plain["ci_high"]) == pytest.approx((1.0, low, high))
    assert "discrepancy" not in plain


def test_the_summaries_model_rows_carry_the_correction_and_write_as_strict_json() -> None:
    frame = simulated_people({"VO": 0.2, "HV": -0.1}, np.zeros((4, 2, 2)))
    frame["position"] = 0
    rng = np.random.default_rng(0)
    draws = np.linspace(1.0, 2.0, 41)
    predicted = {
        "novice": {"VO:force_n": draws, "HV:force_n": draws - 0.5, "HV-VO:force_n": draws * 0 - 0.5}
    }
    found = emulator_discrepancy(frame, ["force_n"], ["novice"], LinearEmulator())
    rows = pd.DataFrame(summaries(frame, frame, ["force_n"], ["novice"], predicted, rng, 50, found))
    model = rows[rows["source"] == "model"].set_index("condition")
    # exact offsets, no noise: the SE is 0 and the interval is the emulator's, moved
    assert model.loc["HV-VO", "mean"] == pytest.approx(-0.5 - 0.3, abs=1e-12)
    assert model.loc["HV-VO", "ci_low"] == pytest.approx(-0.8, abs=1e-12)
    assert model.loc["VO", "discrepancy"] == pytest.approx(0.2, abs=1e-12)
    # the fit writes the rows with NaN (the observed rows have no discrepancy) dropped
    records = [
        {k: v for k, v in r.items() if not (isinstance(v, float) and np.isnan(v))}
        for r in rows.to_dict(orient="records")
    ]
    json.loads(json.dumps(records, default=float), parse_constant=pytest.fail)
