"""A lab day in a real terminal: `study tui` in tmux at 80 x 24, driven by keys only.

Participants of three groups (outsider, novice, expert) are enrolled on the participants
screen, every block of an LCCA + NOTES study is run with the simulated participant at a
high pace, every NASA-TLX (six ratings and 15 pairwise choices, drawn per participant
and block from a seeded RNG) is typed on the form as one burst of keys, as a quick
operator types ahead, and a note is typed for each participant. Half-way the app is
quit and started again; at the end the last block's questionnaire is typed in part and
not saved, and quitting must name exactly that block. Then the database is compared
field by field with what was typed: every rating and choice under its own participant,
task and condition, no questionnaire for a block never saved, one completed trial per
block, no trial left running, the notes, and no traceback with exit status 0.

The pairwise choices are recorded as the subscale named on the screen on the side that
was picked (the pair lines read off the terminal), not from the app's own pair order.

Run as a script with more participants (the test runs 6, with a quick typist):

    python -m tests.study.tui.lab_day --participants 30 --pace 200 --typing-s 5
"""

from __future__ import annotations

import argparse
import math
import random
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

GROUPS = ("outsider", "novice", "expert")
TASK_BLOCKS = ("lcca/VO", "lcca/HV", "notes/VO", "notes/HV")
SUBSCALES = ("mental", "physical", "temporal", "performance", "effort", "frustration")
TITLES = {  # as the NASA-TLX form names them
    "Mental demand": "mental",
    "Physical demand": "physical",
    "Temporal demand": "temporal",
    "Performance": "performance",
    "Effort": "effort",
    "Frustration": "frustration",
}
PAIR_LINE = re.compile(r"^\s*(\d+)\.\s+(.+?)\s{2}or\s{2}(.+?)\s*[▌▐▁▂▃▄▅▆▇█]*\s*$")
HINT_WORDS = ("P01", "expert", "withdrawn", "done")
"""The examples of the Find field's hint, typed on the participants screen."""
STOPPED_REASON = "stopped from the terminal app in the middle of the trial"
"""The audit log's reason of a trial stopped with `x`, before the typed one
(`study.tui.trial_runner.STOPPED_REASON`, quoted: the reference is not the app's own)."""
REASON_WORDS = ("dial", "slipped", "phone", "rang", "cable", "loose", "asked", "pause")
DIALOG_WORDS = ("Why?", "Withdraw ", "contact details", "A note", "beyond", "target?")
"""Words of the participants screen's dialogs (withdraw, notes, enrolling past a target)."""
NOTE_WORDS = ("left-handed", "glasses", "tired", "calm", "fast", "careful", "asked", "dial")


def design_text(groups: dict[str, int], seed: int = 7) -> str:
    """An LCCA + NOTES study, one measured trial a block, no practice and no break."""
    lines = [
        'name = "lab day"',
        f"seed = {seed}",
        'tasks = ["lcca", "notes"]',
        "trials_per_condition = 1",
        "practice_trials = 0",
        "break_s = 0",
        "[groups]",
        *(f"{g} = {n}" for g, n in groups.items()),
    ]
    return "\n".join(lines) + "\n"


def split_groups(n: int) -> dict[str, int]:
    """`n` participants over the three groups, as evenly as they go (outsiders first)."""
    base, extra = divmod(n, len(GROUPS))
    return {g: base + (k < extra) for k, g in enumerate(GROUPS)}


class Timeout(AssertionError):
    pass


class Terminal:
    """A command in a tmux pane of its own server (its own socket), read as text."""

    def __init__(self, command: list[str], cwd: Path, size: tuple[int, int] = (80, 24)):
        self.tmux = shutil.which("tmux")
        if self.tmux is None:
            raise RuntimeError("tmux is not installed; the lab day needs a real terminal")
        self.socket = Path(tempfile.mkdtemp(prefix="labday-tmux-")) / "sock"
        cols, rows = size
        shell = (
            f"cd {shlex.quote(str(cwd))} && TERM=xterm-256color COLUMNS={cols} LINES={rows} "
            f"{shlex.join(command)}; "
            'echo "exit status: $?"; sleep 100000'
        )
        self._tmux(
            "-f",
            "/dev/null",
            "new-session",
            "-d",
            "-s",
            "lab",
            "-x",
            str(cols),
            "-y",
            str(rows),
            shell,
        )
        self._tmux("set-option", "-t", "lab", "history-limit", "5000")

    def _tmux(self, *args: str) -> str:
        out = subprocess.run(
            [self.tmux, "-S", str(self.socket), *args], capture_output=True, text=True, check=True
        )
        return out.stdout

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "lab")

    def history(self) -> str:
        """The screen and the lines scrolled off it (a traceback after the app ended)."""
        return self._tmux("capture-pane", "-p", "-t", "lab", "-S", "-5000")

    def until(self, pattern: str, *keys: str, tries: int = 20, each_s: float = 1.0) -> None:
        """Send `keys` until `pattern` is on the screen (each try waits `each_s` for it):
        for keys that do nothing where the focus may still be on its way."""
        for _ in range(tries):
            self.keys(*keys)
            try:
                self.wait(pattern, each_s)
                return
            except Timeout:
                continue
        raise Timeout(f"not on the screen after {tries} x {keys}: {pattern!r}\n{self.screen()}")

    def wait_until(self, condition, what: str, timeout_s: float = 10.0) -> None:
        end = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > end:
                raise Timeout(f"not seen in {timeout_s} s: {what}\n{self.screen()}")
            time.sleep(0.02)

    def keys(self, *keys: str) -> None:
        """tmux key names (F3, Down, C-s, BTab) or single characters, in one write."""
        self._tmux("send-keys", "-t", "lab", *keys)

    def text(self, text: str) -> None:
        self._tmux("send-keys", "-t", "lab", "-l", text)

    def wait(self, pattern: str, timeout_s: float = 60.0, where: str = "screen") -> re.Match:
        """Poll the screen until `pattern` (a regex) is on it; fail with the screen."""
        end = time.monotonic() + timeout_s
        while True:
            text = self.history() if where == "history" else self.screen()
            found = re.search(pattern, text, re.MULTILINE)
            if found:
                return found
            if time.monotonic() > end:
                raise Timeout(f"not on the screen after {timeout_s} s: {pattern!r}\n{text}")
            time.sleep(0.05)

    def close(self) -> None:
        subprocess.run([self.tmux, "-S", str(self.socket), "kill-server"], capture_output=True)
        shutil.rmtree(self.socket.parent, ignore_errors=True)


@dataclass
class Typed:
    """What the operator did, the reference the database is compared with."""

    groups: dict[str, str] = field(default_factory=dict)  # code -> group
    notes: dict[str, str] = field(default_factory=dict)  # code -> note
    blocks: dict[str, list[tuple[str, str]]] = field(default_factory=dict)  # code -> run order
    tlx: dict[tuple[str, str, str], tuple[dict[str, int], list[tuple[str, str, str]]]] = field(
        default_factory=dict
    )  # block -> (ratings, [(left, right, chosen)] as seen on the screen)
    unsaved: tuple[str, str, str] | None = None  # the block typed in part and not saved
    stops: dict[str, tuple[str, str, str]] = field(default_factory=dict)
    """code -> (task, condition, reason) of the trial stopped with x."""
    lost_stops: list[str] = field(default_factory=list)
    """Stops whose trial ended before the reason was answered (what the screen said)."""
    raw_only: set[tuple[str, str, str]] = field(default_factory=set)
    """Blocks whose questionnaire was saved with ratings only."""
    raw_questions: int = 0
    """How often the raw-only question was seen (once per raw-only save)."""
    found: dict[str, list[str]] = field(default_factory=dict)
    """A word typed in the Find field -> the codes the list showed."""
    lost_keys: list[str] = field(default_factory=list)
    """Keys typed in the Find field that it never showed (typed again)."""
    dialogs: list[str] = field(default_factory=list)
    """A dialog seen while a word was typed on the participants screen."""
    cli: dict[str, float] = field(default_factory=dict)
    """code enrolled from the command line -> seconds until the list showed it."""
    headers_in_view: int = 0
    """Forms whose participant and block lines were in view with the reason field."""


class LabDay:
    def __init__(
        self,
        db: Path,
        workdir: Path,
        pace: float,
        rng: random.Random,
        typing_s: float = 5.0,
        stop_within_s: float = 12.0,
    ) -> None:
        self.db, self.workdir, self.pace, self.rng = db, workdir, pace, rng
        self.typing_s = typing_s
        """Seconds a stop's reason takes to type, character by character."""
        self.stop_within_s = stop_within_s
        """x comes at a moment drawn uniformly from the trial's first seconds (at 1x,
        every trial of the study lasts longer)."""
        self.typed = Typed()
        self.term: Terminal | None = None
        self.group_shown = GROUPS[0]  # the group list's value (the first group at start)
        self.histories: list[str] = []
        self.retried_keys = 0
        self.seconds: dict[str, float] = {}
        """Wall time spent per part of the day (enrolment, trials, forms, notes, starts)."""

    @contextmanager
    def timed(self, part: str) -> Iterator[None]:
        start = time.monotonic()
        try:
            yield
        finally:
            self.seconds[part] = self.seconds.get(part, 0.0) + time.monotonic() - start

    # -- the app -------------------------------------------------------------------------

    def start(self) -> None:
        study = Path(sys.executable).with_name("study")
        # p is remembered in the user's settings: this day's own
        config = f"XDG_CONFIG_HOME={self.workdir / 'config'}"
        command = ["env", config, str(study), "tui", "--db", str(self.db)]
        command += ["--pace", f"{self.pace:g}"]
        self.term = Terminal(command, self.workdir)
        self.term.wait(r"Study: lab day", 60)
        # the other screens are mounted after the overview shows: F2 acts once they are
        self.term.until(r"a Enrol", "F2", tries=60)
        self.group_shown = GROUPS[0]
        self.picked: str | None = None

    def quit(self, unsaved: str | None = None) -> None:
        """ctrl+q; with `unsaved` the app must ask, naming exactly that block; exit 0."""
        term = self.term
        term.keys("C-q")
        if unsaved is not None:
            asked = term.wait(r"NASA-TLX answers typed and not saved \(([^)]*)\)", 20)
            assert asked.group(1) == unsaved, asked.group(0)
            term.keys("y")
        status = term.wait(r"^exit status: (\d+)", 60, where="history")
        history = term.history()
        self.histories.append(history)
        term.close()
        self.term = None
        assert "Traceback" not in history, history
        assert status.group(1) == "0", history

    # -- enrolment -----------------------------------------------------------------------

    def to_screen(self, key: str, shown: str) -> None:
        """F1 (the overview), then `key`, whose screen shows `shown` once its first field
        has the focus (F2 to F2 would show no change to wait for)."""
        self.term.keys("F1")
        self.term.wait(r"Sessions done")
        self.term.keys(key)
        self.term.wait(shown)

    def enrol(self, code: str, group: str) -> None:
        term = self.term
        self.to_screen("F2", r"a Enrol")  # the list has the focus
        if group != self.group_shown:
            # from the list back over the find field and the Add button to the group
            # list; Enter opens it on the group shown
            # back along the fields (the list, the find field, the Add button, the group
            # list) until the group list has the focus: it opens with Down, which does
            # nothing on the others (Enter would press Add)
            for _ in range(3):
                term.until(r"esc Dismiss menu", "BTab", "Down", tries=20, each_s=1.0)
                # the group typed (the open list searches as one types), not counted in
                # rows: a Down sent while the list was opening has moved its highlight
                term.text(group)
                term.keys("Enter")
                try:
                    term.wait(rf"Group {group}\b", 10)
                    break
                except Timeout:  # on a loaded machine the list may miss the word
                    self.retried_keys += 1
                    if "esc Dismiss menu" in term.screen():
                        term.keys("Escape")
                        term.wait_until(lambda: "esc Dismiss menu" not in term.screen(), "")
            else:
                raise Timeout(f"group {group} not chosen in three tries\n{term.screen()}")
            self.group_shown = group
        # right after start the first `a` is now and then ignored (not diagnosed; a
        # second press enrols): pressed again only while the list shows no `code`
        for _ in range(3):
            term.keys("C-a")
            try:
                term.wait(rf"enrolled {code} \({group}\)", 5)
                break
            except Timeout:
                if re.search(rf"^\s+{code}\s", term.screen(), re.MULTILINE):
                    term.wait(rf"enrolled {code} \({group}\)", 30)
                    break
                self.retried_keys += 1
        else:
            raise Timeout(f"{code} not enrolled after three presses of ctrl+a\n{term.screen()}")
        self.typed.groups[code] = group

    def note(self, code: str, text: str) -> None:
        """The participant's note: F2, the cursor to their row, ctrl+n, the text, Enter."""
        term = self.term
        self.to_screen("F2", r"a Enrol")  # the list has the focus
        for _ in range(200):
            under = _under_cursor(term.screen())
            if under == code:
                break
            # the rows are in code order: down towards a later code, up to an earlier one;
            # one row a key, and the next key once the detail below the list follows
            term.keys("Down" if under is None or under < code else "Up")
            term.wait_until(lambda u=under: _under_cursor(term.screen()) != u, "the cursor")
        else:
            raise Timeout(f"the list's cursor never reached {code}")
        term.keys("C-n")
        term.wait(r"contact details", 10)
        term.text(text)
        term.keys("Enter")
        # the status line, or (when the block's notices cover it) the detail under the list
        term.wait(rf"{code}: note kept|note: {re.escape(text)}", 30)
        self.typed.notes[code] = text

    def enrol_from_command_line(self, code: str, group: str) -> None:
        """`study participant add` in a subprocess while the participants screen's Find
        field holds the next code (a long list scrolls): the seconds from the command's
        end to `code`'s row on the screen."""
        term = self.term
        self.to_screen("F2", r"a Enrol")
        self._type_in_find(code)
        row = rf"^\s+{code}\s+{group}\s"
        assert re.search(row, term.screen(), re.MULTILINE) is None, term.screen()
        study = Path(sys.executable).with_name("study")
        command = [str(study), "participant", "add", "--group", group, "--db", str(self.db)]
        out = subprocess.run(command, capture_output=True, text=True, cwd=self.workdir)
        assert out.returncode == 0, out.stderr
        assert out.stdout.startswith(f"{code} ({group})"), out.stdout
        done = time.monotonic()
        term.wait(row, 30)
        self.typed.cli[code] = time.monotonic() - done
        self.typed.groups[code] = group
        term.keys("C-u")  # the field emptied: the whole list again
        term.wait(r"^ Find code, group or state", 10)

    def _type_in_find(self, word: str) -> None:
        """`word` typed on the list a key at a time, each key seen in the Find field
        (a key never seen is typed again, and reported)."""
        term = self.term
        for k, ch in enumerate(word):
            term.text(ch)
            try:
                term.wait(rf"^ Find {re.escape(word[: k + 1])}\s*$", 5)
            except Timeout:
                self.typed.lost_keys.append(f"{ch!r} of {word!r} on F2")
                term.text(ch)
                term.wait(rf"^ Find {re.escape(word[: k + 1])}\s*$", 10)

    def search_words(self) -> None:
        """Every word of the Find field's hint typed on the list, a key at a time: the
        field takes it (no dialog opens) and the list shows the rows holding it."""
        term = self.term
        for word in HINT_WORDS:
            self.to_screen("F2", r"a Enrol")  # the list has the focus
            self._type_in_find(word)
            time.sleep(0.3)  # a dialog a key opened would be drawn by now
            screen = term.screen()
            self.typed.dialogs += [w for w in DIALOG_WORDS if w in screen]
            self.typed.found[word] = re.findall(
                rf"^\s+(P\d{{3}})\s+(?:{'|'.join(GROUPS)})\s", screen, re.MULTILINE
            )
            term.keys("C-u")  # the field emptied: the whole list again
            term.wait(r"^ Find code, group or state", 10)

    # -- sessions ------------------------------------------------------------------------

    def pick(self, code: str, position: int) -> None:
        """F3 and the participant list (focused while nobody is picked): the code at
        `position` (0: the first) in the list."""
        term = self.term
        self.to_screen("F3", r"s Start")
        if self.picked is None:  # nobody picked: the list has the focus
            term.keys("Enter")
            term.wait(r"Enter: pick|\(no change\)", 30)  # the picker is open on "(no change)"
            term.keys(*["Down"] * (position + 1), "Enter")
        else:  # the one before is done: n goes on to the next
            term.wait(rf"{self.picked}: every scheduled trial is done; n: on to {code}", 20)
            term.keys("n")
        term.wait(rf"next: {code} ", 20)
        self.picked = code

    def run_block(
        self, code: str, last: bool, stop: bool = False, raw_only: bool = False
    ) -> tuple[str, str]:
        """s (and the checklist's y): the next trial, which ends the block; the NASA-TLX
        form opens, is typed as one burst and saved with ctrl+s (unless `last`, whose
        form is typed in part and left unsaved; with `raw_only`, the ratings only). With
        `stop`, the block's first try is stopped with x first (`stop_trial`)."""
        term = self.term
        term.keys("F3")
        nxt = term.wait(rf"next: {code} (\w+)/(\w+) trial 1", 20)
        task, condition = nxt.group(1), nxt.group(2)
        if stop:
            with self.timed("stops (1x, x, the reason typed)"):
                self.stop_trial(code, task, condition)
        with self.timed("trials (s to the form shown)"):
            self._start_trial(code, task, condition)
            term.wait(rf"Participant {code}\s+▼\s+Block {task}/{condition}\s+▼", 120)
            term.wait(r"How mentally demanding was the task\?", 10)  # the first rating focused
        with self.timed("forms (typed, read, saved)"):
            return self._fill_form(code, task, condition, last, raw_only)

    def _start_trial(self, code: str, task: str, condition: str) -> None:
        term = self.term
        term.keys("s")
        shown = term.wait(rf"consent confirmed|running: {code}|Block {task}/{condition}", 30)
        if "consent" in shown.group(0):
            term.keys("y")

    def set_pace(self, shown: str) -> None:
        """p until the run screen says `pace: {shown} (p)`, a press at a time."""
        term = self.term
        for _ in range(6):
            now = term.wait(r"pace: (.+?) \(p\)", 10).group(1)
            if now == shown:
                return
            term.keys("p")
            term.wait_until(
                lambda n=now: re.search(rf"pace: {re.escape(n)} \(p\)", term.screen()) is None,
                "the pace to change",
            )
        raise Timeout(f"pace {shown} not reached with p\n{term.screen()}")

    def stop_trial(self, code: str, task: str, condition: str) -> None:
        """The block's trial at 1x, x at a random moment of its first seconds, a reason
        typed a character at a time over `typing_s`, Enter: stopped, to be repeated."""
        term = self.term
        self.set_pace("1x")
        self._start_trial(code, task, condition)
        term.wait(rf"running: {code} ", 30)
        time.sleep(self.rng.uniform(0.2, self.stop_within_s))
        term.keys("x")
        asked = term.wait(rf"Stop {code}'s running trial\?|ended before it was stopped", 20)
        reason = f"{self.rng.choice(REASON_WORDS)} {self.rng.choice(REASON_WORDS)} {code}"
        if "ended before" in asked.group(0):
            self.typed.lost_stops.append(f"{code} {task}/{condition}: the trial ended first")
            term.keys("Escape")
        else:
            for ch in reason:
                term.text(ch)
                time.sleep(self.typing_s / len(reason))
            term.keys("Enter")
            ended = term.wait(rf"{code}: trial stopped; kept as|ended before it", 30)
            if "ended before" in ended.group(0):
                self.typed.lost_stops.append(f"{code} {task}/{condition}: ended while typed")
                term.keys("Escape")
            else:
                self.typed.stops[code] = (task, condition, reason)
        self.set_pace(f"{self.pace:g}x")
        term.wait(rf"next: {code} {task}/{condition} trial 1", 20)

    def _fill_form(
        self, code: str, task: str, condition: str, last: bool, raw_only: bool = False
    ) -> tuple[str, str]:
        term = self.term
        first = term.screen()
        block = (code, task, condition)
        ratings = {s: 5 * self.rng.randrange(21) for s in SUBSCALES}
        sides = [self.rng.randrange(2) for _ in range(15)]
        keys: list[str] = []
        for k, s in enumerate(SUBSCALES):
            keys += [*str(ratings[s]), "Down"]
            if last and k == 2:  # three ratings typed, then the operator is called away
                term.keys(*keys)
                self.typed.unsaved = block
                return task, condition
        if raw_only:
            return self._save_raw_only(block, keys, ratings)
        for side in sides:
            keys += ["Left" if side == 0 else "Right", "Down"]
        term.keys(*keys)
        # the burst ends on the reason field, scrolled into view below the last pairs;
        # the participant and block lines stay in view above the scrolled form
        term.wait(r"^ Reason ", 20)
        end_screen = term.screen()
        header = rf"Participant {code}\s+▼\s+Block {task}/{condition}\s+▼"
        scrolled = re.search(r"^ Mental demand\b", end_screen, re.MULTILINE) is None
        if re.search(header, end_screen) and scrolled:  # the first rating's row scrolled off
            self.typed.headers_in_view += 1
        pairs = _pairs(first)
        end = time.monotonic() + 20  # a notification may cover a pair for a while
        while len(pairs) < 15 and time.monotonic() < end:
            pairs |= _pairs(term.screen())
            time.sleep(0.05)
        assert sorted(pairs) == list(range(1, 16)), f"pairs read: {sorted(pairs)}\n{first}"
        term.keys("C-s")
        term.wait(rf"{code} {task}/{condition}: stored", 30)
        chosen = [(*pairs[k + 1], pairs[k + 1][side]) for k, side in enumerate(sides)]
        self.typed.tlx[block] = (ratings, chosen)
        return task, condition

    def _save_raw_only(
        self, block: tuple[str, str, str], keys: list[str], ratings: dict[str, int]
    ) -> tuple[str, str]:
        """The six ratings and ctrl+s: asked once whether to store the raw score only,
        y, stored, and not asked again."""
        term = self.term
        code, task, condition = block
        term.keys(*keys, "C-s")
        question = rf"{code} {task}/{condition}: no pairwise choices: store the raw"
        term.wait(question, 20)
        self.typed.raw_questions += 1
        term.keys("y")
        term.wait(rf"{code} {task}/{condition}: stored", 30)
        time.sleep(0.5)  # a second question would be up by now
        self.typed.raw_questions += bool(re.search(question, term.screen()))
        self.typed.tlx[block] = (ratings, None)
        self.typed.raw_only.add(block)
        return task, condition

    def session(self, code: str, position: int, last: bool = False, raw_only: int = -1) -> None:
        """Every block of `code`, one of them (at random) with a stopped trial first;
        block `raw_only` (if any) saved with its ratings only."""
        self.pick(code, position)
        order = []
        stopped = self.rng.randrange(len(TASK_BLOCKS))
        for k in range(len(TASK_BLOCKS)):
            order.append(
                self.run_block(
                    code,
                    last=last and k == len(TASK_BLOCKS) - 1,
                    stop=k == stopped,
                    raw_only=k == raw_only,
                )
            )
        self.typed.blocks[code] = order
        if not last:
            self.term.keys("F3")
            self.term.wait(rf"{code}: every scheduled trial is done", 20)


def _under_cursor(screen: str) -> str | None:
    """The participant whose detail shows below the participants list."""
    detail = re.search(r"^ (P\d{3}) \(", screen, re.MULTILINE)
    return detail.group(1) if detail else None


def _pairs(screen: str) -> dict[int, tuple[str, str]]:
    """The pair lines on the screen: number -> (left, right) subscales. A notification
    may cover the end of a line: a right-hand title cut short counts if what is left of
    it (3 characters or more) starts one title only."""
    found = {}
    for line in screen.splitlines():
        m = PAIR_LINE.match(line.split("▌")[0])
        if not m or m.group(2) not in TITLES:
            continue
        right = m.group(3).strip()
        names = [t for t in TITLES if t == right or (len(right) >= 3 and t.startswith(right))]
        if len(names) == 1:
            found[int(m.group(1))] = (TITLES[m.group(2)], TITLES[names[0]])
    return found


def run_lab_day(
    workdir: Path,
    participants: int = 10,
    pace: float = 200.0,
    seed: int = 0,
    typing_s: float = 5.0,
    stop_within_s: float = 12.0,
) -> dict:
    """The whole day in `workdir`; returns what was typed and the figures of the run."""
    from db.migrate import open_database
    from study.protocol.design import parse_design
    from study.protocol.roster import create_study

    started = time.monotonic()
    rng = random.Random(seed)
    groups = split_groups(participants)
    text = design_text(groups)
    db = workdir / "lab.db"
    engine = open_database(str(db), create=True)
    create_study(engine, parse_design(text), text)
    engine.dispose()

    enrolment = [g for g, n in groups.items() for _ in range(n)]
    rng.shuffle(enrolment)
    codes = [f"P{k + 1:03d}" for k in range(participants)]
    day = LabDay(db, workdir, pace, rng, typing_s, stop_within_s)
    day.start()
    try:
        for code, group in zip(codes[:-1], enrolment[:-1], strict=True):
            with day.timed("enrolment"):
                day.enrol(code, group)
        with day.timed("enrolment"):  # the last one from the command line, the app open
            day.enrol_from_command_line(codes[-1], enrolment[-1])
        with day.timed("find words"):
            day.search_words()
        restart_after = math.ceil(participants / 2) - 1
        raw_only = rng.randrange(len(TASK_BLOCKS))  # the first participant's raw-only block
        for k, code in enumerate(codes):
            last = k == participants - 1
            day.session(code, k, last=last, raw_only=raw_only if k == 0 else -1)
            with day.timed("notes"):
                day.note(code, f"{rng.choice(NOTE_WORDS)} {rng.choice(NOTE_WORDS)} {k}")
            if k == restart_after and not last:  # the app quit and started again
                with day.timed("quit and start"):
                    day.quit()
                    day.start()
        day.quit(unsaved="{} {}/{}".format(*day.typed.unsaved))
    finally:
        if day.term is not None:
            day.term.close()
    return {
        "typed": day.typed,
        "db": db,
        "seconds": time.monotonic() - started,
        "seed": seed,
        "retried_keys": day.retried_keys,
        "parts_s": day.seconds,
    }


def expected_found(typed: Typed, word: str) -> list[str]:
    """The codes whose row holds `word` when it was typed (before any block was run):
    the code or the group; no one was withdrawn or done then."""
    return [c for c, g in sorted(typed.groups.items()) if word.lower() in (c + " " + g).lower()]


def compare(db: Path, typed: Typed) -> list[str]:
    """Every difference between the database (and the screen) and what was typed, one
    line each."""
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from db.migrate import open_database
    from db.models.audit import AuditEntry
    from db.models.study import Participant
    from db.models.tlx import TlxResponse
    from db.models.trial import Trial

    wrong = _compare_screen(typed)
    engine = open_database(str(db), create=False)
    try:
        with Session(engine) as session:
            people = {p.code: p for p in session.scalars(select(Participant))}
            groups = {c: p.group for c, p in people.items()}
            if groups != typed.groups:
                wrong.append(f"groups: stored {groups}, enrolled {typed.groups}")
            notes = {c: p.note for c, p in people.items() if p.note}
            if notes != typed.notes:
                wrong.append(f"notes: stored {notes}, typed {typed.notes}")
            wrong += [f"{c} withdrawn" for c, p in people.items() if p.withdrawn_at is not None]
            stored = {}
            for r in session.scalars(select(TlxResponse)):
                block = (r.participant.code, r.task, r.condition)
                ratings = {s: getattr(r, s) for s in SUBSCALES}
                pairs = [tuple(p) for p in r.pairwise] if r.pairwise else None
                stored[block] = (ratings, pairs)
            wrong += _compare_tlx(stored, typed)
            audit = {
                e.entity_id: e.reason
                for e in session.scalars(
                    select(AuditEntry).where(
                        AuditEntry.entity == "trial", AuditEntry.new_value == "interrupted"
                    )
                )
            }
            trials = session.scalars(select(Trial).order_by(Trial.id)).all()
            for code in typed.groups:
                mine = [t for t in trials if t.participant.code == code]
                wrong += _compare_trials(code, mine, typed, audit)
    finally:
        engine.dispose()
    return wrong


def _compare_screen(typed: Typed) -> list[str]:
    """What the screen showed against what it should have: stops answered, no dialog
    from a typed word, the rows a word finds, the raw-only question once, the form's
    header in view."""
    wrong = [f"stop lost: {line}" for line in typed.lost_stops]
    wrong += [f"a dialog opened while a word was typed on F2: {w!r}" for w in typed.dialogs]
    for word in HINT_WORDS:
        if typed.found.get(word) != expected_found(typed, word):
            wrong.append(
                f"Find {word!r}: the list showed {typed.found.get(word)}, "
                f"expected {expected_found(typed, word)}"
            )
    if typed.raw_questions != len(typed.raw_only):
        wrong.append(
            f"the raw-only question seen {typed.raw_questions} times for "
            f"{len(typed.raw_only)} raw-only saves"
        )
    walked = len(typed.tlx) - len(typed.raw_only)
    if typed.headers_in_view != walked:
        wrong.append(
            f"participant and block lines in view at the form's end in {typed.headers_in_view}"
            f" of {walked} forms"
        )
    return wrong


def _compare_tlx(stored: dict, typed: Typed) -> list[str]:
    wrong = []
    for block in sorted(set(stored) | set(typed.tlx)):
        if block not in typed.tlx:
            wrong.append(f"{block}: a questionnaire stored for a block never saved")
            continue
        if block not in stored:
            wrong.append(f"{block}: typed and saved, not stored")
            continue
        (got_ratings, got_pairs), (ratings, pairs) = stored[block], typed.tlx[block]
        for s in SUBSCALES:
            if got_ratings[s] != ratings[s]:
                wrong.append(f"{block} {s}: stored {got_ratings[s]}, typed {ratings[s]}")
        if pairs is None or got_pairs is None:
            if pairs != got_pairs:
                wrong.append(f"{block} pairs: stored {got_pairs}, typed {pairs}")
            continue
        for k, (got, want) in enumerate(zip(got_pairs, pairs, strict=True)):
            if got != want:
                wrong.append(f"{block} pair {k + 1}: stored {got}, typed {want}")
    return wrong


def _compare_trials(code: str, mine: list, typed: Typed, audit: dict[int, str | None]) -> list:
    """`code`'s trials: one completed in each block, in the order run; the stopped one
    stored interrupted with its reason audited, its block's completed trial attempt 2."""
    wrong = []
    done = [t for t in mine if t.status == "completed"]
    run = [(t.task, t.condition) for t in done]
    if run != typed.blocks.get(code):
        wrong.append(f"{code}: trials {run}, blocks run {typed.blocks.get(code)}")
    if sorted(run) != sorted(tuple(b.split("/")) for b in TASK_BLOCKS):
        wrong.append(f"{code}: trials {run}; expected one in each block")
    stop = typed.stops.get(code)
    for t in done:
        attempt = 2 if stop is not None and (t.task, t.condition) == stop[:2] else 1
        if (t.driver, t.trial_index, t.attempt) != ("simulated", 0, attempt):
            wrong.append(
                f"{code} {t.task}/{t.condition}: trial {t.driver} index {t.trial_index} "
                f"attempt {t.attempt}; expected simulated 0 attempt {attempt}"
            )
    stopped = [t for t in mine if t.status != "completed"]
    want = [] if stop is None else [(stop[0], stop[1], "interrupted")]
    if [(t.task, t.condition, t.status) for t in stopped] != want:
        wrong.append(
            f"{code}: not completed {[(t.task, t.condition, t.status) for t in stopped]}, "
            f"stopped {want}"
        )
    for t in stopped:
        reason = f"{STOPPED_REASON}: {stop[2]}" if stop is not None else None
        if audit.get(t.id) != reason:
            wrong.append(f"{code} trial {t.id}: audited {audit.get(t.id)!r}, typed {reason!r}")
    return wrong


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--participants", type=int, default=10)
    parser.add_argument("--pace", type=float, default=200.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--typing-s", type=float, default=5.0, help="seconds to type a stop's reason"
    )
    parser.add_argument(
        "--stop-within-s",
        type=float,
        default=12.0,
        help="x at a moment drawn from this many first seconds of the trial (at 1x)",
    )
    parser.add_argument(
        "--keep", type=Path, help="folder to run in and keep (default: a temporary one)"
    )
    args = parser.parse_args(argv)
    if args.participants < 3:
        parser.error(f"--participants {args.participants}; expected 3 or more (three groups)")
    workdir = args.keep or Path(tempfile.mkdtemp(prefix="labday-"))
    workdir.mkdir(parents=True, exist_ok=True)
    result = run_lab_day(
        workdir, args.participants, args.pace, args.seed, args.typing_s, args.stop_within_s
    )
    wrong = compare(result["db"], result["typed"])
    typed = result["typed"]
    print(
        f"lab day: {args.participants} participants, {len(typed.tlx)} questionnaires typed "
        f"and saved (+1 typed in part, not saved), {sum(map(len, typed.blocks.values()))} "
        f"blocks run at pace {args.pace:g}, {result['seconds']:.0f} s; "
        f"{len(wrong)} differences from what was typed"
    )
    print(
        f"  stops: {len(typed.stops)} stored interrupted with their reason typed in "
        f"{args.typing_s:g} s, {len(typed.lost_stops)} lost; Find words: "
        + ", ".join(f"{w} {len(typed.found.get(w, []))} rows" for w in HINT_WORDS)
        + f"; raw-only saves {len(typed.raw_only)} (asked {typed.raw_questions} times); "
        + "enrolled from the command line: "
        + ", ".join(f"{c} on the list {s:.2f} s after" for c, s in typed.cli.items())
        + f"; keys lost in Find: {typed.lost_keys or 'none'}"
    )
    parts = ", ".join(f"{k} {v:.0f} s" for k, v in result["parts_s"].items())
    print(f"  time: {parts}; keys pressed again: {result['retried_keys']}")
    for line in wrong:
        print("  " + line)
    if args.keep is None:
        shutil.rmtree(workdir, ignore_errors=True)
    return 1 if wrong else 0


if __name__ == "__main__":
    raise SystemExit(main())
