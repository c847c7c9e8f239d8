"""The analysis screen: per-group VO vs HV comparisons, a chart, and the paper's figures.

The tables are `study.analysis.stats.analyze` on what is stored (the same numbers as
`study analyze`); the chart draws one measure's group means under VO and HV as bars in
the terminal; export writes the paper's figures (`study.analysis.paper.write_figures`,
as `study figures`) to a folder. Everything runs in a worker: the statistics import
pandas, pingouin and statsmodels on first use.

Those imports (scipy.stats, pandas, pingouin and the matplotlib it pulls in, statsmodels)
are most of a fresh app's first analysis; the analysis itself takes a fraction of a
second on a study's data. `warm_up` imports them in a worker of its own when the screen
is first shown or `WARM_UP_AFTER_S` after it is mounted (the app has shown its screens
by then; not while a trial runs), so the first `r` takes about as long as the next ones.

At 80 columns the table holds every number whole: a task column, measure names broken
at their underscores over lines, short headers ("p Holm"), the test as "t" (paired t)
or "W" (Wilcoxon signed-rank), and the effect size's kind above its value.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import DataTable, Input, Label, Select, Static

from study.analysis.apa import p_text
from study.tui.db_errors import SafeWorkers
from study.tui.services import StudyServices

__all__ = ["AnalysisPane", "bar_chart"]

VO_STYLE = "#E69F00"
HV_STYLE = "#0072B2"
"""Okabe-Ito orange and blue, the colours of VO and HV in the paper's figures."""


def bar_chart(comparisons: Any, measure: str, width: int = 40) -> Text:
    """Group means of `measure` under VO and HV as horizontal bars (one scale)."""
    rows = comparisons[comparisons["measure"] == measure]
    text = Text(no_wrap=True)
    if not len(rows):
        return text.append(f"no comparison of {measure} yet")
    top = float(max(rows["mean_vo"].max(), rows["mean_hv"].max()))
    scale = width / top if top > 0 else 0.0
    for _, r in rows.iterrows():
        for label, value, style in (("VO", r["mean_vo"], VO_STYLE), ("HV", r["mean_hv"], HV_STYLE)):
            name = r["group"] if label == "VO" else ""
            n = round(value * scale) if math.isfinite(value) else 0
            text.append(f"{name:<9}{label} ")
            text.append("█" * n, style)
            text.append(f" {value:.3g}\n")
    text.append(
        "p (Holm) per group: "
        + ", ".join(f"{r['group']} {r['p_holm']:.3f}" for _, r in rows.iterrows())
    )
    return text


class AnalysisPane(SafeWorkers, Vertical):
    """Run the analysis, read its tables and chart, export the figures."""

    DEFAULT_CSS = """
    AnalysisPane { height: 1fr; }
    AnalysisPane .row { height: 1; }
    AnalysisPane #measure { width: 28; }
    AnalysisPane #out-dir { width: 1fr; }
    AnalysisPane #comparisons { height: 1fr; min-height: 5; scrollbar-size-vertical: 1; }
    AnalysisPane #chart { height: auto; max-height: 9; }
    AnalysisPane #analysis-status { height: auto; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("r", "analyze", "Analyse"),
        Binding("n", "notes", "Notes"),
        # priority: the folder field (an Input) would take ctrl+e as "end of line"
        Binding("ctrl+e", "export", "Export figures", priority=True),
    ]

    @dataclass
    class Ready(Message):
        result: Any
        """`study.analysis.stats.Analysis`."""

    @dataclass
    class Exported(Message):
        paths: list[Path]

    def __init__(
        self,
        services: StudyServices,
        figures_dir: Path,
        formats: tuple[str, ...] = ("pdf", "svg", "png"),
        **kwargs: object,
    ) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.services = services
        self.figures_dir = figures_dir
        self.formats = formats
        self.result: Any = None
        self.exported: list[Path] = []
        self.warmed = threading.Event()
        """Set once `warm_up` has imported the statistics' libraries (or given up)."""
        self._warming = False

    def compose(self) -> ComposeResult:
        with Horizontal(classes="row"):
            yield Label("Chart ")
            yield Select[str]([], id="measure", compact=True, prompt="measure")
            yield Label(" Figures to ")
            # select_on_focus off: Tab into the field and a key no longer replaces the path
            yield Input(str(self.figures_dir), id="out-dir", compact=True, select_on_focus=False)
        table: DataTable[str] = DataTable(id="comparisons", zebra_stripes=True, cursor_type="row")
        table.add_columns(*COLUMNS)
        yield table
        yield Static("", id="chart")
        yield Static(
            "r: run the analysis; ctrl+e: export the paper's figures", id="analysis-status"
        )

    def on_mount(self) -> None:
        self.set_timer(WARM_UP_AFTER_S, self._warm_up_unasked)

    def _warm_up_unasked(self) -> None:
        """The timer's warm-up, unless a trial is running: a trial's loop is not shared
        with seconds of imports nobody asked for (F5 shown then still warms up)."""
        runs = [getattr(p, "run", None) for p in self.app.query("#run-pane")]
        if not any(run is not None for run in runs):
            self.warm_up()

    def on_show(self) -> None:
        self.warm_up()  # F5 shown first: no need to wait for the timer

    def warm_up(self) -> None:
        """Import what the first analysis needs, once, in a worker (the analysis started
        meanwhile waits on the same imports rather than repeating them)."""
        if not self._warming:
            self._warming = True
            self._warm_up()

    @work(thread=True, exclusive=True, group="warm-up", exit_on_error=False)
    def _warm_up(self) -> None:
        try:
            import pandas  # noqa: F401
            import pingouin  # noqa: F401  (and matplotlib.pyplot)
            import scipy.stats  # noqa: F401
            import statsmodels.formula.api
            import statsmodels.regression.mixed_linear_model  # noqa: F401

            import study.analysis.crossover
            import study.analysis.frames
            import study.analysis.stats
            import study.analysis.success  # noqa: F401
        except Exception:
            pass
        finally:
            self.warmed.set()

    def action_analyze(self) -> None:
        self._status("analysing...")
        self._analyze()

    @work(thread=True, exclusive=True, group="analysis", exit_on_error=False)
    def _analyze(self) -> None:
        try:
            result = self.services.analysis()
        except ValueError as exc:
            self.app.call_from_thread(self._status, f"nothing to analyse: {exc}")
            return
        self.post_message(self.Ready(result))

    @on(Ready)
    def _ready(self, event: Ready) -> None:
        self.result = event.result
        comparisons = event.result.comparisons
        table = self.query_one("#comparisons", DataTable)
        table.clear()
        for _, r in comparisons.iterrows():
            cells = (
                str(r["task"]),
                wrapped(str(r["measure"])),
                str(r["group"]),
                str(r["n"]),
                f"{r['mean_vo']:.3g}",
                f"{r['mean_hv']:.3g}",
                TEST_LABELS.get(str(r["test"]), str(r["test"])),
                p_text(r["p_holm"]),
                _effect(r["effect_size"], r["effect_size_kind"]),
            )
            table.add_row(*cells, height=max(c.count("\n") + 1 for c in cells))
        measures = list(dict.fromkeys(comparisons["measure"]))
        select = self.query_one("#measure", Select)
        select.set_options([(m, m) for m in measures])
        if measures:
            select.value = (
                "peak_proximal_force_n" if "peak_proximal_force_n" in measures else (measures[0])
            )
        notes = len(event.result.exclusions) + len(event.result.warnings)
        note = event.result.source.note
        self._status(
            f"{len(comparisons)} comparisons (test t: paired t, W: Wilcoxon signed-rank), "
            f"{notes} exclusions and notes (n: read them, with the mixed ANOVA)"
            + (f"; data: {note}" if note else "")
        )

    def action_notes(self) -> None:
        """The exclusions, the analysis's notes and the mixed ANOVA, over the screen."""
        # lazy: study.tui.confirm costs 4 ms at start-up
        from study.tui.confirm import TextScreen

        if self.result is None:
            self._status("r: run the analysis first; n then shows its notes")
            return
        self.app.push_screen(
            TextScreen("Exclusions, notes and the mixed ANOVA", details_text(self.result))
        )

    @on(Select.Changed, "#measure")
    def _measure(self, event: Select.Changed) -> None:
        event.stop()
        self._draw_chart()

    def on_resize(self) -> None:
        """The chart's bars are drawn to the width: redrawn when the terminal changes."""
        self._draw_chart()

    def _draw_chart(self) -> None:
        measure = self.query_one("#measure", Select).value
        if self.result is not None and measure is not Select.NULL:
            width = max(self.content_size.width - 24, 10)
            chart = bar_chart(self.result.comparisons, str(measure), width)
            self.query_one("#chart", Static).update(chart)

    def action_export(self) -> None:
        folder = Path(self.query_one("#out-dir", Input).value.strip() or self.figures_dir)
        self._status(f"drawing the figures into {folder}...")
        self._export(folder)

    @work(thread=True, exclusive=True, group="figures", exit_on_error=False)
    def _export(self, folder: Path) -> None:
        try:
            paths = self.services.export_figures(folder, self.formats)
        except (ValueError, OSError) as exc:
            self.app.call_from_thread(self._status, f"refused: {exc}")
            return
        self.post_message(self.Exported(paths))

    @on(Exported)
    def _exported(self, event: Exported) -> None:
        self.exported = event.paths
        folder = event.paths[0].parent if event.paths else self.figures_dir
        figures = [p for p in event.paths if p.suffix != ".md"]
        self._status(f"{len(figures)} figure files and their captions written to {folder}")

    def _status(self, text: str) -> None:
        self.query_one("#analysis-status", Static).update(text)

    def worker_failed(self, group: str, line: str) -> None:
        what = "the analysis" if group == "analysis" else "the figures"
        self._status(f"{what} failed: {line}")
        super().worker_failed(group, line)


EFFECT_LABELS = {"hedges_g_av": "g_av", "rank_biserial": "r_rb"}
"""Hedges' g_av (after a paired t) and the matched-pairs rank-biserial r (after a
Wilcoxon), named in each cell so that the two are never read as one scale."""


COLUMNS = ("task", "measure", "group", "n", "VO", "HV", "test", "p Holm", "effect")
"""The comparisons table's headers: short, so that at 80 columns every number is whole."""
TEST_LABELS = {"paired_t": "t", "wilcoxon": "W"}
"""The test column's names (the status line says them in full)."""
MEASURE_CHARS = 15
"""The widest line of the measure column; a longer name goes on over lines."""
WARM_UP_AFTER_S = 3.0
"""Seconds after the screen is mounted before the statistics' libraries are imported,
if F5 has not been shown by then (the app's start is over)."""


def wrapped(name: str, width: int = MEASURE_CHARS) -> str:
    """`name` over lines of at most `width` characters, broken before an underscore
    ("peak_proximal" / "_force_n"), a part longer than a line cut where it fills one."""
    lines: list[str] = []
    line = ""
    for k, part in enumerate(name.split("_")):
        piece = part if k == 0 else "_" + part
        if line and len(line) + len(piece) > width:
            lines.append(line)
            line = ""
        line += piece
        while len(line) > width:
            lines.append(line[:width])
            line = line[width:]
    lines.append(line)
    return "\n".join(x for x in lines if x)


def _effect(value: float, kind: str) -> str:
    """The effect size's kind above its value ("g_av" / "-0.52"), each whole."""
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{EFFECT_LABELS.get(kind, kind)}\n{value:+.2f}"


def details_text(result: Any) -> str:
    """What the table leaves out: exclusions, notes, and the mixed ANOVA (APA p)."""
    lines = ["Exclusions:"]
    lines += [f"  {e}" for e in result.exclusions] or ["  none"]
    lines += ["", "Notes:"]
    lines += [f"  {w}" for w in result.warnings] or ["  none"]
    anova = result.mixed_anova
    lines += ["", f"Mixed ANOVA (Type {result.ss_type} sums of squares), group x condition:"]
    if len(anova) == 0:
        lines.append("  not computed (see the notes)")
    for _, r in anova.iterrows():
        lines.append(
            f"  {r['task']}/{r['measure']} {r['source']}: F({r['df1']:.0f}, {r['df2']:.0f}) = "
            f"{r['F']:.2f}, p {_apa(r['p'])}, partial eta^2 = {r['np2']:.3f}"
        )
    return "\n".join(lines)


def _apa(p: float) -> str:
    text = p_text(p)
    return text if text.startswith("<") or text == "n/a" else f"= {text}"
