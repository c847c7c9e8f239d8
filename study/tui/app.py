"""The application: six screens as tabs, the roster loaded in a worker, a safe quit.

`make_app(services, settings)` builds the app from its dependencies (the database
engine, the estimator loader, the calibration loop), so `study tui` and the tests build
it the same way and nothing inside reads global configuration. The app owns only the
wiring between the screens: it loads the `Roster` (in a worker) at start, whenever a
screen reports a change (a participant enrolled, a trial ended, a questionnaire saved),
on every screen switch and once a second (`POLL_S`: what the command line or another
lab machine changed shows within two seconds), hands it to every screen when it has
changed, and opens the NASA-TLX form when a trial finishes a block.
Quitting in the middle of a trial stops it first, so it is marked interrupted and
every committed sample stays; closing the terminal (SIGHUP) or SIGTERM quits the same way.
"""

from __future__ import annotations

import asyncio
import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from textual import events, on, work
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.css.query import NoMatches
from textual.message import Message
from textual.widget import Widget
from textual.widgets import Footer, Input, Select, SelectionList, TabbedContent, TabPane

from study.tui.db_errors import SafeWorkers
from study.tui.overview import OverviewPane
from study.tui.palette import StudyCommands
from study.tui.services import Roster, StudyServices
from study.tui.tabs import TABS, TITLES

if TYPE_CHECKING:  # imported when first mounted, after the overview has shown
    from study.tui.participant_page import ParticipantPage
    from study.tui.participants import ParticipantsPane
    from study.tui.run_pane import RunPane
    from study.tui.tlx_pane import TlxPane

__all__ = ["TABS", "StudyApp", "TuiSettings", "make_app"]

SHORT_TITLES = ("Home", "People", "Run", "TLX", "Stats", "Calib")
"""The tab labels below `WIDE_COLUMNS` columns, so that all six stay on the bar."""
WIDE_COLUMNS = 80
POLL_S = 1.0
"""Seconds between two reads of the roster, for the changes made outside the app."""


@dataclass(frozen=True)
class TuiSettings:
    """How the app behaves (not what it works on: that is `StudyServices`)."""

    simulated_pace: float | None = 1.0
    """Times real time for a simulated participant at start (None: as fast as it goes)."""
    figures_dir: Path = Path("figures")
    """Where the analysis screen exports the paper's figures by default."""
    calibrations_dir: Path = Path("calibrations")
    """Where the calibration screen writes each result's report file."""
    exports_dir: Path = Path("exports")
    """Where the overview's `e` exports the data (a new folder per export)."""
    backups_dir: Path = Path("backups")
    """Where the overview's `b` writes the end-of-day copy of the database."""
    figure_formats: tuple[str, ...] = ("pdf", "svg", "png")
    """Formats of the exported figures (as `study figures --format`)."""
    theme: str = "textual-dark"
    driver: str = "simulated"
    """The run screen's driver at start (`simulated` or `keyboard`)."""
    preferences_file: Path | None = None
    """Where the run screen remembers its driver and pace (`study.tui.preferences`);
    None: nothing is remembered."""
    prepare_simulation: bool = True
    """Load the estimator and compile the loop when the run screen is first shown (a few
    seconds of one core, in a worker); off, the first trial pays it instead."""

    def __post_init__(self) -> None:
        if self.simulated_pace is not None and not self.simulated_pace > 0:
            raise ValueError(f"simulated pace {self.simulated_pace!r}; expected > 0 or None")
        if self.driver not in ("simulated", "keyboard"):
            raise ValueError(f"driver {self.driver!r}; expected simulated or keyboard")


class StudyApp(SafeWorkers, App[None]):
    """`study tui`."""

    TITLE = "haptic-study"
    CSS = """
    TabbedContent { height: 1fr; }
    TabPane { padding: 0 1; }
    /* focus that reads in both themes (the default was one grey step on the dark one) */
    Input:focus, Select:focus > SelectCurrent, DataTable:focus, Button:focus,
    PairChoice:focus { background-tint: $accent 35%; }
    /* notices stack up from the footer, so they never cover a screen's first lines (whose
       participant and block a NASA-TLX form opens on) */
    ToastRack { align: right bottom; }
    """
    COMMANDS = App.COMMANDS | {StudyCommands}
    """ctrl+p: Textual's commands and the app's own (`study.tui.palette`)."""
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("ctrl+q", "quit", "Quit", priority=True),
        Binding("ctrl+t", "toggle_theme", "Theme", show=False),  # in ? and ctrl+p
        *(Binding(f"f{k + 1}", f"tab('{t}')", TITLES[k], show=False) for k, t in enumerate(TABS)),
        *(
            Binding(str(k + 1), f"digit_tab('{t}')", TITLES[k], show=False)
            for k, t in enumerate(TABS)
        ),
        Binding("question_mark", "toggle_help", "Help"),
    ]

    @dataclass
    class RosterLoaded(Message):
        roster: Roster

    def __init__(self, services: StudyServices, settings: TuiSettings) -> None:
        super().__init__()
        self.services = services
        self.settings = settings
        self.roster: Roster | None = None
        self.started_at = time.monotonic()
        self.overview_shown_s: float | None = None
        """Seconds from the app's construction to the first overview with data."""
        self.ready = False
        """True once every screen is mounted (after the overview has shown)."""
        self._later_mounted = asyncio.Event()
        """Set when the screens mounted after the overview are in place (or gave up)."""

    def compose(self) -> ComposeResult:
        # only the overview at first: the other screens (some 300 widgets) are mounted
        # once it shows, so the first paint waits for neither their layout nor their CSS
        with TabbedContent(id="tabs"):
            for k, tab in enumerate(TABS):
                with TabPane(f"F{k + 1} {TITLES[k]}", id=tab):
                    if tab == "overview":
                        yield OverviewPane(id="overview-pane")
        yield Footer(compact=True)

    def on_resize(self, event: events.Resize) -> None:
        """Short tab labels on a narrow terminal: every tab stays on the bar; and no
        `^p palette` on the footer, whose 12 columns cut the screen's last keys (ctrl+p
        still opens it, and `?` lists it)."""
        wide = event.size.width >= WIDE_COLUMNS
        titles = TITLES if wide else SHORT_TITLES
        tabs = self.query_one("#tabs", TabbedContent)
        for k, tab in enumerate(TABS):
            tabs.get_tab(tab).label = f"F{k + 1} {titles[k]}"
        self.query_one(Footer).show_command_palette = wide

    def _later_panes(self) -> dict[str, Widget]:
        # imported here, not at the top: the run screen alone pulls in the teleoperation
        # core, and none of them is needed for the first paint (`study bench tui`)
        from study.tui.analysis_pane import AnalysisPane

        # here, not at the top: importing study.tui.calibration_pane imports this module
        from study.tui.calibration_pane import CalibrationPane

        # here, not at the top: importing study.tui.participants imports this module
        from study.tui.participants import ParticipantsPane

        # here, not at the top: importing study.tui.run_pane imports this module
        from study.tui.run_pane import RunPane

        # here, not at the top: importing study.tui.tlx_pane imports this module
        from study.tui.tlx_pane import TlxPane

        return {
            "participants": ParticipantsPane(self.services, id="participants-pane"),
            "run": RunPane(
                self.services,
                self.settings.simulated_pace,
                driver=self.settings.driver,
                preferences_file=self.settings.preferences_file,
                id="run-pane",
            ),
            "tlx": TlxPane(self.services, id="tlx-pane"),
            "analysis": AnalysisPane(
                self.services,
                self.settings.figures_dir,
                self.settings.figure_formats,
                id="analysis-pane",
            ),
            "calibration": CalibrationPane(
                self.services, self.settings.calibrations_dir, id="calibration-pane"
            ),
        }

    async def _mount_later_panes(self) -> None:
        try:
            for tab, pane in self._later_panes().items():
                await self.query_one(f"#{tab}", TabPane).mount(pane)
            self.ready = True
            if self.roster is not None:
                self._show(self.roster)
        except NoMatches:  # the app closed while the screens were being mounted
            self.ready = False
        finally:
            self._later_mounted.set()

    def on_mount(self) -> None:
        self.theme = self.settings.theme
        self.reload()
        self.set_interval(POLL_S, self._poll)
        # closing the terminal window (SIGHUP) or `kill` (SIGTERM) quits as ctrl+q does:
        # a running trial is stopped and marked interrupted, not left `running`
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGHUP, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self._signalled, sig)
            except (NotImplementedError, RuntimeError, ValueError):  # not the main thread
                pass

    def _signalled(self, sig: signal.Signals) -> None:
        if sig == signal.SIGHUP:
            self.run_worker(self._hang_up(), exclusive=True, group="hang-up")
        else:
            self.call_next(self._quit_now)  # `kill`: no question asked

    async def _hang_up(self) -> None:
        """The terminal is gone: stop the trial (marked interrupted, its samples kept),
        then leave at once. Textual's own exit would restore a terminal that no longer
        exists, and its writer thread blocks on it for good (seen in tmux)."""
        await self.stop_trial()
        os._exit(128 + signal.SIGHUP)

    # -- the roster -----------------------------------------------------------------------

    def reload(self) -> None:
        self._load_roster()

    @work(thread=True, exclusive=True, group="roster", exit_on_error=False)
    def _load_roster(self) -> None:
        self.post_message(self.RosterLoaded(self.services.roster()))

    def _poll(self) -> None:
        """Once a second: the roster read again, shown if something changed it."""
        if self.roster is None:
            return
        if any(w.group in ("roster", "poll") and not w.is_finished for w in self.workers):
            return  # a read is under way: its roster is as fresh
        self._poll_roster()

    @work(thread=True, exclusive=True, group="poll", exit_on_error=False)
    def _poll_roster(self) -> None:
        try:
            roster = self.services.roster()
        except Exception:  # quiet: the screens' own reads and writes say what is wrong
            return
        if roster != self.roster:  # unchanged, the screens keep what they show
            self.post_message(self.RosterLoaded(roster))

    def show_roster(self, roster: Roster) -> None:
        """A roster a screen has just read (to decide on fresh data), shown everywhere."""
        if roster != self.roster:
            self.roster = roster
            self._show(roster)

    @on(RosterLoaded)
    def _roster_loaded(self, event: RosterLoaded) -> None:
        self.roster = event.roster
        self._show(event.roster)
        if self.overview_shown_s is None:
            self.overview_shown_s = time.monotonic() - self.started_at
            self.call_after_refresh(self._mount_later_panes)
            self._tell_left_running()

    @work(thread=True, group="left-running", exit_on_error=False)
    def _tell_left_running(self) -> None:
        """At start: a trial that a session which has ended left running (the app
        killed, say) is named, as it counts now (interrupted, repeated next)."""
        for code, why in self.services.left_running():
            self.call_from_thread(
                self.notify,
                f"{code}: a trial was found running from a session that has ended ({why}); "
                "it counts as interrupted and is repeated at their next start",
                severity="warning",
                timeout=20,
            )

    def _pane(self, tab: str) -> Widget:
        return self.query_one(f"#{tab}-pane")

    def _show(self, roster: Roster) -> None:
        overviews = self.query(OverviewPane)
        if not overviews:  # a roster that arrives while the app closes: nothing to show
            return
        overviews.first().show(roster)
        if self.ready:
            for tab in ("participants", "run", "tlx"):
                self._pane(tab).show(roster)  # type: ignore[attr-defined]

    # the later screens' messages, by handler name (their classes load after start)

    def on_participants_pane_added(self, _event: ParticipantsPane.Added) -> None:
        self.reload()

    def on_participants_pane_note_kept(self, _event: ParticipantsPane.NoteKept) -> None:
        self.reload()

    def on_participants_pane_withdrawn(self, _event: ParticipantsPane.Withdrawn) -> None:
        self.reload()

    def on_tlx_pane_saved(self, _event: TlxPane.Saved) -> None:
        self.reload()

    def on_run_pane_trial_ended(self, event: RunPane.TrialEnded) -> None:
        self._after_trial(event.block)

    @work(thread=True, exclusive=True, group="roster", exit_on_error=False)
    def _after_trial(self, block: tuple[str, str, str]) -> None:
        roster = self.services.roster()
        self.post_message(self.RosterLoaded(roster))
        if block in roster.tlx_due():
            self.call_from_thread(self._open_tlx, *block)

    def _open_tlx(self, code: str, task: str, condition: str) -> None:
        self.action_tab("tlx")
        # the form's first line names the participant and block: no notice over it
        self._pane("tlx").open_block(code, task, condition)  # type: ignore[attr-defined]

    # -- actions --------------------------------------------------------------------------

    def open_participant(self, code: str) -> ParticipantPage:
        """`code`'s page over the screens (`study.tui.participant_page`); Esc comes back."""
        # here, not at the top: importing study.tui.participant_page imports this module
        from study.tui.participant_page import ParticipantPage

        groups = list(self.roster.groups) if self.roster is not None else []
        page = ParticipantPage(self.services, code, groups)
        self.push_screen(page)
        return page

    @on(TabbedContent.TabActivated)
    def _tab_shown(self, event: TabbedContent.TabActivated) -> None:
        self.reload()  # each screen opens on what the database holds now
        if event.pane.id == "run" and self.settings.prepare_simulation:
            self._pane("run").prepare()  # type: ignore[attr-defined]

    def action_tab(self, tab: str) -> None:
        if not self.ready:
            return
        self.query_one("#tabs", TabbedContent).active = tab
        # focus inside the screen, so its key bindings work at once
        pane = self.query_one(f"#{tab}").children[0]
        if hasattr(pane, "focus_first"):  # the screen knows which field comes first
            pane.focus_first()
            return
        target = pane if pane.focusable else next((w for w in pane.query("*") if w.focusable), None)
        if target is not None:
            target.focus()

    def action_digit_tab(self, tab: str) -> None:
        """1-6 switch screens only where no form field has the focus: in a form the digit
        belongs to the field (a Select or a pairwise choice does not take digits, and
        the key used to fall through to here and leave the form). F1-F6 always switch."""
        if self.focused is not None and _is_form_field(self.focused):
            return
        self.action_tab(tab)

    def action_toggle_help(self) -> None:
        """`?`: every key of the current screen and the app, beside the screen."""
        if self.screen.query("HelpPanel"):
            self.action_hide_help_panel()
        else:
            self.action_show_help_panel()

    def action_toggle_theme(self) -> None:
        self.theme = "textual-light" if self.theme == "textual-dark" else "textual-dark"

    def on_unmount(self) -> None:
        self.services.close_lsl()  # the design's LSL streams end with the app

    async def action_quit(self) -> None:
        """Stop a running trial (marked interrupted, its samples kept), then exit.

        Quitting while the later screens are still being mounted waits for them first:
        exiting under a mounting `Select` made Textual print a NoMatches traceback.
        """
        unsaved = self._pane("tlx").unsaved() if self.ready else []  # type: ignore[attr-defined]
        if unsaved:
            from study.tui.confirm import Confirm

            async def leave(yes: bool | None) -> None:
                if yes:
                    await self._quit_now()

            blocks = ", ".join(f"{c} {t}/{k}" for c, t, k in unsaved)
            self.push_screen(
                Confirm(
                    f"NASA-TLX answers typed and not saved ({blocks}). Quit without saving them?"
                ),
                leave,
            )
            return
        if self.ready and self._pane("run").run is not None:  # type: ignore[attr-defined]
            from study.tui.confirm import Confirm

            async def answered(yes: bool | None) -> None:
                if yes:
                    await self._quit_now()

            self.push_screen(
                Confirm("A trial is running. Stop it (kept as interrupted) and quit?"), answered
            )
            return
        await self._quit_now()

    async def _quit_now(self) -> None:
        if self.overview_shown_s is not None:
            await asyncio.wait_for(self._later_mounted.wait(), timeout=10.0)
        await self.stop_trial()
        self.exit()

    async def stop_trial(self, timeout_s: float = 30.0) -> None:
        if not self.ready:
            return
        run = self._pane("run").run  # type: ignore[attr-defined]
        if run is not None:
            self.notify("stopping the trial: it is kept as interrupted")
            run.stop()
            await asyncio.to_thread(run.finished.wait, timeout_s)


def _is_form_field(widget: Widget) -> bool:

    # here, not at the top: importing study.tui.tlx_pane imports this module
    from study.tui.tlx_pane import PairChoice

    chain = [widget, *widget.ancestors]
    return any(isinstance(w, (Input, Select, SelectionList, PairChoice)) for w in chain)


def make_app(services: StudyServices, settings: TuiSettings | None = None) -> StudyApp:
    """The terminal app over `services` (see `study.tui.services.StudyServices`)."""
    return StudyApp(services, settings or TuiSettings())
