"""The run-session screen: pick a participant, start and stop the next trial, watch it live.

The trial runs in a thread worker (`TrialRun.run`, the session runner); the worker posts
`TrialStarted` and `TrialEnded` back as messages. A 30 Hz timer redraws the live view
from `LiveState` (never from the worker), so the screen moves at real time whatever the
trial does. Drivers: the participant's simulated person (paced at 1x, 4x or as fast as
it goes) or the keyboard, paced at real time: up/down aim the dial forward/back (the
hand holds it there; in HV the felt torque deflects the dial from the aim, which slows
the guidewire), left/right turn the rotation joystick, space lets go of the dial, `e`
ends the trial (`KeyboardDriver.press`). `x` stops a trial in the middle, with a reason: its
samples stay, it is marked interrupted (the reason audited), and it is repeated as a new
attempt.

After a block the design's break is counted down on the status line; its clock stands
while the NASA-TLX screen is open on the participant's questionnaire still to fill in
(that is not rest), and the terminal bell rings when it ends.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widget import Widget
from textual.widgets import Label, Select, TabbedContent

from study.protocol.observer import SessionObserver
from study.protocol.tasks import Task, get_task, tasks
from study.tui.db_errors import SafeWorkers, plain_line
from study.tui.live_view import LiveReadout
from study.tui.picker import ParticipantSelect, picker_rows
from study.tui.preferences import RunChoices, save_run_choices
from study.tui.run_live import KeyboardMixin, LiveViewMixin
from study.tui.scenes import TrackView, scene_class
from study.tui.services import NextTrial, Roster, StudyServices
from study.tui.stop_dialog import StopAnswer, StopScreen
from study.tui.task_views import live_view
from study.tui.trial_runner import (
    Simulation,
    TrialOutcome,
    TrialRun,
    TuiKeyboardDriver,
    _if_app_alive,
)
from study.tui.trial_summary import TrialReport, report_lines, trial_report

__all__ = ["RunPane"]

PACES: tuple[float | None, ...] = (1.0, 4.0, None)
"""Pace choices for a simulated participant (times real time; None: as fast as it goes)."""
REDRAW_HZ = 30.0
"""Live-view redraws per second (the issue asks for >= 20 Hz; 30 leaves room on a busy machine)."""


class RunPane(SafeWorkers, LiveViewMixin, KeyboardMixin, Vertical, can_focus=True):
    """Run a participant's next trial with a live view."""

    DEFAULT_CSS = """
    RunPane { height: 1fr; }
    RunPane #run-top { height: 1; }
    RunPane #run-top Label { padding: 0 1 0 0; }
    RunPane #participant { width: 14; }
    RunPane #next { height: auto; max-height: 2; }
    RunPane #live { height: 1fr; }
    RunPane #phantom-box { width: 1fr; height: 1fr; border: round $primary-muted; }
    RunPane:focus #phantom-box { border: round $accent; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("s", "start", "Start"),
        Binding("x", "stop", "Stop"),
        Binding("d", "driver", "Driver"),
        Binding("p", "pace", "Pace"),
        Binding("n", "next_participant", "Next participant", show=False),
        Binding("v", "participant_page", "Page"),
        Binding("t", "tlx_due", "NASA-TLX", show=False),
        Binding("up", "dial_forward", "Dial +", show=False),
        Binding("down", "dial_back", "Dial -", show=False),
        Binding("right", "rotate_cw", "Rotate", show=False),
        Binding("left", "rotate_ccw", "Rotate", show=False),
        Binding("space", "release", "Let go", show=False),
        Binding("e", "end_trial", "End trial", show=False),
    ]

    @dataclass
    class TrialStarted(Message):
        code: str
        description: str
        practice: bool = False

    @dataclass
    class TrialEnded(Message):
        outcome: TrialOutcome
        block: tuple[str, str, str]
        """(code, task, condition) of the trial's block."""
        report: TrialReport | None = None
        """The stored trial's figures (and its block's, at a block's end)."""

    def __init__(
        self,
        services: StudyServices,
        simulated_pace: float | None = 1.0,
        driver: str = "simulated",
        preferences_file: Path | None = None,
        **kwargs: object,
    ) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.services = services
        self.roster: Roster | None = None
        self.driver_kind = driver
        self.preferences_file = preferences_file
        """Where d and p are remembered for the next start (None: not remembered)."""
        self.pace: float | None = simulated_pace
        self.paces: tuple[float | None, ...] = tuple(dict.fromkeys((simulated_pace, *PACES)))
        """What p cycles through: the pace the app was started with, then 1x, 4x, fastest."""
        self._practice = False
        """Whether the running trial is a practice trial (e ends it without asking)."""
        self.run: TrialRun | None = None
        self.status = "idle"
        self.simulation = Simulation(services.load_estimator)
        self.last_outcome = ""
        self.last_report: tuple[str, TrialReport, str] | None = None
        """The last stored trial's code, figures and `last_outcome` text: the readout
        lays the figures out in the rows it has while that text is the one shown."""
        self._codes: list[str] = []
        self._redraws: deque[float] = deque(maxlen=50)
        self._next: NextTrial | None = None
        self._checked: set[str] = set()
        """Participants whose session checklist is recorded (in this app or before)."""
        self._breaks: dict[str, float] = {}
        """Participant -> time.monotonic() when their last finished block ended."""
        self._paused_s: dict[str, float] = {}
        """Participant -> seconds of their break spent on their NASA-TLX form (not rest)."""
        self._rung: set[str] = set()
        """Participants whose break has ended and been rung."""
        self._tick = time.monotonic()
        self._ended_at: tuple[tuple[str, str, str], float] | None = None
        """The last completed trial's block and when it ended (until the roster knows)."""
        self._trial_task: Task = tasks()[0]
        """The task of the trial running or run last."""
        self._stop_screen: StopScreen | None = None
        """The stop dialog last opened over a running trial."""
        self._running_text = ""
        """The status line of the running trial."""
        self._starting = False
        """`s` is reading the roster before it decides (a second `s` waits for it)."""

    def compose(self) -> ComposeResult:
        with Horizontal(id="run-top"):
            yield Label("Participant")
            yield ParticipantSelect([], id="participant", compact=True, prompt="pick")
            yield Label("", id="mode")
        yield Label("", id="next")
        with Horizontal(id="live"):
            with Vertical(id="phantom-box"):
                scenes: list[type[Widget]] = [*map(scene_class, tasks()), TrackView]
                for scene in dict.fromkeys(scenes):
                    yield scene()
            yield LiveReadout(id="readout")

    def on_mount(self) -> None:
        self._show_task(self._trial_task)
        self._show_mode()
        self._redraw()
        self.set_interval(1 / REDRAW_HZ, self._redraw)
        self.set_interval(1.0, self._count_down)

    def on_unmount(self) -> None:
        """The app ends whichever way: a trial still held or running is stopped (kept
        as interrupted), so its thread does not wait for an answer that cannot come."""
        if self.run is not None:
            self.run.stop()

    def _count_down(self) -> None:
        """Once a second: the break's clock (held while the participant fills in the
        NASA-TLX), the bell when a break ends, the countdown on the status line."""
        now = time.monotonic()
        step, self._tick = now - self._tick, now
        for code in list(self._breaks):
            if code in self._rung:
                continue
            roster = self.roster
            if roster is None or roster.break_s <= 0 or roster.next_trial(code) is None:
                continue  # no break to ring the end of (none planned, or nothing left)
            if self._filling_in_tlx(code):
                self._paused_s[code] = self._paused_s.get(code, 0.0) + step
            elif self.break_left_s(code) <= 0:
                self._rung.add(code)
                self.app.bell()
                self.app.notify(f"{code}'s break is over: s starts the next block")
        if self.run is None and self.code is not None and self.code in self._breaks:
            self._show_next()

    def _filling_in_tlx(self, code: str) -> bool:
        """The NASA-TLX screen is shown while `code` has a questionnaire to fill in."""
        if self.roster is None or self.app.query_one("#tabs", TabbedContent).active != "tlx":
            return False
        return any(b[0] == code for b in self.roster.tlx_due())

    def _break_starts(self, code: str, at: float) -> None:
        self._breaks[code] = at
        self._paused_s.pop(code, None)
        self._rung.discard(code)

    # -- roster and selection -------------------------------------------------------------

    def show(self, roster: Roster) -> None:
        self.roster = roster
        if self._ended_at is not None:
            (code, task, condition), at = self._ended_at
            row = next((r for r in roster.participants if r["code"] == code), None)
            blocks = row["blocks"] if row else []
            if any(
                b["task"] == task and b["condition"] == condition and b["completed"] >= b["planned"]
                for b in blocks
            ):
                self._break_starts(code, at)
                self._ended_at = None
        codes = [r["code"] for r in roster.participants]
        select = self.query_one("#participant", ParticipantSelect)
        select.rows = picker_rows(roster)  # group, progress and next trial, searched by code
        if codes != self._codes:
            self._codes = codes
            current = select.value
            select.set_options([(c, c) for c in codes])
            if current in codes:
                select.value = current
        self._show_next()

    def select_participant(self, code: str) -> None:
        self.query_one("#participant", Select).value = code
        self._show_next()

    def focus_first(self) -> None:
        """F3: the participant list while none is picked (Enter opens it), else the
        screen itself, whose keys (s, d, p) then act at once."""
        if self.code is None or not self.focusable:
            self.query_one("#participant", Select).focus()
        else:
            self.focus()

    @property
    def code(self) -> str | None:
        value = self.query_one("#participant", Select).value
        return None if value is Select.NULL else str(value)

    @on(Select.Changed, "#participant")
    def _picked(self, event: Select.Changed) -> None:
        event.stop()
        self._show_next()

    def _show_next(self) -> None:
        code = self.code
        nxt = self.roster.next_trial(code) if (self.roster and code) else None
        self._next = nxt
        if code is None:
            text = "pick a participant, then s to start"
        elif nxt is None and self.roster is not None and self.roster.withdrawn(code):
            text = f"{code} withdrew ({self.roster.withdrawn(code)}): no more sessions"
        elif nxt is None:
            text = f"{code}: every scheduled trial is done"
            due = self._questionnaire_due(code)
            if due is not None:  # shorter, so that all three fit on 80 columns
                text = f"{code}: every trial is done; the NASA-TLX of {due[0]}/{due[1]} is due (t)"
            after = self.next_participant()
            if after is not None:
                text += f"; n: on to {after}"
        else:
            text = f"next: {code} {nxt.describe()} ({nxt.remaining} left)  s: start"
            left = self.break_left_s(code)
            due = self._tlx_due(code)
            if due is not None:
                text = f"{code}: the NASA-TLX of {due[0]}/{due[1]} is due first (t), then s"
            elif left > 0:
                text = f"break: {int(left) // 60}:{int(left) % 60:02d} left, then {text[6:]}"
        if self.run is None:
            self.query_one("#next", Label).update(text)
            if nxt is not None:  # the view of the task the next trial is in
                self._show_task(get_task(nxt.task))

    def _show_mode(self) -> None:
        pace = "real time" if self.driver_kind == "keyboard" else self._pace_text()
        self.query_one("#mode", Label).update(f"driver: {self.driver_kind} (d)  pace: {pace} (p)")

    def _pace_text(self) -> str:
        return "as fast as it goes" if self.pace is None else f"{self.pace:g}x"

    # -- actions --------------------------------------------------------------------------

    def action_driver(self) -> None:
        if self.run is None:
            self.driver_kind = "keyboard" if self.driver_kind == "simulated" else "simulated"
            self._show_mode()
            self.refresh_bindings()
            self._remember()

    def action_pace(self) -> None:
        if self.run is None and self.driver_kind == "simulated":
            k = self.paces.index(self.pace) if self.pace in self.paces else -1
            self.pace = self.paces[(k + 1) % len(self.paces)]
            self._show_mode()
            self._remember()

    def _remember(self) -> None:
        """Keep the driver and pace for the app's next start on this database."""
        if self.preferences_file is None:
            return

        try:
            choices = RunChoices(self.driver_kind, self.pace)
            save_run_choices(self.services.engine, choices, self.preferences_file)
        except OSError as exc:
            self.app.notify(
                f"driver and pace not remembered for the next start: {plain_line(exc)}",
                severity="warning",
            )

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """Offer only the keys that act now: no start, driver or pace change during a
        trial (and no pace for the keyboard, which runs at real time), no stop without a
        trial."""
        if action in ("start", "driver"):
            return self.run is None
        if action == "pace":
            return self.run is None and self.driver_kind == "simulated"
        if action == "stop":
            return self.run is not None
        if action == "participant_page":  # not over a running trial's live view
            return self.run is None
        return True

    def action_end_trial(self) -> None:
        """`e` (keyboard driver): a practice trial ends at once; a measured one is asked
        first, as it is stored as completed and unsuccessful."""
        run = self.run
        if run is None or run.keyboard is None:
            return
        if self._practice:
            self._press("end_trial")
            return
        # lazy: study.tui.confirm costs 4 ms at start-up
        from study.tui.confirm import Confirm

        def answered(yes: bool | None) -> None:
            if yes and self.run is run:
                self._press("end_trial")

        self.app.push_screen(
            Confirm(
                f"End {run.code}'s measured trial now? It is stored as completed and "
                "not successful (x stops it instead: kept as interrupted, repeated "
                "later)."
            ),
            answered,
        )

    def action_start(self) -> None:
        """Start the picked participant's next trial, decided on the roster as the
        database has it now (another program may have run or withdrawn them)."""
        code = self.code
        if self.run is not None or code is None or self._starting:
            return
        self._starting = True
        self.query_one("#next", Label).update(f"{code}: reading what is next...")
        self._fresh_start(code)

    @work(thread=True, exclusive=True, group="fresh-start", exit_on_error=False)
    def _fresh_start(self, code: str) -> None:
        try:
            roster = self.services.roster()
            checked = code in self._checked or self.services.checklist_recorded(code)
        finally:
            self.app.call_from_thread(setattr, self, "_starting", False)
        self.app.call_from_thread(self._start_on, code, roster, checked)

    def _start_on(self, code: str, roster: Roster, checked: bool) -> None:
        if checked:  # recorded before (an earlier start of the app): asked once
            self._checked.add(code)
        self.app.show_roster(roster)  # type: ignore[attr-defined]
        self.show(roster)
        nxt = self._next
        if self.run is not None or code != self.code:
            return
        if nxt is None:
            self.app.notify(f"{code}: nothing left to run", severity="warning")
            return
        due = self._tlx_due(code)
        if due:  # the session flow: a finished block's questionnaire before the next block
            task, condition = due
            self._show_next()
            self.app.notify(
                f"{code} finished {task}/{condition}: its NASA-TLX comes before "
                "the next block (t opens it)",
                severity="warning",
            )
            return
        left = self.break_left_s(code)
        if left > 0:
            from study.tui.confirm import Confirm

            def answered(yes: bool | None) -> None:
                if yes and self._next == nxt and self.run is None:
                    self._breaks.pop(code, None)
                    self._rung.add(code)  # ended early: no bell later
                    self._start(code, nxt)

            self.app.push_screen(
                Confirm(
                    f"{code}'s break after the last block has {left:.0f} s left of the "
                    f"design's {self.roster.break_s if self.roster else 0:g} s. Start the "
                    "next block now?"
                ),
                answered,
            )
            return
        if code not in self._checked:  # the session checklist, once per participant
            from study.tui.confirm import Confirm

            def confirmed(yes: bool | None) -> None:
                if yes and self._next == nxt and self.run is None:
                    self._checked.add(code)
                    self._start(code, nxt, checklist=True)
                elif not yes:  # said on the screen: nothing started, asked again at s
                    line = f"{code}: not started, the checklist is not confirmed; s asks again"
                    self.query_one("#next", Label).update(line)
                    self.app.notify(line, severity="warning")

            self.app.push_screen(
                Confirm(
                    f"Session checklist for {code}: consent confirmed and the device "
                    "checked? (recorded with the session)"
                ),
                confirmed,
            )
            return
        self._start(code, nxt)

    def next_participant(self) -> str | None:
        """The first participant after the selected one (in code order, then from the
        start) who still has trials to run and has not withdrawn."""
        if self.roster is None:
            return None
        codes = [r["code"] for r in self.roster.participants]
        start = codes.index(self.code) + 1 if self.code in codes else 0
        for code in codes[start:] + codes[:start]:
            if code != self.code and self.roster.next_trial(code) is not None:
                return code
        return None

    def action_participant_page(self) -> None:
        """The picked participant's page (trials, notes, corrections)."""
        if self.code is not None:
            self.app.open_participant(self.code)  # type: ignore[attr-defined]

    def action_tlx_due(self) -> None:
        """`t`: the picked participant's questionnaire due, on the NASA-TLX screen."""
        code = self.code
        due = self._questionnaire_due(code) if self.run is None and code is not None else None
        if code is not None and due is not None:
            self.app._open_tlx(code, *due)  # type: ignore[attr-defined]

    def action_next_participant(self) -> None:
        """A finished participant leads to the next one."""
        if self.run is None and self.code is not None and self._next is None:
            after = self.next_participant()
            if after is not None:
                self.select_participant(after)

    def _tlx_due(self, code: str) -> tuple[str, str] | None:
        """(task, condition) of `code`'s finished block awaiting its questionnaire, if the
        design says it comes first (`tlx_before_next_block`)."""
        if self.roster is None or not self.roster.tlx_first:
            return None
        return self._questionnaire_due(code)

    def _questionnaire_due(self, code: str) -> tuple[str, str] | None:
        """(task, condition) of `code`'s first finished block without its questionnaire."""
        due = [b for b in self.roster.tlx_due() if b[0] == code] if self.roster else []
        return (due[0][1], due[0][2]) if due else None

    def break_left_s(self, code: str) -> float:
        """Seconds left of the break that began when `code`'s last block ended (0: none)."""
        ended = self._breaks.get(code)
        if ended is None or self.roster is None:
            return 0.0
        rested = time.monotonic() - ended - self._paused_s.get(code, 0.0)
        return max(0.0, self.roster.break_s - rested)

    def _start(self, code: str, nxt: NextTrial, checklist: bool = False) -> None:
        opened, observer = self._lsl_observer()
        if not opened:  # the design's streams are part of the trial: not run without
            return
        keyboard = TuiKeyboardDriver() if self.driver_kind == "keyboard" else None
        pace = 1.0 if keyboard is not None else self.pace
        self.run = TrialRun(
            self.services.engine,
            None,
            code,
            self.driver_kind,
            pace,
            keyboard=keyboard,
            observer=observer,
        )
        self.status = "starting"
        self.refresh_bindings()
        self._trial_task = get_task(nxt.task)
        self._show_task(self._trial_task)
        self.query_one("#next", Label).update(f"{code} {nxt.describe()}: loading...")
        self.focus()
        self._run_trial(self.run, (code, nxt.task, nxt.condition), checklist)

    def action_stop(self) -> None:
        """Hold the running trial at once and ask why it is stopped: a reason stops it
        (kept as interrupted, the reason in its audit row), Esc lets it go on. A trial
        that ends while the dialog is open is offered for invalidation instead."""
        if self.run is None:
            return
        run = self.run
        run.hold()
        self.status = "held"
        self.query_one("#next", Label).update(f"held: {run.code}'s trial stands until answered")

        def answered(answer: StopAnswer | None) -> None:
            if answer is None:
                if self.run is run:
                    run.resume()
                    self.status = "running"
                    self._show_running()
                return
            if answer.action == "stop":
                self.status = "stopping"
                run.stop(answer.reason)
            elif answer.trial_id is not None:
                self._invalidate(run.code, answer.trial_id, answer.reason)

        self._stop_screen = StopScreen(run.code)
        self.app.push_screen(self._stop_screen, answered)

    @work(thread=True, group="invalidate", exit_on_error=False)
    def _invalidate(self, code: str, trial_id: int, reason: str) -> None:
        """The trial that ended before it could be stopped, marked invalid (audited)."""
        try:
            what = self.services.mark_trial(trial_id, False, reason)
        except ValueError as exc:
            self.app.call_from_thread(self.app.notify, f"not invalidated: {exc}", severity="error")
            return
        line = f"{code}: {what} marked invalid ({reason})"
        self.app.call_from_thread(self._show_invalidated, line)

    def _show_invalidated(self, line: str) -> None:
        self.last_outcome = line
        self.app.notify(line)
        self.query_one("#next", Label).update(line)

    # -- the workers ----------------------------------------------------------------------

    def prepare(self) -> None:
        """Load the estimator and compile the loop when the screen is first shown; open
        the design's `[lsl]` streams."""
        self._lsl_observer()
        if self.simulation.estimator is None:
            self.status = "preparing the simulation"
            self._prepare()

    def _prepare(self) -> None:  # not a worker: quitting meanwhile does not wait for it
        self.simulation.prepare_in_background(
            lambda: self.app.call_from_thread(self._prepared),
            lambda exc: self.app.call_from_thread(self.worker_failed, "prepare", plain_line(exc)),
        )

    def _lsl_observer(self) -> tuple[bool, SessionObserver | None]:
        """Whether the app's LSL observer (`StudyServices.lsl_observer`) could be
        opened, and it (None when the design has no `[lsl]` streams); the reason shown
        when it could not (no LSLAPICFG, say)."""
        try:
            return True, self.services.lsl_observer(
                lambda line: _if_app_alive(self.app.call_from_thread, self.notify, line)
            )
        except Exception as exc:
            self.notify(f"LSL streams not opened: {plain_line(exc)}", severity="error")
            return False, None

    def worker_failed(self, group: str, line: str) -> None:
        if group == "fresh-start":
            self._show_next()
            line = f"not started: {line}"
        if group == "prepare":
            self.status = "idle"
            line = f"the simulation could not be prepared: {line}"
        super().worker_failed(group, line)

    def _prepared(self) -> None:
        if self.status == "preparing the simulation":
            self.status = "idle"

    @work(thread=True, exclusive=True, group="trial", exit_on_error=False)
    def _run_trial(self, run: TrialRun, block: tuple[str, str, str], checklist: bool) -> None:
        try:
            if checklist:
                self.services.record_checklist(run.code)
            run.estimator = self.simulation.ready()
            self._run_loaded(run, block)
        finally:
            run.finished.set()

    def _run_loaded(self, run: TrialRun, block: tuple[str, str, str]) -> None:

        def started(item) -> None:
            kind = "practice" if item.practice else "trial"
            desc = f"{item.block.task}/{item.block.condition} {kind} {item.trial_index + 1}"
            self.post_message(self.TrialStarted(run.code, desc, item.practice))

        try:
            outcome = run.run(started)
        except Exception as exc:  # shown, not swallowed: the trial row says what is stored
            line = f"trial failed: {plain_line(exc)}"
            outcome = TrialOutcome(run.code, [], 0, 0.0, line)
            self.app.call_from_thread(self.app.notify, line, severity="error", timeout=15)
        report = None
        if outcome.trial_ids:
            try:
                report = trial_report(self.services.engine, outcome.trial_ids[0])
            except Exception:  # the trial is stored; only its figures are not shown
                report = None
        self.post_message(self.TrialEnded(outcome, block, report))

    @on(TrialStarted)
    def _started(self, event: TrialStarted) -> None:
        self.status = "running"
        self._practice = event.practice
        text = f"running: {event.code} {event.description}  x: stop"
        if self.run is not None and self.run.keyboard is not None:
            text += "\n" + live_view(self._trial_task).key_hints  # a line of its own: none is cut
        self._running_text = text
        if self.run is not None and self.run.held:
            self.status = "held"
        else:
            self._show_running()

    def _show_running(self) -> None:
        self.query_one("#next", Label).update(self._running_text)

    @on(TrialEnded)
    def _ended(self, event: TrialEnded) -> None:
        outcome, run = event.outcome, self.run
        self.run = None
        self.refresh_bindings()
        if outcome.trial_ids:  # the break starts if this trial finished its block
            self._ended_at = (event.block, time.monotonic())
        if outcome.trial_ids:
            self.status = "completed"
            peaks = ""
            if run is not None and run.live.task is not None:
                first, second = live_view(run.live.task).shown_peaks
                peaks = (
                    f", peaks {run.live.peaks[0]:.2f} N {first.label},"
                    f" {run.live.peaks[1]:.2f} N {second.label}"
                )
            text = f"{outcome.code}: trial stored (id {outcome.trial_ids[0]}{peaks})"
            if event.report is not None:
                text = "\n".join(report_lines(outcome.code, event.report))
                self.last_report = (outcome.code, event.report, text)
        elif outcome.error:
            self.status = "failed"
            text = (
                f"{outcome.code}: {outcome.error}; the next start marks the trial "
                "interrupted and repeats it"
            )
        elif outcome.interrupted:
            self.status = "interrupted"
            text = f"{outcome.code}: trial stopped; kept as interrupted, to be repeated"
        else:
            self.status = "idle"
            text = f"{outcome.code}: nothing run"
        self.last_outcome = text
        self._show_next()
        self._tell_stop_dialog(run, event)

    def _tell_stop_dialog(self, run: TrialRun | None, event: TrialEnded) -> None:
        """A stop asked for over a trial that ended first is not dropped: the dialog
        still open learns that it has ended (stored as completed: it then offers to
        invalidate it), and a stop answered just as it ended asks that again."""
        dialog, self._stop_screen = self._stop_screen, None
        outcome = event.outcome
        stored = outcome.trial_ids[0] if outcome.trial_ids else None
        measured = not (event.report.practice if event.report is not None else self._practice)
        if run is None or dialog is None:
            return
        if dialog in self.app.screen_stack:
            if dialog.ended is None and not run.stop_requested:
                how = "completed" if stored else (outcome.error or "nothing stored")
                dialog.trial_ended(stored, measured, how)
            return
        if run.stop_requested and stored is not None:  # answered as it ended
            again = StopScreen(run.code, ended=(stored, measured, "completed"))

            def answered(answer: StopAnswer | None) -> None:
                if answer is not None and answer.trial_id is not None:
                    self._invalidate(run.code, answer.trial_id, answer.reason)

            self.app.push_screen(again, answered)
