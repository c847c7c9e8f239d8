"""`study participants fit --task notes`: the NOTES task fitted through the same
engine as the LCCA, recovery of a known trait, and the fitted model taken by
`study simulate`. Small data, as in `test_participant_fit.py`: 6 people per group, an
emulator of 120 settings (with 40, checked on held-out settings, the preferred speed was
barely identifiable and one group's estimate 24 % off)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from study.analysis.participant_fit.fit import (
    FitSettings,
    build_emulator,
    fit_trials,
    simulate_people,
)
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.traits import PROFILES

SETTINGS = FitSettings(design=120, repeats=1, check=4, bootstrap=10, jobs=1, seed=5, max_s=60.0)
pytestmark = pytest.mark.timeout(900)
TRUE_SPEED_M_S = {"outsider": 0.008, "novice": 0.018, "expert": 0.024}
"""Known group means of the preferred speed, set apart from the profiles' (0.012 / 0.014
/ 0.017) by more than the tolerance, so that recovering them tests the fit, not the
priors."""
TOLERANCE = 0.20
"""As in the LCCA test: the fit's own 95 % interval with 6 people and 2 trials per
condition is about +/- 15 %."""


def test_the_notes_groups_preferred_speeds_are_recovered() -> None:
    truth = {
        g: [dataclasses.replace(p, preferred_speed_m_s=(TRUE_SPEED_M_S[g], 0.0015))]
        for g, p in PROFILES.items()
    }
    data = dataclasses.replace(SETTINGS, seed=23)
    trials = simulate_people("notes", truth, 6, 2, data, lambda *_: None)
    model, table = fit_trials(
        trials, "notes", SETTINGS, build_emulator("notes", SETTINGS), "test data"
    )
    assert model["task"] == "notes"
    assert model["data_source"] == "simulated"
    assert model["moments"] == [
        f"{c}:{m}"
        for c in ("VO", "HV")
        for m in ("completion_time_s", "peak_force_demanded_n", "peak_tip_force_n")
    ]
    assert "preferred_speed_m_s" in model["identifiable"]
    for group, true in TRUE_SPEED_M_S.items():
        got = model["groups"][group]["preferred_speed_m_s"]["mean"]
        assert abs(got - true) <= TOLERANCE * true, (group, got, true)
        prior = PROFILES[group].preferred_speed_m_s[0]
        assert abs(prior - true) > TOLERANCE * true  # the prior alone would fail
    # the summaries compare the NOTES measures, observed against simulated from the fit
    assert set(table["measure"]) == {
        "completion_time_s",
        "peak_force_demanded_n",
        "peak_tip_force_n",
    }
    assert set(table["source"]) == {"observed", "simulated", "model"}


def test_a_notes_study_is_fitted_from_the_command_and_the_model_drives_simulate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    design = TEMPLATE.replace('tasks = ["lcca"]', 'tasks = ["notes"]')
    for group in ("outsider = 20", "novice = 8", "expert = 8"):
        design = design.replace(group, group.split(" = ")[0] + " = 4")
    design = design.replace("trials_per_condition = 3", "trials_per_condition = 1")
    (tmp_path / "d.toml").write_text(design)
    db = str(tmp_path / "notes.db")
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    for group in ("outsider", "novice", "expert"):
        assert main(["participant", "add", "--group", group, "--count", "4", "--db", db]) == 0
    assert main(["run", "--all", "--jobs", "1", "--db", db]) == 0
    out = tmp_path / "model.json"
    argv = [
        "participants",
        "fit",
        "--db",
        db,
        "--task",
        "notes",
        "--out",
        str(out),
        "--design",
        "16",
        "--repeats",
        "1",
        "--check",
        "4",
        "--bootstrap",
        "20",
        "--jobs",
        "1",
    ]
    capsys.readouterr()
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "what the participants lack" in printed
    # the loop on the people says what it added (or that it added nothing) in one line
    assert sum(line.startswith("participant effects: ") for line in printed.splitlines()) == 1
    model = json.loads(out.read_text())
    assert model["verdict"] in ("white", "structure_remains")
    assert set(model["prediction_error"]) >= {"before", "after", "definition"}
    assert isinstance(model["participant_effects"], list)
    assert model["task"] == "notes"
    assert model["fitted_from"]["participants"] == 12
    assert model["data_source"] == "simulated"  # run --all's people: simulated, and said so
    assert out.with_suffix(".png").stat().st_size > 10_000
    csv = tmp_path / "t.csv"
    argv = [
        "simulate",
        "--task",
        "notes",
        "--group",
        "expert",
        "--condition",
        "VO",
        "--seed",
        "2",
        "--max-seconds",
        "60",
        "--out",
        str(csv),
        "--participants",
        str(out),
    ]
    assert main(argv) == 0
    summary = json.loads(csv.with_suffix(".json").read_text())
    assert summary["participant_model"]["path"] == str(out)
    assert "simulated participant drawn from the" in capsys.readouterr().out
