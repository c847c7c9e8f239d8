"""Coverage of the fitted group means' 95 % intervals (`participant_fit.coverage`), on an
emulator fitted to a made-up, exactly log-linear task (no physics: quick), where the
fit's model holds and a calibrated interval must hold the truth about 95 % of the time."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit.coverage import coverage, draw_moments, typical_probe_se
from study.analysis.participant_fit.emulator import MomentEmulator, design_box, design_settings
from study.protocol.traits import PROFILES, TRAITS

MEASURES = ("completion_time_s", "peak_force_n")
NOISE_SD = 0.15
"""Trial noise of each log measure."""


def _made_up_emulator() -> MomentEmulator:
    """log time = 1 - log(speed / 0.014) + 0.5 log(reaction / 0.28) (+ 0.1 in HV);
    log force = -0.5 + 0.8 log(speed / 0.014) (- 0.3 in HV); the other traits act on
    nothing. 200 settings, 3 trials per condition, noise NOISE_SD."""
    rng = np.random.default_rng(0)
    x = design_settings(200, 0, design_box())
    rows = []
    for s, row in enumerate(x):
        speed, reaction = np.log(row[0] / 0.014), np.log(row[1] / 0.28)
        for r in range(3):
            for c, (dt, df) in {"VO": (0.0, 0.0), "HV": (0.1, -0.3)}.items():
                rows.append(
                    {
                        "setting": s,
                        "repeat": r,
                        "condition": c,
                        "completion_time_s": np.exp(
                            1 - speed + 0.5 * reaction + dt + NOISE_SD * rng.standard_normal()
                        ),
                        "peak_force_n": np.exp(
                            -0.5 + 0.8 * speed + df + NOISE_SD * rng.standard_normal()
                        ),
                    }
                )
    return MomentEmulator().fit(x, pd.DataFrame(rows), MEASURES)


def test_people_drawn_on_the_emulator_have_the_noise_of_their_k_trials() -> None:
    emulator = _made_up_emulator()
    profile = PROFILES["novice"]
    y, probed = draw_moments(emulator, profile, 4000, 4.0, np.random.default_rng(1))
    assert probed is None
    # the time's spread over people: speed's and reaction's spread through the slopes
    # (sd of log speed ~ 0.003 / 0.014, of log reaction ~ 0.05 / 0.28), plus the noise of
    # a mean of 4 trials (NOISE_SD / 2); computed from the draws' own traits, it is the
    # sum of the two, so the noise is the remainder
    idx = emulator.moments_.index("VO:completion_time_s")
    speed_sd, reaction_sd = 0.003 / 0.014, 0.05 / 0.28
    expected = np.sqrt(speed_sd**2 + (0.5 * reaction_sd) ** 2 + (NOISE_SD / 2) ** 2)
    assert y[:, idx].std() == pytest.approx(expected, rel=0.1)


def test_people_drawn_with_probes_carry_their_probe_error() -> None:
    emulator = _made_up_emulator()
    profile = PROFILES["novice"]
    j = TRAITS.index("reaction_s")
    se = np.full(len(TRAITS), np.nan)
    se[j] = 0.04
    _, probed = draw_moments(emulator, profile, 4000, 4.0, np.random.default_rng(3), se)
    assert probed is not None
    assert probed.shape == (4000, len(TRAITS), 2)
    # a probe's estimate: the person's trait (N(0.28, 0.05), far inside its bounds) plus
    # its error of SE 0.04: mean 0.28, SD sqrt(0.05^2 + 0.04^2) = 0.064
    mean, sd = profile.reaction_s
    assert probed[:, j, 0].mean() == pytest.approx(mean, abs=0.004)
    assert probed[:, j, 0].std() == pytest.approx(np.hypot(sd, 0.04), rel=0.05)
    assert (probed[:, j, 1] == 0.04).all()
    others = [i for i in range(len(TRAITS)) if i != j]
    assert np.isnan(probed[:, others]).all()


def test_typical_probe_se_is_the_median_over_the_people_who_have_it() -> None:
    arrays = np.full((3, len(TRAITS), 2), np.nan)
    arrays[:, 0, 1] = [0.1, 0.3, 0.2]
    arrays[:2, 1, 1] = [0.5, 0.7]  # the third person lacks this probe
    se = typical_probe_se({"novice": arrays})["novice"]
    assert se[0] == pytest.approx(0.2)
    assert se[1] == pytest.approx(0.6)
    assert np.isnan(se[2:]).all()


def test_the_intervals_of_a_fit_whose_model_holds_cover_the_truth() -> None:
    emulator = _made_up_emulator()
    free = [TRAITS.index("preferred_speed_m_s"), TRAITS.index("reaction_s")]
    out = coverage(
        emulator,
        {g: PROFILES[g] for g in ("novice", "expert")},
        {"novice": 8, "expert": 8},
        3.0,
        free,
        studies=15,
        bootstrap=25,
        seed=2,
    )
    assert out["intervals"] == 15 * 2 * 2
    assert {(r["group"], r["trait"]) for r in out["per_trait"]} == {
        (g, t) for g in ("novice", "expert") for t in ("preferred_speed_m_s", "reaction_s")
    }
    # 60 intervals at 95 %: 57 expected; fewer than 48 (80 %) has probability < 0.1 %
    # (binomial(60, 0.95)); the bootstrap's percentile intervals of 25 replicates run a
    # little narrow, so only the lower side is held
    assert out["coverage"] >= 0.80, out


def test_the_trait_plan_decides_per_trait_fitted_prior_or_told_by_another_source() -> None:
    """`plan_traits` is the one place a trait's source is decided: the made-up task tells
    the preferred speed (both measures follow it), nothing tells the caution, and a trait
    told by another source (a measurement before the task) is neither fitted from the
    task's data nor held at its prior."""
    from study.analysis.participant_fit.fit import FitData, FitSettings, plan_traits

    emulator = _made_up_emulator()
    groups = ["novice", "expert"]
    data = FitData(
        trials=pd.DataFrame(),
        measures=list(MEASURES),
        groups=groups,
        people=pd.DataFrame(),
        by_group={},
        ks={g: 3.0 for g in groups},
        sizes={g: np.full(len(emulator.moments_), 12) for g in groups},
        sampled=0,
        source="simulated",
        counts={},
    )
    plan = plan_traits(emulator, data, FitSettings())
    assert plan.role("preferred_speed_m_s") == "fitted"
    assert plan.role("caution") == "prior"
    assert "caution" in plan.fixed
    told = plan_traits(emulator, data, FitSettings(), {"preferred_speed_m_s": "probes"})
    assert told.role("preferred_speed_m_s") == "probes"
    j = TRAITS.index("preferred_speed_m_s")
    assert j not in told.free
    assert j not in told.told
    assert "preferred_speed_m_s" not in told.fixed
