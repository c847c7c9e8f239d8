"""F5 at 80 x 24: a task column, every column whole (effect sizes such as "g_av -0.52"
not cut), and the statistics' libraries imported before the first `r`."""

from __future__ import annotations

import sys

from textual.widgets import DataTable

from tests.study.tui.conftest import analysed, store_trials, wait_for


async def test_the_table_holds_the_task_and_whole_numbers(make_test_app, study_engine) -> None:
    store_trials(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await analysed(pilot)
        await pilot.pause()
        table = pane.query_one("#comparisons", DataTable)
        labels = [str(c.label) for c in table.columns.values()]
        assert labels[0] == "task"
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        assert rows
        assert {r[0] for r in rows} == {"lcca"}
        # every column within the table: no horizontal scroll, no cell cropped
        assert table.virtual_size.width <= table.scrollable_content_region.width
        assert table.max_scroll_x == 0
        for column in table.columns.values():
            widest = max(
                len(line)
                for r in rows
                for line in str(r[list(table.columns).index(column.key)]).split("\n")
            )
            assert column.get_render_width(table) - 2 * table.cell_padding >= widest
        effects = [r[8] for r in rows if r[8] != "n/a"]
        assert effects
        assert all(e.split()[0] in ("g_av", "r_rb") for e in effects)
        assert all(len(e.split()[1]) == 5 for e in effects)  # "-0.52", "+1.00"
        # the peak force by hand (conftest.PEAKS): the novices' VO mean (1.0+1.2+1.4)/3
        peak = next(r for r in rows if r[1].startswith("peak_proximal") and r[2] == "novice")
        assert peak[4] == "1.2"
        assert peak[1] == "peak_proximal\n_force"


async def test_the_libraries_are_imported_before_the_first_analysis(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda: app.ready)
        pane = app.query_one("#analysis-pane")
        await wait_for(pilot, pane.warmed.is_set, 60)
        assert {"pingouin", "statsmodels.formula.api", "study.analysis.stats"} <= set(sys.modules)
