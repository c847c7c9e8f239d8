"""One progress protocol (`teleop_core.progress.Progress`): its helpers, every long
function taking it, and the command line's adapters."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from teleop_core.progress import as_step, describe, no_progress

ROOT = Path(__file__).resolve().parents[2]


def test_describe_writes_the_count_only_when_there_is_one() -> None:
    assert describe("samples", 3, 10) == "samples (3/10)"
    assert describe("compiling the loop") == "compiling the loop"
    assert describe("samples", 0, 0) == "samples"


def test_as_step_names_the_part_and_keeps_the_count() -> None:
    seen: list[tuple[str, int, int]] = []
    told = as_step(lambda step, done=0, total=0: seen.append((step, done, total)), "emulator")
    told("simulating", 2, 5)
    told("simulating")
    assert seen == [("emulator", 2, 5), ("emulator", 0, 0)]
    assert no_progress("anything", 1, 2) is None


def test_every_progress_parameter_is_the_one_protocol() -> None:
    """No long function declares its own callback shape: a parameter named `progress`
    is annotated `Progress` everywhere in the packages."""
    other = []
    for package in ("study", "teleop_core", "db", "examples"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    a = node.args
                    for arg in [*a.posonlyargs, *a.args, *a.kwonlyargs]:
                        annotation = ast.unparse(arg.annotation) if arg.annotation else None
                        if arg.arg == "progress" and annotation != "Progress":
                            other.append(f"{path.relative_to(ROOT)}:{node.lineno} {annotation}")
    assert other == []


def test_power_counts_every_simulated_study_over_all_scales() -> None:
    """`study power`'s curve: 4 studies at each of 2 sizes are told as 1..8 of 8."""
    from study.analysis.power import power_curve

    seen: list[tuple[str, int, int]] = []
    power_curve(
        {"a": 6, "b": 6},
        {"a": 0.5, "b": 0.5},
        0.5,
        4,
        0,
        lambda step, done=0, total=0: seen.append((step, done, total)),
        scales=(0.5, 1.0),
    )
    assert seen == [("simulated studies", k, 8) for k in range(1, 9)]


def test_the_command_line_bar_follows_the_count_and_names_the_step() -> None:
    from study.commands.base import bar_progress, progress_bar

    with progress_bar() as bar:
        task = bar.add_task("start", total=None)
        told = bar_progress(bar, task)
        told("samples", 3, 10)
        state = bar.tasks[0]
        assert (state.description, state.completed, state.total) == ("samples", 3, 10)
        told("writing the files")  # no count: the bar keeps its own
        state = bar.tasks[0]
        assert (state.description, state.completed, state.total) == ("writing the files", 3, 10)
        quiet = bar.add_task("kept", total=None)
        bar_progress(bar, quiet, describe=False)("rows", 5, 7)
        assert (bar.tasks[1].description, bar.tasks[1].completed) == ("kept", 5)


@pytest.mark.parametrize(
    ("done", "total", "line"), [(2, 4, "demo: trials (2/4)"), (0, 0, "demo: trials")]
)
def test_the_status_line_shows_the_step_and_its_count(done: int, total: int, line: str) -> None:
    from study.commands.base import status_progress

    class Status:
        text = ""

        def update(self, text: str) -> None:
            self.text = text

    status = Status()
    status_progress(status, "demo: ")("trials", done, total)  # type: ignore[arg-type]
    assert status.text == line


class FakeClock:
    """Monotonic seconds that move only when told."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_heartbeat_writes_what_is_done_and_what_remains_every_interval() -> None:
    from teleop_core.progress import Heartbeat

    clock, lines = FakeClock(), []
    beat = Heartbeat(lines.append, "study demo", 10.0, clock)
    beat("sessions", 0, 36)
    clock.now += 9.9
    assert not beat.poll()
    clock.now += 0.1  # 10 s after the start
    assert beat.poll()
    beat("sessions", 12, 36)
    clock.now += 10.0  # 20 s: 12 done in 20 s, so 24 more take about 40 s
    assert beat.poll()
    assert lines == [
        "study demo: sessions: 0/36 done, 36 to go; 10 s elapsed",
        "study demo: sessions: 12/36 done, 24 to go; 20 s elapsed, about 40 s left",
    ]
    # a step without a count: what runs and the time; nothing twice within the interval
    beat.update("analysis and figures")
    clock.now += 65.0
    assert beat.poll()
    assert not beat.poll()
    assert lines[-1] == "study demo: analysis and figures; 1 min 25 s elapsed"


def test_a_heartbeats_thread_beats_while_the_work_reports_nothing() -> None:
    import time

    from teleop_core.progress import Heartbeat

    lines: list[str] = []
    with Heartbeat(lines.append, "work", interval_s=0.05) as beat:
        beat("one long step")
        time.sleep(0.6)
    written = len(lines)
    time.sleep(0.2)
    assert written >= 3  # about 12 at 0.05 s; a loaded machine may give fewer
    assert len(lines) == written  # none after the block
    assert all(line.startswith("work: one long step; ") for line in lines)


def test_a_bar_off_the_terminal_writes_its_tasks_counts() -> None:
    from io import StringIO

    from rich.console import Console

    from study.commands.progress_lines import LineProgress

    out = StringIO()
    console = Console(file=out, force_terminal=False)
    with LineProgress(console=console, interval_s=3600.0) as bar:
        task = bar.add_task("calibration", total=None, what="", unit="families")
        bar.update(task, completed=3, total=8, what="round 1: stribeck")
        clock = FakeClock()
        bar.heartbeat.clock, bar.heartbeat.last_s = clock, clock.now - 3600.0
        assert bar.heartbeat.poll()
    line = out.getvalue().strip()
    assert line.startswith("study: calibration (round 1: stribeck): 3/8 families, 5 to go")
    assert "\x1b" not in line  # plain text for a log file
