"""The participant fit reads each trial's behavioural features off the samples the session
runner stored: checked against the simulated people's own traits, which the
study's seed and the participants' codes give back (`session.participant_traits`), on
SQLite and on the PostgreSQL server."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.study import Participant, Study
from db.models.trial import SampleChunk, Trial
from study.analysis.participant_fit.observed import observed_trials, with_features
from study.protocol.demo import run_demo
from study.protocol.session import participant_traits
from study.protocol.tasks import get_task


def test_the_features_of_stored_trials_follow_the_peoples_traits(db_url: str) -> None:
    run_demo(db_url, 4, jobs=1, quick=True)  # 2 people per group, one trial per block
    engine = open_database(db_url, create=False)
    try:
        trials = observed_trials(engine, "lcca")
        with Session(engine) as session:
            seed = session.scalars(select(Study.seed)).one()
        features, counts = with_features(engine, trials, "lcca")
        with Session(engine) as session:
            # each trial's state of its person (the traits varied from trial to trial)
            states = {
                (code, condition): summary["trial_state"]
                for code, condition, summary in session.execute(
                    select(Participant.code, Trial.condition, Trial.summary)
                    .join(Trial, Trial.participant_id == Participant.id)
                    .where(Trial.practice.is_(False), Trial.status == "completed")
                )
            }
    finally:
        engine.dispose()
    assert counts == {"with_samples": len(trials), "without_samples": 0}
    assert len(trials) == 3 * 2 * 2
    for row in features.itertuples():
        traits = participant_traits(seed, row.participant, row.group)
        state = states[(row.participant, row.condition)]
        # the trial's state: the person's traits varied, the caution the person's own
        assert state["caution"] == traits.caution
        # the advance: the trial's preferred speed (the hand's grip against the return
        # spring and, in HV, the felt force take a few per cent off the aim)
        assert row.advance_speed_m_s == pytest.approx(state["preferred_speed_m_s"], rel=0.15)
        if row.condition == "VO" and np.isfinite(row.target_speed_ratio):
            # inside the target the participant goes on at 1 - 0.4 caution of its speed
            # (`SimulatedParticipant._plan`)
            assert row.target_speed_ratio == pytest.approx(1 - 0.4 * traits.caution, abs=0.03)
    vo = features[features["condition"] == "VO"]
    assert np.isfinite(vo["target_speed_ratio"]).sum() >= 4
    assert np.isfinite(features["turn_peak_s"]).any()


def test_a_trial_without_samples_gives_the_measures_only(tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    run_demo(db, 4, jobs=1, quick=True)
    engine = open_database(db, create=False)
    try:
        with Session(engine) as session, session.begin():
            first = session.scalars(
                select(Trial.id)
                .where(Trial.task == "lcca", Trial.status == "completed")
                .order_by(Trial.id)
            ).first()
            session.execute(delete(SampleChunk).where(SampleChunk.trial_id == first))
        trials = observed_trials(engine, "lcca")
        features, counts = with_features(engine, trials, "lcca")
    finally:
        engine.dispose()
    assert counts == {"with_samples": len(trials) - 1, "without_samples": 1}
    names = list(get_task("lcca").fit_features)
    empty = features[names].isna().all(axis=1)
    assert empty.sum() == 1
    # the measures are all there
    assert features.loc[empty, "completion_time_s"].notna().all()


def test_the_bench_truth_lies_off_the_priors_by_the_shift() -> None:
    from study.bench.participants import truth_profiles
    from study.protocol.traits import PROFILES, TRAIT_BOUNDS, TRAITS

    truth = truth_profiles(0.7)
    for group, profile in PROFILES.items():
        for trait in TRAITS:
            (mean, sd), (moved, moved_sd) = getattr(profile, trait), getattr(truth[group], trait)
            assert moved_sd == sd
            assert abs(moved - mean) == pytest.approx(0.7 * sd, rel=1e-9), (group, trait)
            low, high = TRAIT_BOUNDS[trait]
            assert moved <= high - sd
            assert moved > mean or moved >= low + sd  # down only with an SD left to the bound
    # up and down in turn: the experts' (group 2) haptic threshold (trait 4) moves up
    assert truth["expert"].haptic_threshold_n_m[0] == pytest.approx(0.0033 + 0.7 * 0.0006)
    # and the novices' (group 1) down
    assert truth["novice"].haptic_threshold_n_m[0] == pytest.approx(0.0037 - 0.7 * 0.0007)
    assert truth_profiles(0.0) == PROFILES


def test_the_oracle_bound_is_the_normal_mean_s_chance_of_lying_within_the_tolerance() -> None:
    from scipy.stats import norm

    from study.bench.participants import oracle_within
    from study.protocol.traits import TRAIT_BOUNDS, TRAITS, GroupProfile

    # every trait mid-way between its bounds, with an SD (a quarter of the mean) that
    # leaves the clipping 4 SDs away: the people's mean of n is then N(mu, sd^2 / n), and
    # |mean - mu| <= 0.15 mu has the chance 2 Phi(0.15 mu sqrt(n) / sd) - 1
    mid = {t: (lo + hi) / 2 for t, (lo, hi) in TRAIT_BOUNDS.items()}
    sd = {t: min(0.25 * m, (TRAIT_BOUNDS[t][1] - m) / 4) for t, m in mid.items()}
    profile = GroupProfile(**{t: (mid[t], sd[t]) for t in TRAITS})
    out = oracle_within({"a": profile, "b": profile}, {"a": 8, "b": 3}, studies=20000)
    expected = {
        (g, t): 2 * norm.cdf(0.15 * mid[t] * np.sqrt(n) / sd[t]) - 1
        for g, n in (("a", 8), ("b", 3))
        for t in TRAITS
    }
    for row in out["per_trait"]:
        # 20000 studies: a binomial SE of at most 0.0035
        chance = expected[(row["group"], row["trait"])]
        assert row["probability"] == pytest.approx(chance, abs=0.015)
    assert out["expected_within"] == pytest.approx(sum(expected.values()), abs=0.1)
    # the traits are drawn independently: all at once is the product of the chances
    assert out["all_within_share"] == pytest.approx(np.prod(list(expected.values())), abs=0.015)
    shares = out["at_least_share"]
    assert shares[2 * len(TRAITS)] == out["all_within_share"]
    assert shares[0] == 1.0
    assert all(shares[k] >= shares[k + 1] for k in range(2 * len(TRAITS)))
    # the mean count is the sum over k >= 1 of P(count >= k)
    assert sum(shares[k] for k in range(1, 2 * len(TRAITS) + 1)) == pytest.approx(
        out["expected_within"], abs=1e-9
    )
    # people are clipped into the bounds as a session clips them: a mean on its bound
    # (c = 0.002 N m, s = 0.0005) gives max(X, c), of mean c + s / sqrt(2 pi) and SD
    # s sqrt(1/2 - 1/(2 pi)); 8 people's mean is within 15 % when below 1.15 c, by the
    # normal approximation Phi((0.15 c - s / sqrt(2 pi)) / (s sqrt(1/2 - 1/(2 pi)) / sqrt(8)))
    c, s = 0.002, 0.0005
    on_bound = GroupProfile(
        **{**{t: (mid[t], sd[t]) for t in TRAITS}, "haptic_threshold_n_m": (c, s)}
    )
    clipped = oracle_within({"e": on_bound}, {"e": 8}, studies=20000)
    haptic = next(r for r in clipped["per_trait"] if r["trait"] == "haptic_threshold_n_m")
    z = (0.15 * c - s / np.sqrt(2 * np.pi)) / (s * np.sqrt(0.5 - 0.5 / np.pi) / np.sqrt(8))
    assert norm.cdf(z) == pytest.approx(0.835, abs=0.001)
    assert haptic["probability"] == pytest.approx(norm.cdf(z), abs=0.03)
