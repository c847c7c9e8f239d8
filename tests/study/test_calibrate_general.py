"""The calibration generalisation bench (`study bench calibrate --generalise`): its
recordings have the drawn strengths and ranges, its shares are counted as stated, and a
small run works end to end."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from study.bench.calibrate_general import GeneraliseConfig, plan, run_generalise_bench, summarise
from study.cli import main
from teleop_core.calibration.general import (
    FAMILIES,
    RANGES,
    STRENGTH_JND,
    general_recording,
    oracle_rmse,
)
from teleop_core.calibration.synthetic import JND_N, follower_recording


@pytest.mark.parametrize("family", ["stribeck", "backlash", "load_friction"])
def test_an_additive_effect_has_its_drawn_size_and_parameters_in_range(family: str) -> None:
    clean = general_recording((), seed=3, duration_s=30.0, rate_hz=100.0)
    drawn = general_recording((family,), seed=3, duration_s=30.0, rate_hz=100.0)
    (truth,) = drawn.truth
    added = drawn.data.y - clean.data.y
    assert np.sqrt(np.mean(added**2)) == pytest.approx(truth["rms_n"], rel=1e-9)
    assert STRENGTH_JND[0] * JND_N <= truth["rms_n"] <= STRENGTH_JND[1] * JND_N
    for name, (lo, hi, _) in RANGES[family].items():
        assert lo <= truth["params"][name] <= hi
    np.testing.assert_allclose(drawn.deviation, added)


def test_slip_saturates_the_true_force_and_takes_the_drawn_rms_away() -> None:
    true: dict = {}
    follower_recording(30.0, (), rate_hz=100.0, seed=4, noise_free=true)
    drawn = general_recording(("slip",), seed=4, duration_s=30.0, rate_hz=100.0)
    f = true["force"]
    level = np.max(np.abs(f + drawn.deviation))
    np.testing.assert_allclose(drawn.deviation, np.clip(f, -level, level) - f, atol=1e-12)
    removed = np.sqrt(np.mean(drawn.deviation**2))
    assert removed == pytest.approx(drawn.truth[0]["rms_n"], rel=1e-6)


def test_the_oracle_of_a_clean_recording_is_eq1_fitted_by_least_squares() -> None:
    drawn = general_recording((), seed=5, duration_s=30.0, rate_hz=100.0)
    # with no deviation the oracle is eq. 1 alone; here by numpy directly
    from teleop_core.calibration.models import FollowerBase

    X = FollowerBase().columns(drawn.data.signals)
    cut = round(0.75 * len(X))
    coef, *_ = np.linalg.lstsq(X[:cut], drawn.data.y[:cut], rcond=None)
    expected = np.sqrt(np.mean((drawn.data.y[cut:] - X[cut:] @ coef) ** 2))
    assert oracle_rmse(drawn) == pytest.approx(expected, rel=1e-6)


def test_the_plan_has_every_family_mixtures_and_clean_in_round_robin() -> None:
    todo = plan(GeneraliseConfig(per_family=2, mixtures_of_two=3, mixtures_of_three=1, clean=4))
    groups = [g for g, _, _ in todo]
    for f in FAMILIES:
        assert groups.count(f) == 2
    assert groups.count("mixture of 2") == 3
    assert groups.count("mixture of 3") == 1
    assert groups.count("clean") == 4
    assert len({seed for _, _, seed in todo}) == len(todo)
    for g, families, _ in todo:
        if g.startswith("mixture"):
            assert len(set(families)) == int(g[-1])
            assert not {"delay", "lag"} <= set(families)
    # the first round has one recording of every group
    assert set(groups[: len(FAMILIES) + 3]) == set(groups)


def test_a_group_filter_keeps_each_recordings_seed_from_the_whole_plan() -> None:
    whole = GeneraliseConfig(per_family=2, mixtures_of_two=2, mixtures_of_three=1, clean=2)
    only = plan(replace(whole, only=("backlash", "mixtures")))
    expected = [r for r in plan(whole) if r[0] == "backlash" or r[0].startswith("mixture")]
    assert only == expected
    assert len(only) == 2 + 2 + 1


def test_an_unknown_family_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["bench", "calibrate", "--generalise", "--family", "friction"]
    assert main([*argv, "--json", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "--family friction" in err[0]
    assert "backlash" in err[0]
    assert not (tmp_path / "r.json").exists()


def test_shares_are_counted_as_stated() -> None:
    runs = [
        {
            "group": "a",
            "families": ["a"],
            "within_2x_oracle": True,
            "right_first": True,
            "wrong_named": False,
            "ambiguous": [],
            "honest": True,
            "ratio_to_oracle": 1.0,
            "seconds": 1.0,
            "verdict": "white",
        },
        {
            "group": "a",
            "families": ["a"],
            "within_2x_oracle": False,
            "right_first": False,
            "wrong_named": True,
            "ambiguous": [["x", "y"]],
            "honest": False,
            "ratio_to_oracle": 3.0,
            "seconds": 2.0,
            "verdict": "white",
        },
        {
            "group": "clean",
            "families": [],
            "within_2x_oracle": True,
            "right_first": None,
            "wrong_named": False,
            "ambiguous": [],
            "honest": True,
            "ratio_to_oracle": 1.0,
            "seconds": 1.0,
            "verdict": "white",
        },
    ]
    s = summarise(runs)
    a = s["per_group"]["a"]
    assert (
        a["within_2x_oracle"],
        a["right_first"],
        a["wrong_named"],
        a["ambiguous"],
        a["honest"],
    ) == (0.5, 0.5, 0.5, 0.5, 0.5)
    assert s["per_group"]["clean"]["right_first"] is None
    assert s["overall"]["within_2x_oracle"] == 0.5
    assert s["overall"]["clean_untouched"] == 1.0
    # the run outside 2x ended white: not every unexplained recording is honest
    assert s["overall"]["not_explained_end_structure_remains"] is False


def test_a_small_run_end_to_end(tmp_path: Path) -> None:
    config = GeneraliseConfig(
        per_family=1,
        mixtures_of_two=0,
        mixtures_of_three=0,
        clean=1,
        duration_s=30.0,
        rate_hz=100.0,
        families=("stribeck", "slip"),
    )
    report = run_generalise_bench(config, tmp_path)
    assert "not measured" in report["data"]
    assert set(report["summary"]["per_group"]) == {"stribeck", "slip", "clean"}
    lines = (tmp_path / "calibrate_general_runs.jsonl").read_text().splitlines()
    assert len(lines) == 3
    runs = [json.loads(x) for x in lines]
    for r in runs:
        assert r["ratio_to_oracle"] == pytest.approx(r["rmse_after_n"] / r["oracle_rmse_n"])
    slip = next(r for r in runs if r["group"] == "slip")
    assert slip["right_first"] is None
    assert slip["wrong_named"] == bool(slip["named"])
    assert "| stribeck | 1 |" in (tmp_path / "calibrate_general.md").read_text()


def test_count_without_generalise_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["bench", "calibrate", "--json", str(tmp_path / "r.json"), "--count", "2"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "--count 2" in err[0]
    assert "--generalise" in err[0]
    assert not (tmp_path / "r.json").exists()


def test_a_gain_change_after_the_training_block_is_not_counted_against_the_2x_share() -> None:
    from teleop_core.calibration.general import general_recording, shown_in_training

    late = [{"family": "gain_change", "params": {"change_fraction": 0.8}}]
    early = [{"family": "gain_change", "params": {"change_fraction": 0.7}}]
    other = [{"family": "stribeck", "params": {"stribeck_speed_rad_s": 0.1}}]
    assert not shown_in_training(late)
    assert shown_in_training(early)
    assert shown_in_training(other)
    assert not shown_in_training(other + late)
    # a drawn recording: its step is where the truth says, on the held-out block
    drawn = general_recording(("gain_change",), 12, 30.0, 50.0)
    fraction = drawn.truth[0]["params"]["change_fraction"]
    assert fraction > 0.75
    assert not shown_in_training(drawn.truth)
    t = drawn.data.signals["t"]
    step = np.flatnonzero(np.abs(drawn.deviation) > 1e-9)[0]
    assert (t[step] - t[0]) / (t[-1] - t[0]) == pytest.approx(fraction, abs=0.01)
    base = {
        "group": "a",
        "families": ["a"],
        "right_first": True,
        "wrong_named": False,
        "ambiguous": [],
        "ratio_to_oracle": 1.0,
        "seconds": 1.0,
        "verdict": "structure_remains",
        "honest": True,
    }
    runs = [
        {**base, "within_2x_oracle": True, "shown_in_training": True},
        {**base, "within_2x_oracle": False, "shown_in_training": False},
    ]
    s = summarise(runs)
    assert s["per_group"]["a"]["within_2x_oracle"] == 1.0
    assert s["per_group"]["a"]["within_2x_oracle_all"] == 0.5
    assert s["per_group"]["a"]["not_shown_in_training"] == 1
    assert (s["overall"]["within_2x_oracle"], s["overall"]["within_2x_oracle_all"]) == (1.0, 0.5)


def test_the_extra_families_run_only_when_named_and_leave_the_plans_seeds() -> None:
    from teleop_core.calibration.general import EXTRA

    whole = GeneraliseConfig(per_family=2, mixtures_of_two=2, mixtures_of_three=1, clean=2)
    default = plan(whole)
    assert not {g for g, _, _ in default} & set(EXTRA)
    asked = plan(replace(whole, only=("gap_loss", "backlash")))
    assert [r for r in asked if r[0] == "backlash"] == [r for r in default if r[0] == "backlash"]
    extra = [r for r in asked if r[0] == "gap_loss"]
    assert [f for _, f, _ in extra] == [("gap_loss",)] * 2
    assert not {s for *_, s in extra} & {s for *_, s in default}


def test_a_gap_loss_loses_the_current_force_while_the_gap_is_open() -> None:
    from teleop_core.calibration.effects import play_operator

    true: dict = {}
    follower_recording(30.0, (), rate_hz=100.0, seed=6, noise_free=true)
    drawn = general_recording(("gap_loss",), seed=6, duration_s=30.0, rate_hz=100.0)
    (truth,) = drawn.truth
    h = play_operator(true["angle"], truth["params"]["half_gap_rad"])
    shape = (np.abs(h) - 1.0) * true["drive"]
    expected = truth["rms_n"] * shape / np.sqrt(np.mean(shape**2))
    np.testing.assert_allclose(drawn.deviation, expected, rtol=1e-9, atol=1e-12)
