"""Simulated participants: drawn per group, and acting only on what a participant perceives."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import wilcoxon

from study.errors import StudyInputError
from study.protocol.tasks import get_task
from study.protocol.traits import GROUPS, draw_traits, simulated_participant
from study.protocol.trial_run import simulate_trial
from study.tasks.lcca.trial import wall_contacts
from teleop_core.loop.drivers import OperatorView
from teleop_core.phantom.lcca import LccaPhantom


def test_traits_are_reproducible_per_seed_and_differ_by_group() -> None:
    assert simulated_participant("novice", 4) == simulated_participant("novice", 4)
    rng = np.random.default_rng(0)
    draws = {g: [draw_traits(g, rng) for _ in range(300)] for g in GROUPS}

    def mean(g: str, field: str) -> float:
        return float(np.mean([getattr(t, field) for t in draws[g]]))

    # experts faster, steadier and quicker to react than engineering outsiders
    assert mean("expert", "preferred_speed_m_s") > mean("outsider", "preferred_speed_m_s")
    assert mean("expert", "steering_error_rad") < mean("outsider", "steering_error_rad")
    assert mean("expert", "reaction_s") < mean("outsider", "reaction_s")


def test_an_unknown_group_is_refused() -> None:
    with pytest.raises(
        StudyInputError, match="no simulated participant profile for group 'surgeon'"
    ):
        draw_traits("surgeon", np.random.default_rng(0))


def test_what_a_participant_sees_carries_no_condition_and_no_force() -> None:
    names = {f.name for f in dataclasses.fields(OperatorView)}
    assert not any("force" in n or "condition" in n or "haptic" in n for n in names)


def test_wall_contacts_count_rising_crossings() -> None:
    assert wall_contacts(np.array([0.0, 0.3, 0.3, 0.1, 0.5, 0.0])) == 2
    assert wall_contacts(np.array([0.5, 0.1])) == 1


LCCA = get_task("lcca")


@pytest.fixture(scope="module")
def phantom() -> LccaPhantom:
    return LccaPhantom()


def test_hv_at_zero_gain_is_vo_draw_for_draw(phantom: LccaPhantom) -> None:
    traits = simulated_participant("outsider", 3)
    vo = simulate_trial(LCCA, traits, "VO", 3, 60, context=phantom)
    hv0 = simulate_trial(LCCA, traits, "HV", 3, 60, haptic_gain_n_m_per_n=0.0, context=phantom)
    assert vo.frame.equals(hv0.frame)


def test_hv_at_zero_gain_is_statistically_indistinguishable_from_vo(
    phantom: LccaPhantom,
) -> None:
    peaks = {"VO": [], "HV": []}
    for i in range(10):
        traits = simulated_participant("novice", 100 + i)
        # separate runs: each condition with its own noise, as two real trials would be
        peaks["VO"].append(
            simulate_trial(LCCA, traits, "VO", 10 + i, 90, context=phantom).summary[
                "peak_proximal_force_n"
            ]
        )
        peaks["HV"].append(
            simulate_trial(
                LCCA, traits, "HV", 50 + i, 90, haptic_gain_n_m_per_n=0.0, context=phantom
            ).summary["peak_proximal_force_n"]
        )
    assert wilcoxon(peaks["VO"], peaks["HV"]).pvalue > 0.05


def test_felt_torque_lowers_peak_forces(phantom: LccaPhantom) -> None:
    """Outsiders catch the ostium often; in HV they feel it before the wire buckles.
    Sixteen people: with thresholds centred on the JND and trial-to-trial variability,
    fewer than half of the outsiders' HV trials feel an obstacle."""
    vo, hv = [], []
    for i in range(16):
        traits = simulated_participant("outsider", 200 + i)
        vo.append(simulate_trial(LCCA, traits, "VO", i, 120, context=phantom).summary)
        hv.append(simulate_trial(LCCA, traits, "HV", i, 120, context=phantom).summary)
    assert np.mean([s["peak_distal_force_n"] for s in hv]) < np.mean(
        [s["peak_distal_force_n"] for s in vo]
    )
    assert sum(s["obstacles_felt"] for s in hv) > 0
    assert sum(s["obstacles_felt"] for s in vo) == 0  # nothing to feel without haptics


def test_a_group_of_the_designs_own_is_noted_at_init_and_named_by_a_simulated_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from study.cli import main
    from study.protocol.design import TEMPLATE
    from tests.study.conftest import one_error_line

    design = tmp_path / "d.toml"
    design.write_text(TEMPLATE.replace("outsider = 20", '"a|b<i>" = 20', 1))
    db = str(tmp_path / "s.db")
    assert main(["init", "--design", str(design), "--db", db]) == 0
    out = capsys.readouterr().out
    assert "note: no simulated participant profile for group(s) a|b<i>" in out
    assert main(["participant", "add", "--group", "a|b<i>", "--db", db]) == 0
    capsys.readouterr()
    before = _dump(db)
    line = one_error_line(capsys, ["run", "--participant", "P001", "--db", db])
    assert "no simulated participant profile for group 'a|b<i>'" in line
    assert "expected one of outsider, novice, expert" in line
    assert _dump(db) == before


def _dump(db: str) -> list[str]:
    import sqlite3
    from contextlib import closing

    with closing(sqlite3.connect(db)) as conn:
        return list(conn.iterdump())
