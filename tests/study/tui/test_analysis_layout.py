"""F5 at 80 x 24: a task column, every number whole (no column past the table's width),
and the statistics' libraries imported before the first `r`, after the app has shown."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time

from textual.widgets import DataTable

from study.tui.analysis_pane import wrapped
from tests.study.tui.conftest import analysed, run_screen, store_trials, wait_for


def test_measure_names_break_at_underscores_within_the_width() -> None:
    assert wrapped("peak_proximal_force_n") == "peak_proximal\n_force_n"
    assert wrapped("push_over_capacity_fraction") == "push_over\n_capacity\n_fraction"
    assert wrapped("tlx_frustration") == "tlx_frustration"  # 15: fits
    assert wrapped("success") == "success"
    assert wrapped("a" * 20, 8) == "aaaaaaaa\naaaaaaaa\naaaa"  # no underscore: cut


async def test_the_table_holds_the_task_and_every_number_whole(make_test_app, study_engine) -> None:
    store_trials(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await analysed(pilot)
        await pilot.pause()
        table = pane.query_one("#comparisons", DataTable)
        labels = [str(c.label) for c in table.columns.values()]
        assert labels == ["task", "measure", "group", "n", "VO", "HV", "test", "p Holm", "effect"]
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        assert {r[0] for r in rows} == {"lcca"}
        # no column beyond the table's width: nothing scrolled out of view at 80 columns
        assert table.max_scroll_x == 0
        assert table.virtual_size.width <= table.scrollable_content_region.width
        # the peak force by hand (conftest.PEAKS): novices VO (1.0 + 1.2 + 1.4) / 3, HV 0.6
        peak = next(r for r in rows if r[1] == "peak_proximal\n_force_n" and r[2] == "novice")
        assert peak[3:6] == ["3", "1.2", "0.6"]
        effects = [r[8] for r in rows if r[8] != "n/a"]
        assert effects
        for effect in effects:  # the kind above the value, both whole: "g_av" / "-0.52"
            kind, value = effect.split("\n")
            assert kind in ("g_av", "r_rb")
            assert len(value) == 5
            float(value)
        assert {r[6] for r in rows} <= {"t", "W"}


def test_the_statistics_are_imported_before_the_first_analysis(tmp_path) -> None:
    """In a fresh interpreter (the test process has them imported already): nothing of
    the statistics at the first paint, all of them later with no `r` pressed."""
    script = textwrap.dedent(
        f"""
        import asyncio, sys
        from db.migrate import open_database
        from study.protocol.design import parse_design
        from study.protocol.roster import create_study
        from study.tui import StudyServices, TuiSettings, make_app
        from tests.study.tui.conftest import DESIGN

        STATS = ("pingouin", "scipy.stats", "statsmodels.formula.api", "study.analysis.stats")
        engine = open_database({str(tmp_path / "s.db")!r}, create=True)
        create_study(engine, parse_design(DESIGN), DESIGN)

        async def main():
            app = make_app(StudyServices(engine, lambda: None), TuiSettings(
                prepare_simulation=False, figures_dir={str(tmp_path)!r}))
            async with app.run_test(size=(80, 24)) as pilot:
                while app.overview_shown_s is None:
                    await pilot.pause(0.01)
                print("at first paint", [m for m in STATS if m in sys.modules])
                while not app.ready:
                    await pilot.pause(0.05)
                pane = app.query_one("#analysis-pane")
                while not pane.warmed.is_set():
                    await pilot.pause(0.1)
                print("warmed", [m for m in STATS if m in sys.modules], pane.result)

        asyncio.run(main())
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True
    ).stdout.splitlines()
    assert out[0] == "at first paint []"
    assert out[1] == (
        "warmed ['pingouin', 'scipy.stats', 'statsmodels.formula.api', 'study.analysis.stats'] None"
    )


async def test_no_unasked_warm_up_while_a_trial_runs(make_test_app, monkeypatch) -> None:
    """The timer's warm-up waits for F5 while a trial runs (its loop is not shared)."""
    import study.tui.analysis_pane as analysis_pane
    from study.protocol.default_estimator import load_estimator
    from study.tui.confirm import Confirm

    monkeypatch.setattr(analysis_pane, "WARM_UP_AFTER_S", 6.0)  # time to start a trial
    app = make_test_app(load_estimator=load_estimator, simulated_pace=1.0)
    async with app.run_test(size=(80, 24)) as pilot:
        run_pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: run_pane.run is not None, 5)
        pane = app.query_one("#analysis-pane")
        await wait_for(pilot, lambda: app.started_at + 7.0 < time.monotonic(), 10)
        assert run_pane.run is not None  # still running (a trial lasts tens of seconds)
        assert not pane._warming
        await pilot.press("f5")  # shown: warmed up all the same
        await pilot.pause()
        assert pane._warming
