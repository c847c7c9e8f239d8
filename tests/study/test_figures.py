"""The paper figures: the figure check on every figure at both widths, one Fig. 12 per
task with that task's marks, the within-subject TLX interval by hand, Fig. 9's shared
axis and drawing order, the power curve's labels.

The study is built in a second (no simulation): two tasks imported from CSV, a few
trials given samples, every trial marked simulated so the data-source note is drawn
(and checked) on every figure.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import matplotlib.pyplot as plt
import matplotlib.text
import numpy as np
import pandas as pd
import pytest
from sqlalchemy import Engine, select, update
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import Trial
from db.samples import SampleWriter
from study.analysis.figcheck import FigureCheckError, check_figure, require_legible, stars
from study.analysis.frames import participant_means, tlx_frame, trial_frame
from study.analysis.paper import draw_figures
from study.analysis.power import power_curve
from study.analysis.power_plot import plot_power_curve, power_caption
from study.analysis.stats import analyze
from study.analysis.tlx_figure import cousineau_morey
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TLX_COLUMNS, TLX_WEIGHT_COLUMNS
from study.protocol.export import trial_columns
from study.protocol.tasks import get_task

GROUPS = {"outsider": 6, "novice": 5, "expert": 5}


def _trial_rows(rng: np.random.Generator) -> list[list[object]]:
    rows, k = [], 0
    for group, n in GROUPS.items():
        for _ in range(n):
            k += 1
            code = f"P{k:03d}"
            for task, effect in (("lcca", -0.3), ("notes", 0.0)):
                for cond in ("VO", "HV"):
                    shift = effect if cond == "HV" else 0.0
                    for trial in (1, 2):
                        force = 0.8 + shift + rng.normal(0, 0.05)
                        if task == "lcca" and group == "expert" and cond == "VO" and k != 16:
                            force = 0.112  # tied values, as the demo's expert distal force
                        distal = 0.4 + shift / 2 + rng.normal(0, 0.03)
                        # each task's two analysed peaks in its own columns
                        pair, empty = [force, distal], ["", ""]
                        peaks = pair + empty if task == "lcca" else empty + pair
                        rows.append(
                            [code, group, task, cond, trial, 30 + rng.normal(0, 3), *peaks, "true"]
                        )
    return rows


WEIGHTS = [5, 4, 3, 2, 1, 0]
"""Tallies of the 15 pairwise choices (every questionnaire the same): a weighted score."""


def _tlx_rows(rng: np.random.Generator) -> list[list[object]]:
    rows = []
    for k in range(1, sum(GROUPS.values()) + 1):
        for task in ("lcca", "notes"):
            for cond in ("VO", "HV"):
                ratings = [int(v) for v in rng.integers(4, 16, 6) * 5]
                rows.append([f"P{k:03d}", task, cond, *ratings, *WEIGHTS])
    return rows


def _give_samples(engine: Engine) -> None:
    """Samples (a push and a pull-back) for every trial 1 of P001 in both tasks."""
    t = np.linspace(0, 10, 200)
    push = np.sin(t / 10 * 2 * np.pi)  # positive while inserting, negative withdrawing
    with Session(engine) as session:
        trials = session.scalars(select(Trial).where(Trial.trial_index == 0)).all()
        gains = {
            trial.id: 1.0 if trial.condition == "VO" else 0.4
            for trial in trials
            if trial.participant.code == "P001"
        }
        session.execute(update(Trial).values(driver="simulated"))
        session.commit()
    for trial_id, gain in gains.items():
        with SampleWriter(engine, trial_id, schema=get_task("lcca").sample_schema()) as writer:
            writer.extend(
                {
                    "t_s": t,
                    "reference_force_n": 2.5 * gain * push,
                    "proximal_force_n": 2.5 * gain * push + 0.05,
                    "distal_force_n": np.maximum(gain * push, 0.0),
                }
            )


@pytest.fixture(scope="module")
def study_db(tmp_path_factory: pytest.TempPathFactory) -> str:
    folder = tmp_path_factory.mktemp("two_tasks")
    db = str(folder / "s.db")
    design = TEMPLATE.replace('tasks = ["lcca"]', 'tasks = ["lcca", "notes"]')
    for group, n in GROUPS.items():
        design = design.replace(f"{group} = {20 if group == 'outsider' else 8} ", f"{group} = {n} ")
    (folder / "d.toml").write_text(design)
    assert main(["init", "--design", str(folder / "d.toml"), "--db", db]) == 0
    rng = np.random.default_rng(7)
    columns = trial_columns(["lcca", "notes"])
    pd.DataFrame(_trial_rows(rng), columns=columns).to_csv(folder / "t.csv", index=False)
    tlx_columns = [*TLX_COLUMNS, *TLX_WEIGHT_COLUMNS]
    pd.DataFrame(_tlx_rows(rng), columns=tlx_columns).to_csv(folder / "x.csv", index=False)
    argv = [
        "import",
        "--enrol-new",
        "--trials",
        str(folder / "t.csv"),
        "--tlx",
        str(folder / "x.csv"),
    ]
    assert main([*argv, "--db", db]) == 0
    engine = open_database(db, create=False)
    try:
        _give_samples(engine)
    finally:
        engine.dispose()
    return db


@pytest.fixture
def engine(study_db: str) -> Iterator[Engine]:
    eng = open_database(study_db, create=False)
    yield eng
    eng.dispose()
    plt.close("all")


@pytest.mark.parametrize("width", ["single", "double"])
def test_every_figure_passes_the_check_at_both_widths(engine: Engine, width: str) -> None:
    drawn = draw_figures(engine, width)
    names = sorted(d.name for d in drawn)
    assert names == sorted(
        f"{f}_{t}"
        for t in ("lcca", "notes")
        for f in ("fig12_groups", "fig9_forces", "tlx_profile")
    )
    for d in drawn:
        assert d.problems() == [], d.name
        texts = [t.get_text() for t in d.figure.findobj(plt.Text)]
        assert any("Simulated participants" in t for t in texts), d.name
        assert d.figure.get_figwidth() == {"single": 3.5, "double": 7.16}[width]
        if width == "single" and not d.name.startswith("fig9"):  # Fig. 12, TLX profile
            assert d.figure.get_figheight() <= 4.0, d.name
        # the caption is beside the figure (captions.md), not in it: no legend title
        assert d.caption
        assert all(not leg.get_title().get_text() for leg in d.figure.legends), d.name
        # group and subscale labels upright at both widths
        labels = [t for ax in d.figure.axes for t in ax.get_xticklabels() if t.get_text()]
        assert labels
        assert {t.get_rotation() for t in labels} == {0.0}, d.name
        if d.name.startswith("tlx_profile"):  # abbreviated, spelled out in the caption
            assert "OP own performance" in d.caption


def test_each_task_gets_its_own_fig12_with_its_own_marks(engine: Engine) -> None:
    trials, tlx = trial_frame(engine), tlx_frame(engine)
    reported = analyze(trials, participant_means(trials, tlx)).comparisons
    drawn = {d.name: d for d in draw_figures(engine, "double")}
    seen = {}
    # each task's own force measure (the LCCA's proximal, the NOTES's demanded force)
    force = {"lcca": "peak_proximal_force_n", "notes": "peak_force_demanded_n"}
    tip = {"lcca": "peak_distal_force_n", "notes": "peak_tip_force_n"}
    for task in ("lcca", "notes"):
        d = drawn[f"fig12_groups_{task}"]
        rows = reported[
            (reported["task"] == task)
            & reported["measure"].isin(
                ["completion_time_s", force[task], tip[task], "tlx_weighted"]
            )
        ]
        expected = {f"{r.measure}/{r.group}": r.p_holm for r in rows.itertuples()}
        assert d.expected_marks == pytest.approx(expected)  # the p values analyze reports
        assert check_figure(d.figure, expected) == []
        marks = {
            t.get_gid(): t.get_text()
            for t in d.figure.findobj(plt.Text)
            if (t.get_gid() or "").startswith("mark:")
        }
        seen[task] = marks[f"mark:{force[task]}/novice"]
    # HV lowers the lcca force (-0.3 N) and not the notes force: the marks differ by task
    assert seen["lcca"] in {"*", "**", "***"}
    assert seen["notes"] == "n.s."
    # the tied expert VO forces give a Wilcoxon, named under its group
    ticks = [
        t.get_text() for ax in drawn["fig12_groups_lcca"].figure.axes for t in ax.get_xticklabels()
    ]
    assert "expert\nWilcoxon\n(exact)" in ticks
    assert any(t.endswith("\npaired t") for t in ticks)


def test_the_check_catches_small_text_overlaps_and_wrong_marks() -> None:
    fig, ax = plt.subplots(figsize=(3.5, 2.0), layout="constrained")
    ax.tick_params(labelsize=8)
    ax.set_xlabel("time (s)", fontsize=8)
    ax.set_ylabel("force (N)", fontsize=8)
    assert check_figure(fig) == []
    small = ax.text(0.1, 0.1, "tiny", fontsize=6)
    assert check_figure(fig) == ["text 'tiny' at 6 pt < 8 pt"]
    small.set_fontsize(8)
    ax.text(0.1, 0.12, "on top", fontsize=8)
    assert check_figure(fig) == ["texts 'tiny' and 'on top' overlap"]
    with pytest.raises(FigureCheckError, match="overlap"):
        require_legible(fig, "example")
    fig.clear()
    ax = fig.add_subplot()
    ax.tick_params(labelsize=8)
    ax.text(0.5, 0.5, "*", fontsize=8, gid="mark:m/novice")
    assert check_figure(fig, {"m/novice": 0.03}) == []
    assert check_figure(fig, {"m/novice": 0.2}) == [
        "mark of m/novice is '*'; the reported p gives 'n.s.'"
    ]
    # no test reported (None): no mark expected, and one drawn is a problem
    assert check_figure(fig, {"m/novice": 0.03, "m/expert": None}) == []
    assert check_figure(fig, {"m/novice": None}) == [
        "mark of m/novice ('*') drawn where no test was run"
    ]
    ax.text(1.5, 0.5, "outside", fontsize=8)
    assert check_figure(fig, {"m/novice": 0.03}) == ["text 'outside' reaches outside the figure"]
    plt.close(fig)
    assert [stars(p) for p in (0.0009, 0.009, 0.049, 0.05, None)] == [
        "***",
        "**",
        "*",
        "n.s.",
        "n/a",
    ]


def test_cousineau_morey_interval_by_hand() -> None:
    wide = pd.DataFrame({"VO": [50.0, 60.0, 70.0, 40.0], "HV": [40.0, 55.0, 50.0, 35.0]})
    cm = cousineau_morey(wide)
    # participant means 45, 57.5, 60, 37.5; grand mean 50
    # centred VO: 50 - 45 + 50 = 55, 52.5, 60, 52.5 (SD 3.5355); HV: 45, 47.5, 40, 47.5
    # half = t(.975, 3) * 3.5355 / 2 * sqrt(2 / 1) = 3.182446 * 1.767767 * 1.414214
    half = 3.182446305284263 * 3.5355339059327378 / 2 * math.sqrt(2)
    assert cm.loc["VO", "half"] == pytest.approx(half) == pytest.approx(7.9561, abs=1e-4)
    assert cm.loc["HV", "half"] == pytest.approx(half)  # two conditions: the same width
    assert cm.loc["VO", "mean"] == 55.0
    assert cm.loc["HV", "mean"] == 45.0
    # narrower than the between-subject interval of the raw VO ratings (SD 12.91)
    assert half < 3.182446 * 12.9099 / 2


def test_fig9_one_figure_shared_axis_reference_above_estimate(engine: Engine) -> None:
    fig_name = "fig9_forces_lcca"
    fig = next(d.figure for d in draw_figures(engine, "double", task="lcca") if d.name == fig_name)
    vo, hv = [ax for ax in fig.axes if ax.get_title()]
    assert vo.get_title().split(", ")[1] == "VO"
    assert hv.get_title().split(", ")[1] == "HV"
    assert vo.get_ylim() == hv.get_ylim()
    assert vo.get_xlim() == hv.get_xlim()  # one time axis: the trials' lengths compare
    assert vo.get_shared_x_axes().joined(vo, hv)
    lines = {line.get_label(): line for line in vo.get_lines()}
    assert lines["proximal, reference"].get_zorder() > lines["proximal, estimated"].get_zorder()
    caption = next(
        d.caption for d in draw_figures(engine, "double", task="lcca") if d.name == fig_name
    )
    assert "positive resists insertion" in caption
    assert "negative resists withdrawal" in caption


def test_fig9_draws_every_stored_sample_of_the_two_trials(engine: Engine) -> None:
    """The traces are the samples `_give_samples` wrote (read batch by batch now, issue
    26): t from 0 to 10 s, the reference 2.5 N x gain x sin, VO gain 1, HV gain 0.4."""
    fig = next(
        d.figure
        for d in draw_figures(engine, "double", task="lcca")
        if d.name == "fig9_forces_lcca"
    )
    t = np.linspace(0, 10, 200)
    push = np.sin(t / 10 * 2 * np.pi)
    for ax, gain in zip([ax for ax in fig.axes if ax.get_title()], (1.0, 0.4), strict=True):
        lines = {line.get_label(): line for line in ax.get_lines()}
        np.testing.assert_array_equal(lines["proximal, reference"].get_xdata(), t)
        np.testing.assert_allclose(
            lines["proximal, reference"].get_ydata(), 2.5 * gain * push, rtol=0, atol=1e-15
        )
        np.testing.assert_allclose(
            lines["distal (tip on wall)"].get_ydata(), np.maximum(gain * push, 0), atol=1e-15
        )


def test_power_curve_per_group_n_and_the_interaction_named(tmp_path: Path) -> None:
    sizes = {"outsider": 20, "novice": 8, "expert": 8}
    equal = power_curve(sizes, dict.fromkeys(sizes, 0.8), 0.5, 20, 0, scales=(0.5, 1.0))
    for width in ("single", "double"):
        fig = plot_power_curve(equal, width, n_sim=20)
        assert check_figure(fig) == []
        ax_groups, ax_inter = fig.axes
        lines = {
            line.get_label(): line
            for line in ax_groups.get_lines()
            if not line.get_label().startswith("_")
        }
        assert list(lines["novice"].get_xdata()) == [4, 8]  # the group's own n
        assert list(lines["outsider"].get_xdata()) == [10, 20]
        styles = {(line.get_marker(), line.get_linestyle()) for line in lines.values()}
        assert len(styles) == 3  # distinguishable without colour
        assert "type I error" in ax_inter.get_ylabel()
        plt.close(fig)
    unequal = power_curve(
        sizes, {"outsider": 0.2, "novice": 0.8, "expert": 1.2}, 0.5, 20, 0, scales=(1.0,)
    )
    effects = {"outsider": 0.2, "novice": 0.8, "expert": 1.2}
    fig = plot_power_curve(unequal, "single", n_sim=20)
    assert "power" in fig.axes[1].get_ylabel()
    assert "type I" not in fig.axes[1].get_ylabel()
    # no caption inside the figure: every text on it is a label, a tick or a legend entry
    texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text) if t.get_text()]
    assert not [t for t in texts if len(t) > 60], texts
    # the assumptions stated in the caption, APA's way
    caption = power_caption(effects, 0.5, 20, "completion time")
    for phrase in (
        "completion time",
        "outsider 0.2, novice 0.8, expert 1.2",
        "standard deviations of one condition",
        "correlation 0.5",
        "\N{GREEK SMALL LETTER ALPHA} = .05",
        "Holm",
        "20 simulated studies per size",
        "Monte-Carlo",
    ):
        assert phrase in caption, caption
    # each estimate's 95 % Monte-Carlo (Wilson) band, drawn around it: novice's power p of
    # 20 studies, by hand: (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    novice = unequal[0][1].groups["novice"]
    z, n = 1.959963984540054, 20
    centre = (novice + z**2 / (2 * n)) / (1 + z**2 / n)
    half = z * np.sqrt(novice * (1 - novice) / n + z**2 / (4 * n**2)) / (1 + z**2 / n)
    bands = [c for c in fig.axes[0].collections if len(c.get_paths())]
    ys = [sorted({round(float(y), 12) for y in b.get_paths()[0].vertices[:, 1]}) for b in bands]
    assert [round(centre - half, 12), round(centre + half, 12)] in ys
    plt.close(fig)


def test_study_figures_task_option(
    study_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "figs"
    argv = ["figures", "--db", study_db, "--out", str(out), "--format", "png"]
    assert main([*argv, "--task", "notes", "--width", "single"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "captions.md",
        "fig12_groups_notes.png",
        "fig9_forces_notes.png",
        "tlx_profile_notes.png",
    ]
    captions = (out / "captions.md").read_text()
    for name in ("fig12_groups_notes", "fig9_forces_notes", "tlx_profile_notes"):
        assert f"## {name}\n" in captions
    assert "Marks: Holm-corrected p of the test named under each group" in captions
    assert "W, Wilcoxon signed-rank test" in captions  # the single column's abbreviations
    assert "Simulated participants" in captions
    capsys.readouterr()
    assert main([*argv, "--tlx-score", "adjusted"]) == 2
    err = capsys.readouterr().err.strip()
    assert "adjusted" in err
    assert "weighted" in err
    capsys.readouterr()
    assert main([*argv, "--task", "knee"]) == 2
    assert "no data for task 'knee'; expected one of lcca, notes" in capsys.readouterr().err


DEMO_MEANS = Path(__file__).parent.parent / "data" / "demo_seed1_means.csv"
"""Participant means of `study demo --seed 1` (20/8/8; see test_analysis.py)."""


@pytest.mark.parametrize("width", ["single", "double"])
def test_fig12_of_the_full_demo_study_passes_the_check(width: str) -> None:
    from study.analysis.comparisons import compare_conditions
    from study.analysis.figures import fig12, fig12_caption, fig12_labels, label_source
    from study.analysis.paper import _marks

    long = pd.read_csv(DEMO_MEANS)  # the raw NASA-TLX only
    comparisons, _ = compare_conditions(long)
    note = "Simulated participants: all 288 trials simulated, none measured"
    labels = fig12_labels("lcca", "raw")
    fig = label_source(fig12(long, comparisons, width, labels), note)
    marks = _marks(long, comparisons, "lcca")
    assert len(marks) == 12
    assert check_figure(fig, marks) == []
    # the expert distal force: 4 of 8 zero differences, the exact conditional p -> n.s.;
    # R: d <- (the 8 expert pairs); coin::pvalue(wilcoxsign_test(d$HV ~ d$VO,
    #   distribution = "exact")) -> 0.375 (zero.method "Pratt" and "Wilcoxon" alike)
    assert marks["peak_distal_force_n/expert"] == pytest.approx(0.375, abs=1e-12)
    ax = fig.axes[2]
    expected = "expert\nW (ex.)" if width == "single" else "expert\nWilcoxon\n(exact)"
    assert expected in [t.get_text() for t in ax.get_xticklabels()]
    tlx_label = fig.axes[3].get_title() if width == "single" else fig.axes[3].get_ylabel()
    assert tlx_label.replace("\n", " ") == "raw NASA-TLX (0-100)"
    if width == "single":  # a column's upper part at most, the abbreviations spelled out
        assert fig.get_figwidth() == 3.5
        assert fig.get_figheight() <= 4.0
        key = fig12_caption(long, comparisons, width, labels)
        assert "W, Wilcoxon signed-rank test, ex. exact or as. asymptotic p" in key
        assert "NASA-TLX panel: the raw score" in key
    # five expert VO values of 0.112 N: jittered apart, not one dot
    expert_vo = ax.collections[4].get_offsets()  # scatter order: group x (VO, HV)
    tied = expert_vo[np.isclose(expert_vo[:, 1], 0.112, atol=5e-4)]
    assert len(tied) == 5
    assert len(np.unique(np.round(tied[:, 0], 3))) == 5
    again = fig12(long, comparisons, width, labels).axes[2].collections[4].get_offsets()
    assert np.array_equal(again, expert_vo)  # seeded: the same figure on every run
    plt.close("all")


def _not_testable_long() -> pd.DataFrame:
    """The demo's means with every expert completion-time difference zero."""
    long = pd.read_csv(DEMO_MEANS)
    cell = (long["measure"] == "completion_time_s") & (long["group"] == "expert")
    vo = long[cell & (long["condition"] == "VO")].set_index("participant")["value"]
    hv = cell & (long["condition"] == "HV")
    long.loc[hv, "value"] = long.loc[hv, "participant"].map(vo).to_numpy()
    return long


@pytest.mark.parametrize("width", ["single", "double"])
def test_an_untestable_group_gets_no_mark_and_the_caption_says_why(width: str) -> None:
    from study.analysis.comparisons import compare_conditions
    from study.analysis.figures import fig12, fig12_caption, fig12_labels
    from study.analysis.paper import _marks

    long = _not_testable_long()
    comparisons, _ = compare_conditions(long)
    row = comparisons[
        (comparisons["measure"] == "completion_time_s") & (comparisons["group"] == "expert")
    ].iloc[0]
    assert row["not_testable"] == "every difference is 0"
    labels = fig12_labels("lcca", "raw")
    fig = fig12(long, comparisons, width, labels)
    marks = _marks(long, comparisons, "lcca")
    assert marks["completion_time_s/expert"] is None
    assert check_figure(fig, marks) == []
    gids = {t.get_gid(): t.get_text() for t in fig.findobj(plt.Text) if t.get_gid()}
    assert "mark:completion_time_s/expert" not in gids  # no star, no n/a: nothing
    assert gids["mark:completion_time_s/novice"] == "n.s."
    star_texts = {"*", "**", "***", "n.s.", "n/a"}
    panel = fig.axes[0]  # completion time
    expert_x = 2 * 3.0 + 0.5
    near = [
        t
        for t in panel.texts
        if t.get_text() in star_texts and abs(t.xy[0] - expert_x) < 1  # type: ignore[attr-defined]
    ]
    assert near == []
    assert "expert\nno test" in [t.get_text() for t in panel.get_xticklabels()]
    caption = fig12_caption(long, comparisons, width, labels)
    assert "completion time (s), expert: not testable (every difference is 0)" in caption
    plt.close(fig)


def test_fig12_tlx_panel_is_the_weighted_score_by_default(engine: Engine) -> None:
    drawn = {d.name: d for d in draw_figures(engine, "double", task="lcca")}
    fig12_drawn = drawn["fig12_groups_lcca"]
    ylabels = [ax.get_ylabel().replace("\n", " ") for ax in fig12_drawn.figure.axes]
    assert "weighted NASA-TLX (0-100)" in ylabels
    assert not any("raw" in y for y in ylabels)
    assert any(k.startswith("tlx_weighted/") for k in fig12_drawn.expected_marks or {})
    assert "NASA-TLX panel: the weighted score" in fig12_drawn.caption
    raw = next(
        d
        for d in draw_figures(engine, "single", task="lcca", tlx_score="raw")
        if d.name == "fig12_groups_lcca"
    )
    titles = [ax.get_title() for ax in raw.figure.axes]
    assert "raw NASA-TLX (0-100)" in titles
    assert any(k.startswith("tlx_raw/") for k in raw.expected_marks or {})
    assert raw.problems() == []
    plt.close("all")


def test_notes_device_figures_pass_the_check_in_the_shared_style() -> None:
    """`study characterize notes` draws these in the same style (now 8 pt)."""
    from study.analysis.notes_figures import bode, ramp_hysteresis
    from teleop_core.notes.characterize import characterize_simulated
    from teleop_core.notes.params import DOFS, default_params

    results = [characterize_simulated(default_params(dof), 0.02, 0) for dof in DOFS]
    for fig in (bode(results), ramp_hysteresis(results)):
        assert check_figure(fig) == []
        plt.close(fig)


def test_three_formats_are_written_from_one_layout_the_checked_one(tmp_path: Path) -> None:
    """`save` lays a constrained figure out once for pdf, svg and png (not once per
    format), and the axes keep the positions the figure check's draw gave them."""
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    from study.analysis.figures import save

    fig, axes = plt.subplots(1, 2, figsize=(3.5, 2.0), layout="constrained")
    axes[0].set_ylabel("a long label\non two lines")
    fig.canvas.draw()  # what check_figure does: the layout it measures
    checked = [ax.get_position().bounds for ax in axes]
    calls: list[int] = []
    original = ConstrainedLayoutEngine.execute

    def counted(self: ConstrainedLayoutEngine, figure: plt.Figure) -> dict:
        calls.append(1)
        return original(self, figure)

    ConstrainedLayoutEngine.execute = counted  # type: ignore[method-assign]
    try:
        paths = save(fig, tmp_path, "f", ["pdf", "svg", "png"])
    finally:
        ConstrainedLayoutEngine.execute = original  # type: ignore[method-assign]
    assert [p.name for p in paths] == ["f.pdf", "f.svg", "f.png"]
    assert all(p.stat().st_size > 0 for p in paths)
    assert len(calls) == 1
    assert [ax.get_position().bounds for ax in axes] == pytest.approx(checked, abs=1e-9)


def test_fig9_of_tied_peaks_draws_the_first_participant_by_code(
    study_db: str, tmp_path: Path
) -> None:
    """Two VO trials with the same peak (the demo's simulated experts tie): Fig. 9 takes
    the first participant by code, not the trial stored first (which, in the demo,
    is whichever session worker committed first)."""
    from db.models.study import Participant
    from db.models.trial import TrialMeasure
    from study.analysis.paper import _trace_trials

    db = tmp_path / "tie.db"
    db.write_bytes(Path(study_db).read_bytes())
    engine = open_database(str(db), create=False)
    try:
        with Session(engine) as session:
            first = session.scalars(select(Participant).where(Participant.code == "P001")).one()
            first.code = "P999"  # stored first, now last by code
            session.commit()
        _give_samples_to(engine, "P002")
        with Session(engine) as session:
            lcca_vo = select(Trial.id).where(
                Trial.task == "lcca", Trial.condition == "VO", Trial.trial_index == 0
            )
            session.execute(
                update(TrialMeasure)
                .where(
                    TrialMeasure.name == "peak_distal_force_n",
                    TrialMeasure.trial_id.in_(lcca_vo),
                    TrialMeasure.trial_id.in_(
                        select(Trial.id)
                        .join(Participant)
                        .where(Participant.code.in_(["P999", "P002"]))
                    ),
                )
                .values(value=5.0)
            )
            session.commit()
        picked = _trace_trials(engine, "lcca")
    finally:
        engine.dispose()
    assert [title.split(",")[0] for _, title in picked] == ["P002", "P002"]


def _give_samples_to(engine: Engine, code: str) -> None:
    from db.models.study import Participant

    t = np.linspace(0, 1, 20)
    with Session(engine) as session:
        ids = session.scalars(
            select(Trial.id)
            .join(Participant)
            .where(Participant.code == code, Trial.task == "lcca", Trial.trial_index == 0)
        ).all()
    for trial_id in ids:
        with SampleWriter(engine, trial_id, schema=get_task("lcca").sample_schema()) as writer:
            writer.extend({"t_s": t, "reference_force_n": t, "distal_force_n": t})
