"""The command palette's own commands (ctrl+p): the app's actions, by name.

`StudyCommands` is a Textual command provider (`textual.command.Provider`) the app
lists in `StudyApp.COMMANDS` beside Textual's own (theme, keys, quit). It offers:

- the screens (F1-F6), each by its title;
- enrolling a participant in each group, with the group's fill;
- per participant: their page, the next trial (started as `s` starts it, checklist and
  all), a note, a withdrawal; each NASA-TLX due, and each stored one (to read or edit);
- every key the screens show in their footers (analyse, export figures, calibrate,
  whatever a screen binds), run on its screen as the key would.

The list is built when the palette opens, from the roster the app holds, so it names
only what can be done now.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from functools import partial
from typing import Any

from textual.command import DiscoveryHit, Hit, Hits, Provider
from textual.widgets import DataTable, Input, Select

__all__ = ["StudyCommands", "study_commands"]

Command = tuple[str, str, Callable[[], Any]]
StudyApp = Any
"""The app (`study.tui.app.StudyApp`), which imports this module: named, not imported."""
"""(name shown, help line, what it does)."""


def study_commands(app: StudyApp) -> list[Command]:
    """The palette's commands for the app as it stands."""
    # here, not at the top: importing study.tui.tabs imports this module
    from study.tui.tabs import TABS, TITLES

    out: list[Command] = [
        (f"Screen: {TITLES[k]}", f"F{k + 1}", partial(app.action_tab, tab))
        for k, tab in enumerate(TABS)
    ]
    roster = app.roster
    if not app.ready or roster is None:
        return out
    for group, fill in roster.groups.items():
        out.append(
            (
                f"Enrol a participant in {group}",
                f"{fill['enrolled']} of {fill['target']} enrolled (F2, a)",
                partial(enrol, app, group),
            )
        )
    for code, task, condition in roster.tlx_due():
        out.append(
            (
                f"NASA-TLX of {code} {task}/{condition}",
                "the block is done; its questionnaire is due (F4)",
                partial(app._open_tlx, code, task, condition),
            )
        )
    for r in roster.participants:
        for b in r["blocks"]:
            if (r["code"], b["task"], b["condition"]) in roster.answered:
                out.append(
                    (
                        f"NASA-TLX of {r['code']} {b['task']}/{b['condition']} (stored)",
                        "opens it filled in; an edit needs a reason (F4)",
                        partial(app._open_tlx, r["code"], b["task"], b["condition"]),
                    )
                )
    for r in roster.participants:
        code, group = r["code"], r["group"]
        out.append(
            (
                f"Participant page: {code} ({group})",
                "trials, notes, TLX, probes, schedule; corrections",
                partial(app.open_participant, code),
            )
        )
        nxt = roster.next_trial(code)
        if nxt is not None:
            out.append(
                (
                    f"Run the next trial of {code}: {nxt.describe()}",
                    f"block {nxt.block_index + 1}, {nxt.remaining} trials left (F3, s)",
                    partial(run_next, app, code),
                )
            )
        out.append((f"Add a note to {code}", "kept with when and who", partial(note, app, code)))
        if not r.get("withdrawn"):
            out.append(
                (f"Withdraw {code}", "asks why; their data are kept", partial(withdraw, app, code))
            )
    out.extend(_screen_keys(app))
    return out


def _screen_keys(app: StudyApp) -> Iterator[Command]:
    """Every key a later screen shows in its footer, run on that screen."""
    # here, not at the top: importing study.tui.tabs imports this module
    from study.tui.tabs import TABS, TITLES

    for k, tab in enumerate(TABS[1:], start=1):
        try:
            pane = app._pane(tab)
        except Exception:  # not mounted (the app is closing)
            continue
        for binding in getattr(pane, "BINDINGS", []):
            if not getattr(binding, "show", False):
                continue
            key = binding.key.split(",")[0]
            yield (
                f"{TITLES[k]}: {binding.description}",
                f"F{k + 1}, {key}",
                partial(_run_key, app, tab, binding.action),
            )


async def _run_key(app: StudyApp, tab: str, action: str) -> None:
    app.action_tab(tab)
    pane = app._pane(tab)
    if pane.check_action(action, ()) is False:  # the key is not offered now
        app.notify(f"not now: {action.replace('_', ' ')} is not offered on this screen now")
        return
    await pane.run_action(action)


def enrol(app: StudyApp, group: str) -> None:
    """Enrol one more participant in `group`, as F2 then `a` does (asked past its target)."""

    app.action_tab("participants")
    pane: Any = app._pane("participants")
    pane.query_one("#group", Select).value = group
    pane.action_add()


def run_next(app: StudyApp, code: str) -> None:
    """Pick `code` on the run screen and start their next trial as `s` does."""
    app.action_tab("run")
    pane: Any = app._pane("run")
    if pane.run is not None:
        app.notify("a trial is running: stop it first (x)", severity="warning")
        return
    pane.select_participant(code)
    pane.focus()
    pane.action_start()


def note(app: StudyApp, code: str) -> None:
    """`code`'s page with the note field open."""
    page = app.open_participant(code)
    page.call_after_refresh(page.action_add_note)


def withdraw(app: StudyApp, code: str) -> None:
    """The participants list on `code`, and the withdrawal's question."""

    app.action_tab("participants")
    pane: Any = app._pane("participants")
    pane.query_one("#filter", Input).value = ""
    pane._fill_table()
    table = pane.query_one("#people", DataTable)
    if code in table.rows:
        table.move_cursor(row=table.get_row_index(code))
        pane.action_withdraw()


class StudyCommands(Provider):
    """The app's own commands in the palette (see the module docstring)."""

    def _commands(self) -> list[Command]:
        return study_commands(self.app)

    async def discover(self) -> Hits:
        for name, help_text, callback in self._commands():
            yield DiscoveryHit(name, callback, help=help_text)

    async def search(self, query: str) -> Hits:
        matcher = self.matcher(query)
        for name, help_text, callback in self._commands():
            score = matcher.match(name)
            if score > 0:
                yield Hit(score, matcher.highlight(name), callback, help=help_text)
