"""Probes: the registry, the simulated answers and their measurement models, the design's
[probes] table, `study probe run`, storage, export/import with the codebook, the device
and keyboard responders, and `study analyze --covariate` against R's lme4."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.probe import ProbeTrial as ProbeTrialRow
from study.analysis.covariate import covariate_model
from study.cli import main
from study.probes import get_probe, probe_names
from study.probes.base import ProbeResponse
from study.probes.measure import trait_estimates
from study.probes.runner import DeviceResponder, KeyboardResponder, SimulatedResponder, run_probe
from study.protocol.design import TEMPLATE, parse_design
from study.protocol.traits import PROFILES, TRAITS, ParticipantTraits, draw_traits
from teleop_core.loop.hardware import UnitState
from tests.study.conftest import one_error_line

DATA = __import__("pathlib").Path(__file__).parent.parent / "data"


def _person(**values: float) -> ParticipantTraits:
    base = {t: PROFILES["novice"].__getattribute__(t)[0] for t in TRAITS}
    return ParticipantTraits(group="novice", **{**base, **values})


def test_the_builtin_probes_tell_every_trait_the_task_tells_weakly() -> None:
    told = {get_probe(n).trait for n in probe_names()}
    assert {
        "steering_error_rad",
        "haptic_threshold_n_m",
        "visual_stall_s",
        "comfort_torque_n_m",
    } <= told
    assert told <= set(TRAITS)


@pytest.mark.parametrize(
    "trait, value, probe, trials, tolerance",
    [
        # each probe's estimate of a known person's trait within 3 of its own SEs
        ("reaction_s", 0.30, "reaction_time", 30, 3.0),
        ("haptic_threshold_n_m", 0.0050, "force_threshold", 80, 3.0),
        ("steering_error_rad", 0.40, "aiming", 40, 3.0),
        ("comfort_torque_n_m", 0.012, "comfort_torque", 12, 3.0),
        ("visual_stall_s", 0.90, "stall_detection", 30, 3.0),
    ],
)
def test_a_probe_recovers_a_known_trait_within_its_standard_error(
    trait: str, value: float, probe: str, trials: int, tolerance: float
) -> None:
    person = _person(**{trait: value})
    rng = np.random.default_rng(11)
    responder = SimulatedResponder(person, rng)
    runs = run_probe(probe, trials, responder, rng, {"gain_n_m_per_n": 0.02})
    if probe == "stall_detection":  # its model subtracts the measured reaction time
        runs += run_probe("reaction_time", 30, responder, rng)
    got = trait_estimates(runs)[trait]
    assert abs(got.value - value) <= tolerance * got.se, (got, value)
    assert got.se < 0.25 * value


def test_the_force_threshold_in_newtons_is_the_trait_over_the_gain() -> None:
    # the 75 % point of a person whose torque threshold is 0.00384 N m at 0.02 N m/N:
    # 0.192 N, the paper's JND; at half the gain the same person needs twice the force
    person = _person(haptic_threshold_n_m=0.00384)
    for gain in (0.02, 0.01):
        rng = np.random.default_rng(3)
        runs = run_probe(
            "force_threshold",
            80,
            SimulatedResponder(person, rng, 0.0),
            rng,
            {"gain_n_m_per_n": gain},
        )
        got = trait_estimates(runs)["haptic_threshold_n_m"]
        assert abs(got.value / gain - 0.00384 / gain) <= 3 * got.se / gain


def test_the_simulated_groups_thresholds_sit_near_the_papers_jnd() -> None:
    # [endovascular]: a JND of 0.192 N; at the paper's gain the 20/8/8 study's mean threshold
    rng = np.random.default_rng(0)
    people = [
        draw_traits(g, rng)
        for g, n in (("outsider", 20), ("novice", 8), ("expert", 8))
        for _ in range(n * 50)
    ]
    mean_n = np.mean([p.haptic_threshold_n_m for p in people]) / 0.02
    assert abs(mean_n - 0.192) < 0.01


def test_lapses_show_in_the_answers_and_do_not_move_the_estimates() -> None:
    person = _person(reaction_s=0.25)
    rng = np.random.default_rng(5)
    runs = run_probe("reaction_time", 400, SimulatedResponder(person, rng, lapse_rate=0.2), rng)
    times = np.array([t.response for t in runs])
    # a fifth answer at random over 0.1-1 s: far more spread than 15 % log-normal noise
    assert np.mean(np.abs(np.log(times / 0.25)) > 0.6) > 0.08
    got = trait_estimates(runs)["reaction_s"]
    assert abs(got.value - 0.25) < 0.02


def test_the_keyboard_and_a_device_stream_answer_through_the_same_probes() -> None:
    keys = iter(["x", " "])
    clock = iter([0.0, 0.2, 0.31])
    shown: list[str] = []
    slept: list[float] = []
    kb = KeyboardResponder(
        read_key=lambda: next(keys),
        show=shown.append,
        clock=lambda: next(clock),
        sleep=slept.append,
    )
    # the foreperiod (the stimulus, 2 s) passes, GO shows, the time counts from there
    answer = kb.respond(get_probe("reaction_time"), 2.0, {})
    assert slept == [2.0]
    assert shown[1] == "GO"
    assert answer == ProbeResponse(0.31)
    assert "'x' is not an answer" in shown[2]
    # the stall: dots at 10 Hz for the 1.5 s the tip moves, then none; Enter answers
    keys, clock, shown[:], slept[:] = iter([""]), iter([0.0, 0.8]), [], []
    assert kb.respond(get_probe("stall_detection"), 1.5, {}) == ProbeResponse(0.8)
    assert shown[1:] == ["."] * 15
    assert slept == [0.1] * 15
    # a fake dial unit: the joystick turns the tip at 0.5 of full rate for 0.4 s, then
    # the hand pushes the dial past the confirm angle
    state = {"t_ms": 0.0}

    def exchange(current_a: float) -> UnitState:
        # what `HardwareDriver.exchange` returns: the dial unit's parsed state line
        state["t_ms"] += 10.0
        t = state["t_ms"] / 1000.0
        line = f"S {state['t_ms']:g} {0.5 if t > 0.405 else 0.0} 0 0 {0.5 if t <= 0.405 else 0.0}"
        return UnitState.parse(line)

    device = DeviceResponder(exchange=exchange)
    aimed = device.respond(get_probe("aiming"), 0.0, {})
    # rotation = 0.5 * pi/2 rad/s over 0.39 s: the first state (10 ms) is the clock's
    # origin, the 39 states at 20-400 ms each add 10 ms of turning, the one at 410 ms
    # presses with the joystick at rest
    assert aimed.response == pytest.approx(0.5 * math.pi / 2 * 0.39, abs=1e-9)
    chosen = device.respond(get_probe("force_threshold"), 0.2, {"interval": 2.0})
    assert chosen == ProbeResponse(2.0, True)


DESIGN = """\
name = "probes"
seed = 5
trials_per_condition = 2
practice_trials = 0

[probes]
before_block = 2
force_threshold = 20
reaction_time = 10
stall_detection = 10
aiming = 10
comfort_torque = 5

[groups]
outsider = 2
novice = 2
expert = 2
"""


def test_the_templates_probes_parse_and_bad_ones_are_one_line() -> None:
    design = parse_design(TEMPLATE)
    assert set(design.probes) == set(probe_names())
    assert design.probes_before_block == 1
    assert parse_design(DESIGN).probes_before_block == 2
    for table, expected in (
        ("nope = 3", "probes.nope names no probe; expected before_block or one of"),
        ("aiming = 0", "probes.aiming = 0; expected a whole number of trials from 1 to 200"),
        ("before_block = 3", "probes.before_block = 3; expected a block number from 1 to 2"),
    ):
        with pytest.raises(ValueError, match=expected.replace(".", r"\.")):
            parse_design(f"[probes]\n{table}\n")


def test_probe_run_stores_export_import_and_covariate(tmp_path, capsys) -> None:
    from tests.study.conftest import init_study

    db = init_study(
        tmp_path, DESIGN, ("outsider", "outsider", "novice", "novice", "expert", "expert")
    )
    assert main(["probe", "run", "--participant", "P001", "--db", db]) == 0
    out = capsys.readouterr().out
    assert "P001: force_threshold 20 trials stored (simulated)" in out
    assert "P001: haptic_threshold_n_m" in out
    # a second run stores nothing more
    assert main(["probe", "run", "--participant", "P001", "--db", db]) == 0
    assert "already stored" in capsys.readouterr().out
    for code in ("P002", "P003", "P004", "P005", "P006"):
        assert main(["probe", "run", "--participant", code, "--db", db]) == 0
    engine = open_database(db, create=False)
    with Session(engine) as s:
        assert s.scalar(select(func.count()).select_from(ProbeTrialRow)) == 6 * 55
    engine.dispose()
    assert main(["run", "--all", "--db", db]) == 0
    assert main(["export", "--out", str(tmp_path / "ex"), "--db", db]) == 0
    exported = pd.read_csv(tmp_path / "ex" / "probe_trials.csv")
    assert len(exported) == 330
    assert set(exported["driver"]) == {"simulated"}
    book = pd.read_csv(tmp_path / "ex" / "codebook.csv").set_index("column")
    assert {"probe", "probe_trial", "stimulus", "response", "correct", "context"} <= set(book.index)
    # into a fresh database: the same estimates from the imported trials
    (tmp_path / "b").mkdir()
    db2 = init_study(tmp_path / "b", DESIGN)
    capsys.readouterr()
    ex = tmp_path / "ex"
    assert (
        main(
            [
                "import",
                "--enrol-new",
                "--trials",
                str(ex / "trials.csv"),
                "--probes",
                str(ex / "probe_trials.csv"),
                "--db",
                db2,
            ]
        )
        == 0
    )
    assert "and 330 probe trials" in capsys.readouterr().out
    from study.probes.measure import probe_table
    from study.probes.store import probe_frame

    engines = [open_database(d, create=False) for d in (db, db2)]
    tables = [probe_table(probe_frame(e)) for e in engines]
    for e in engines:
        e.dispose()
    pd.testing.assert_frame_equal(tables[0], tables[1])
    # importing it again changes nothing: one line, exit 2, the trials not doubled either
    line = one_error_line(
        capsys,
        [
            "import",
            "--enrol-new",
            "--trials",
            str(ex / "trials.csv"),
            "--probes",
            str(ex / "probe_trials.csv"),
            "--db",
            db2,
        ],
    )
    assert "already stored" in line
    # the covariate
    capsys.readouterr()
    assert (
        main(
            [
                "analyze",
                "--out",
                str(tmp_path / "an"),
                "--covariate",
                "force_threshold",
                "--db",
                db2,
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "probe trials by driver: imported 330" in out
    ancova = pd.read_csv(tmp_path / "an" / "ancova_haptic_threshold_n_m.csv")
    assert len(ancova), out
    assert set(ancova["measure"]) == {
        "completion_time_s",
        "peak_proximal_force_n",
        "peak_distal_force_n",
    }


def test_bad_probe_input_is_one_line(tmp_path, capsys) -> None:
    from tests.study.conftest import init_study

    db = init_study(tmp_path, DESIGN, ("outsider",))
    assert "probe 'nope'; expected one of" in one_error_line(
        capsys, ["probe", "run", "--participant", "P001", "--probe", "nope", "--db", db]
    )
    assert "unknown participant 'P404'" in one_error_line(
        capsys, ["probe", "run", "--participant", "P404", "--db", db]
    )
    argv = [
        "probe",
        "run",
        "--participant",
        "P001",
        "--driver",
        "hardware",
        "--port",
        str(tmp_path / "no-port"),
        "--db",
        db,
    ]
    line = one_error_line(capsys, argv)
    assert "no-port: cannot open serial port" in line
    assert "expected the serial port" in line
    bad_design = tmp_path / "bad.toml"
    bad_design.write_text(DESIGN.replace("aiming = 10", "aiming = 'ten'"))
    line = one_error_line(
        capsys, ["init", "--design", str(bad_design), "--db", str(tmp_path / "other.db")]
    )
    assert "probes.aiming = 'ten'; expected a whole number of trials from 1 to 200" in line
    assert not (tmp_path / "other.db").exists()
    assert "--covariate 'nope'; expected a probe or its trait" in one_error_line(
        capsys, ["analyze", "--out", str(tmp_path / "a"), "--covariate", "nope", "--db", db]
    )
    bad = tmp_path / "p.csv"
    bad.write_text(
        "participant,probe,probe_trial,stimulus,stimulus_unit,response,"
        "response_unit,correct,context,driver\n"
        "P001,aiming,1,0.1,rad,inf,rad,,{},keyboard\n"
    )
    trials = tmp_path / "t.csv"
    trials.write_text(
        "participant,group,task,condition,trial,completion_time_s,"
        "peak_proximal_force_n,peak_distal_force_n,success\n"
        "P001,outsider,lcca,VO,1,30,1.0,0.5,true\n"
    )
    line = one_error_line(
        capsys, ["import", "--enrol-new", "--trials", str(trials), "--probes", str(bad), "--db", db]
    )
    assert "p.csv row 2, column response: 'inf'; expected a plain decimal number" in line
    # nothing half-written: the trials file was not imported either
    engine = open_database(db, create=False)
    from db.models.trial import Trial

    with Session(engine) as s:
        imported = select(func.count()).select_from(Trial).where(Trial.driver == "imported")
        assert s.scalar(imported) == 0
    engine.dispose()


def test_the_covariate_model_is_lme4s() -> None:
    # R 4.x, lme4 1.1-31, on tests/data/covariate_lmm.csv (15 people, 3 groups, VO/HV x 3):
    #   d <- read.csv("covariate_lmm.csv")
    #   d$condition <- factor(d$condition, levels = c("VO", "HV")); d$group <- factor(d$group)
    #   d$cov <- d$threshold_n_m - mean(tapply(d$threshold_n_m, d$participant, mean))
    #   f <- lmer(value ~ condition * group + cov + condition:cov + (1 | participant),
    #             data = d, REML = TRUE)
    #   cbind(fixef(f), sqrt(diag(as.matrix(vcov(f)))))
    #   L <- c(0, 1, 0, 0, 0, 1/3, 1/3, 0)
    #   c(sum(L * fixef(f)), sqrt(drop(t(L) %*% as.matrix(vcov(f)) %*% L)))
    lme4 = {
        "Intercept": (19.1499175983, 1.0096794999),
        "C(condition, Treatment('VO'))[T.HV]": (-1.9386415414, 0.3285832609),
        "C(group)[T.novice]": (2.3904555942, 1.4272149788),
        "C(group)[T.outsider]": (6.3799516109, 1.4295458803),
        "cov": (1734.9181239357, 1150.1634324665),
        "C(condition, Treatment('VO'))[T.HV]:C(group)[T.novice]": (-0.4751015241, 0.4644631804),
        "C(condition, Treatment('VO'))[T.HV]:C(group)[T.outsider]": (-0.4394205184, 0.4652217332),
        "C(condition, Treatment('VO'))[T.HV]:cov": (1039.4929069151, 374.3014008421),
    }
    mean_effect = (-2.2434822222, 0.1896016963)
    d = pd.read_csv(DATA / "covariate_lmm.csv").assign(task="lcca")
    values = d.groupby("participant")["threshold_n_m"].first()
    d = d.rename(columns={"value": "completion_time_s"})
    lmm, ancova, notes = covariate_model(d, values, {"lcca": ("completion_time_s",)}, "thr")
    got = lmm.set_index("term")
    for term, (estimate, se) in lme4.items():
        assert got.loc[term, "estimate"] == pytest.approx(estimate, rel=1e-6, abs=1e-6)
        # statsmodels' REML variance components differ from lme4's in the 5th digit
        assert got.loc[term, "se"] == pytest.approx(se, rel=1e-3)
    row = ancova[ancova["effect"].str.startswith("HV - VO at the mean")].iloc[0]
    assert row["estimate"] == pytest.approx(mean_effect[0], rel=1e-6)
    assert row["se"] == pytest.approx(mean_effect[1], rel=1e-3)
    assert row["covariate_mean"] == pytest.approx(values.mean())
    assert notes == []


def test_the_session_flow_runs_the_probes_due_before_the_block(tmp_path) -> None:
    from study.tui.probe_step import due_probes, run_due_probes
    from tests.study.conftest import init_study

    # DESIGN runs its probes before block 2: nothing is due before the first block
    db = init_study(tmp_path, DESIGN, ("outsider",))
    engine = open_database(db, create=False)
    try:
        assert due_probes(engine, "P001") == []
        assert run_due_probes(engine, "P001", "simulated") is None
        assert main(["run", "--participant", "P001", "--db", db]) == 0
        # block 1 ran (both blocks here: `study run` runs every remaining trial)
        assert due_probes(engine, "P001") == list(parse_design(DESIGN).probes)
        line = run_due_probes(engine, "P001", "keyboard")
        assert line is not None
        assert "study probe run --participant P001 --driver keyboard" in line
        line = run_due_probes(engine, "P001", "simulated")
        assert line is not None
        assert "force_threshold 20" in line
        assert due_probes(engine, "P001") == []
    finally:
        engine.dispose()


def test_without_the_reaction_probe_the_stall_falls_back_with_a_wider_se() -> None:
    from study.probes.base import robust_location
    from study.probes.stall_detection import FALLBACK_REACTION_S

    person = _person(visual_stall_s=0.8, reaction_s=0.27)
    rng = np.random.default_rng(8)
    responder = SimulatedResponder(person, rng)
    stall = run_probe("stall_detection", 30, responder, rng)
    react = run_probe("reaction_time", 30, responder, rng)
    with_rt = trait_estimates(stall + react)["visual_stall_s"]
    alone = trait_estimates(stall)
    assert set(alone) == {"visual_stall_s"}
    # the median response less the profiles' middle reaction time, the SEs combined
    times = np.array([t.response for t in stall])
    median, se = robust_location(times[(times >= 0.1) & (times <= 3.0)])
    assert alone["visual_stall_s"].value == pytest.approx(median - FALLBACK_REACTION_S[0])
    assert alone["visual_stall_s"].se == pytest.approx(np.hypot(se, FALLBACK_REACTION_S[1]))
    assert alone["visual_stall_s"].se > with_rt.se
    assert abs(with_rt.value - 0.8) < 3 * with_rt.se


def test_a_built_in_probe_is_found_in_a_fresh_process() -> None:
    """A design naming a built-in probe is checked without importing the probes'
    numerics, and `get_probe` then loads them (a fresh process: nothing registered yet)."""
    import subprocess
    import sys

    code = (
        "import sys; from study.probes import get_probe, is_probe; "
        "assert is_probe('aiming') and 'numpy' not in sys.modules; "
        "print(get_probe('aiming').name)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "aiming"
