"""What the participant fit reports, held to hand-computed values: the intervals of a
positive measure on the log scale (they stay above zero), the HV - VO sign of the
summaries' difference (the analysis's), and a gap between the observed and simulated
means beyond its interval named as a lack."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from study.analysis.participant_fit.checks import lacks_line, summary_gaps
from study.analysis.participant_fit.estimate import expanded_interval
from study.analysis.participant_fit.observed import bootstrap_means
from study.analysis.participant_fit.summaries import (
    DIFFERENCE,
    _model_row,
    condition_values,
    source_rows,
)

# four people's peak forces, one of them far out (a skewed measure, as a force is)
FORCES = np.array([0.3, 0.35, 0.4, 3.0])


def test_a_positive_measures_interval_is_widened_on_the_log_scale_and_stays_above_zero() -> None:
    low, high = bootstrap_means(FORCES, np.random.default_rng(2), 2000)
    # widened on the force's own scale (t(3) over 4 people), its lower end is below 0 N
    assert low < 0
    low, high = bootstrap_means(FORCES, np.random.default_rng(2), 2000, positive=True)
    # by hand: the same resamples' means, the expanded percentile interval of their logs
    idx = np.random.default_rng(2).integers(0, 4, (2000, 4))
    logs = np.log(FORCES[idx].mean(axis=1))
    p_low, mid, p_high = np.percentile(logs, [2.5, 50.0, 97.5])
    widen = np.sqrt(4 / 3) * stats.t.ppf(0.975, 3) / stats.norm.ppf(0.975)
    assert low == pytest.approx(np.exp(mid - widen * (mid - p_low)))
    assert high == pytest.approx(np.exp(mid + widen * (p_high - mid)))
    assert 0 < low < FORCES.mean() < high


def test_a_replicate_at_zero_leaves_the_ordinary_interval() -> None:
    boots = np.array([0.0, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(
        expanded_interval(boots, 4, positive=True), expanded_interval(boots, 4)
    )


def test_the_model_rows_interval_of_a_positive_measure_is_relative() -> None:
    draws = np.concatenate([[1.0], np.linspace(0.8, 1.3, 401)])
    low, high = 0.8125, 1.2875  # the replicates' 2.5 and 97.5 percentiles
    # a discrepancy of -0.9 (SE 0.2, 5 people): on the measure's own scale the interval
    # reaches far below 0
    plain = _model_row(draws, (-0.9, 0.2, 5))
    assert plain["ci_low"] < 0
    row = _model_row(draws, (-0.9, 0.2, 5), positive=True)
    half = stats.t.ppf(0.975, 4) * 0.2
    centre = 0.1
    assert row["mean"] == pytest.approx(centre)
    assert row["ci_low"] == pytest.approx(
        centre * np.exp(-np.hypot(np.log(1.0 / low), half / centre))
    )
    assert row["ci_high"] == pytest.approx(
        centre * np.exp(np.hypot(np.log(high / 1.0), half / centre))
    )
    assert row["ci_low"] > 0


def _trials(vo: list[float], hv: list[float], group: str = "outsider") -> pd.DataFrame:
    rows = []
    for i, (a, b) in enumerate(zip(vo, hv, strict=True)):
        rows += [
            {"group": group, "participant": f"P{i}", "condition": "VO", "force_n": a},
            {"group": group, "participant": f"P{i}", "condition": "HV", "force_n": b},
        ]
    return pd.DataFrame(rows)


def test_the_difference_is_hv_minus_vo_as_the_analysis_takes_it() -> None:
    frame = _trials([2.0, 3.0], [1.5, 2.0])
    found = {c: v for _, _, c, v in condition_values(frame, ["force_n"], ["outsider"])}
    assert DIFFERENCE == "HV-VO"
    assert set(found) == {"VO", "HV", "HV-VO"}
    # HV lower than VO: a negative difference, as `study analyze`'s mean_diff
    np.testing.assert_allclose(found["HV-VO"], [-0.5, -1.0])
    rows = source_rows("observed", frame, ["force_n"], ["outsider"], np.random.default_rng(0), 50)
    diff = next(r for r in rows if r["condition"] == "HV-VO")
    assert diff["mean"] == pytest.approx(-0.75)


def _table(observed: tuple[float, float, float], simulated: tuple[float, float, float]):
    cols = ["group", "measure", "condition", "source", "mean", "ci_low", "ci_high"]
    return pd.DataFrame(
        [
            ("outsider", "completion_time_s", "HV", "observed", *observed),
            ("outsider", "completion_time_s", "HV", "simulated", *simulated),
            ("outsider", "completion_time_s", "HV", "model", 50.0, 40.0, 60.0),
        ],
        columns=cols,
    )


NOTHING = {"flagged": [], "limit": 10.0}


def test_a_gap_beyond_its_interval_is_a_lack_not_nothing() -> None:
    # the observed outsiders' HV time 29.2 s against 54.0 s simulated, as a pilot gave
    table = _table((29.2, 24.0, 35.0), (54.0, 45.0, 64.0))
    gaps = summary_gaps(table, DIFFERENCE)
    (row,) = gaps["rows"]
    # by hand, on the log scale: log(29.2 / 54.0) = -0.615; the interval's upper end adds
    # the observed mean's upper and the simulated's lower half-widths in quadrature
    gap = np.log(29.2 / 54.0)
    up = np.hypot(np.log(35.0 / 29.2), np.log(54.0 / 45.0))
    down = np.hypot(np.log(29.2 / 24.0), np.log(64.0 / 54.0))
    assert row["gap_scale"] == "ratio"
    assert row["gap"] == pytest.approx(29.2 / 54.0)
    assert row["gap_ci95"] == pytest.approx([np.exp(gap - down), np.exp(gap + up)])
    assert row["gap_ci95"][1] < 1
    assert row["flagged"]
    misfit = {"rows": [], "flagged": [], "held": []}
    line = lacks_line([], NOTHING, misfit, gaps)
    assert "nothing" not in line
    assert "outsider HV completion_time_s (29.2 observed vs 54 simulated" in line


def test_a_gap_within_its_interval_is_named_beside_nothing_found() -> None:
    # the tutorial's pilot: 4 outsiders, 29.2 s (16.7-45.0) observed, 54.0 s
    # (25.1-93.0) simulated in HV; a small gap in VO
    table = pd.concat(
        [
            _table((29.2, 16.7, 45.0), (54.0, 25.1, 93.0)),
            _table((31.1, 21.0, 39.4), (34.6, 24.2, 48.0)).assign(condition="VO"),
        ]
    )
    gaps = summary_gaps(table, DIFFERENCE)
    # by hand: |log(29.2 / 54)| = 0.615 < hypot(log(29.2 / 16.7), log(93 / 54)) = 0.779
    assert gaps["flagged"] == []
    line = lacks_line([], NOTHING, {"rows": [], "flagged": [], "held": []}, gaps)
    assert line.startswith("what the participants lack: nothing the checks found")
    assert "gaps" in line
    # its upper end: exp(-0.615 + hypot(log(45 / 29.2), log(54 / 25.1))) = 1.30
    # the larger share of its half-width (0.615 / 0.780 against VO's 0.107 / 0.511)
    assert (
        "; the largest gap, outsider HV completion_time_s (29.2 observed vs 54 simulated: "
        "observed / simulated 0.54, 95 % 0.25-1.30), lies within its 95 % interval" in line
    )
    # no gap at all: nothing named
    same = summary_gaps(_table((50.0, 40.0, 62.0), (50.0, 40.0, 62.0)), DIFFERENCE)
    assert "largest gap" not in lacks_line([], NOTHING, None, same)


def test_the_difference_gap_is_on_the_measures_own_scale() -> None:
    table = _table((-1.0, -1.5, -0.5), (0.5, 0.2, 0.8)).assign(condition=DIFFERENCE)
    (row,) = summary_gaps(table, DIFFERENCE)["rows"]
    assert row["gap_scale"] == "difference"
    assert row["gap"] == pytest.approx(-1.5)
    assert row["gap_ci95"] == pytest.approx([-1.5 - np.hypot(0.5, 0.3), -1.5 + np.hypot(0.5, 0.3)])
    assert row["flagged"]


def test_a_probed_trait_held_at_its_prior_is_reported_with_why() -> None:
    from study.analysis.participant_fit.fit import TraitPlan
    from study.protocol.traits import TRAITS

    # the force-threshold probe: SE 0.0011 N m against the outsiders' prior SD 0.0008
    info = np.zeros(len(TRAITS))
    j = TRAITS.index("haptic_threshold_n_m")
    info[j] = (0.0008 / 0.0011) ** 2  # 0.529
    fitted = [TRAITS.index("reaction_s")]
    plan = TraitPlan(
        told=fitted,
        free=fitted,
        weak=[],
        ratios={"haptic_threshold_n_m": 0.62, "reaction_s": 0.3},
        held_out=None,
        sources={},
        probe_info={"outsider": info},
        people={"outsider": 4},
    )
    why = plan.probed_but_held()
    # only the probed trait among those held: the others no probe told
    assert list(why) == ["haptic_threshold_n_m"]
    w = why["haptic_threshold_n_m"]
    # by hand: 1 / sqrt(1 + 4 * 0.529 / 1.529) = 0.648; ratio < 0.5 needs
    # n * 0.529 / 1.529 > 3, so n >= 9
    assert w["probe_ratio"] == pytest.approx(0.648, abs=1e-3)
    assert w["probe_se_in_prior_sd"] == pytest.approx(1.375, abs=1e-3)
    assert w["people_needed"] == 9
    assert w["ratio"] == 0.62
    # at 4 people the rule needs 4 I / (1 + I) > 3, I > 3: an SE under sqrt(1/3) = 0.577
    assert w["probe_se_needed"] == pytest.approx(0.577, abs=1e-3)
    line = plan.held_line()
    assert line.startswith("probed, yet held at their priors")
    assert "haptic_threshold_n_m (a person's probe SE 1.4 prior SDs" in line
    assert "group outsider's 4 people tell its mean to 0.62" in line
    assert "a probe SE under 0.58 prior SDs (more probe trials) or 9 people a group" in line
    # with 3 people no probe is enough: even an exact one tells the mean to 1 / sqrt(4)
    plan.people["outsider"] = 3
    assert plan.probed_but_held()["haptic_threshold_n_m"]["probe_se_needed"] is None
    assert "or 9 people" not in plan.held_line()
    assert "9 people a group would tell it" in plan.held_line()


def test_a_task_feature_the_design_defines_too_rarely_is_named_as_dropped_not_absent() -> None:
    from study.analysis.participant_fit.emulator import MIN_DEFINED, MomentEmulator
    from study.analysis.participant_fit.fit import features_note
    from tests.study.test_participant_fit_validate import MEASURES, synthetic_trials

    rng = np.random.default_rng(4)

    def emulator(settings: int) -> MomentEmulator:
        x = rng.uniform(0.5, 1.5, (settings, 7))
        trials = synthetic_trials(np.zeros((settings, 2)), 1, rng)
        # one feature every trial shows, one none does
        trials = trials.assign(stall_s=rng.uniform(0.2, 0.4, len(trials)), approaches=np.nan)
        return MomentEmulator(mean_surface=False).fit(
            x, trials, MEASURES, ("stall_s", "approaches")
        )

    few = emulator(MIN_DEFINED - 4)  # 16 settings x 1 repeat: 16 trials a condition
    assert few.features_ == []
    assert few.dropped_features_ == {"stall_s": MIN_DEFINED - 4, "approaches": 0}
    note = features_note(few.features_, few)
    assert "no sample features" not in note
    assert note.startswith("the measures only; 2 of the task's sample features dropped")
    assert "at most 16 trials of a condition, and a feature needs 20" in note
    enough = emulator(MIN_DEFINED)
    assert enough.features_ == ["stall_s"]
    assert enough.dropped_features_ == {"approaches": 0}
    note = features_note(enough.features_, enough)
    assert note.startswith("behavioural features")
    assert note.endswith(
        "; the task's sample features approaches are not in the emulator's design trials"
    )
    # a task without features
    none = MomentEmulator(mean_surface=False).fit(
        rng.uniform(0.5, 1.5, (20, 7)), synthetic_trials(np.zeros((20, 2)), 1, rng), MEASURES
    )
    assert features_note(none.features_, none) == (
        "the task has no sample features: the measures only"
    )


def test_the_figure_draws_positive_intervals_above_zero_and_titles_the_difference_hv_minus_vo() -> (
    None
):
    import matplotlib

    matplotlib.use("Agg")
    from study.analysis.participant_fit.figure import fit_figure

    # the four skewed forces in VO, a little lower in HV; both sources alike
    frame = _trials(list(FORCES), list(FORCES - 0.1)).rename(
        columns={"force_n": "peak_distal_force_n"}
    )
    rng = np.random.default_rng(5)
    rows = [
        {**r, "measure": "peak_distal_force_n"}
        for source in ("observed", "simulated", "model")
        for r in source_rows(source, frame, ["peak_distal_force_n"], ["outsider"], rng, 500)
    ]
    fig = fit_figure(pd.DataFrame(rows), "SIMULATED")
    vo, hv, diff = fig.axes[:3]
    assert [vo.get_title(), hv.get_title(), diff.get_title()] == ["VO", "HV", "HV - VO"]
    for ax in (vo, hv):
        # every interval's ends (the "_" marks) above 0 N
        ends = np.concatenate([line.get_ydata() for line in ax.lines if line.get_marker() == "_"])
        assert len(ends) == 6
        assert ends.min() > 0
    # HV lower by 0.1 N in every person: the difference drawn at -0.1
    means = [line.get_ydata()[0] for line in diff.lines if line.get_marker() == "o"]
    assert means == pytest.approx([-0.1])
