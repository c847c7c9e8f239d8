"""The app's pure parts: what is next in a schedule, the Braille canvas, the gauges."""

from __future__ import annotations

import numpy as np

from study.protocol.tasks import get_task
from study.tui.live_view import BrailleCanvas, gauge, sparkline
from study.tui.scene_lcca import PhantomFrame
from study.tui.scene_notes import notes_scene
from study.tui.services import Roster
from study.tui.trial_runner import LiveFrame, LiveState
from teleop_core.notes.layout import SAMPLE_COLUMNS as NOTES_COLUMNS
from teleop_core.notes.regions import REGIONS
from teleop_core.phantom.anatomy import ArchAnatomy


def _roster(completed: list[int], practice: int = 1, per_block: int = 3) -> Roster:
    blocks = [
        {
            "block_index": k,
            "task": "lcca",
            "condition": c,
            "planned": per_block,
            "completed": n,
            "interrupted": 0,
        }
        for k, (c, n) in enumerate(zip(("VO", "HV"), completed, strict=True))
    ]
    row = {
        "code": "P001",
        "group": "novice",
        "site": None,
        "condition_order": ["VO", "HV"],
        "trials_planned": 2 * per_block,
        "trials_completed": sum(completed),
        "blocks": blocks,
    }
    return Roster("s", 1, practice, {"novice": {"target": 2, "enrolled": 1}}, [row])


def test_next_trial_walks_practice_then_measured_trials_block_by_block() -> None:
    # 1 practice + 2 measured per block (planned 3): by hand, completed k -> the (k+1)-th
    assert _roster([0, 0]).next_trial("P001").describe() == "lcca/VO practice 1"
    assert _roster([1, 0]).next_trial("P001").describe() == "lcca/VO trial 1"
    assert _roster([2, 0]).next_trial("P001").describe() == "lcca/VO trial 2"
    nxt = _roster([3, 1]).next_trial("P001")
    assert (nxt.describe(), nxt.remaining) == ("lcca/HV trial 1", 2)
    assert _roster([3, 3]).next_trial("P001") is None
    assert _roster([0, 0]).next_trial("P999") is None


def test_what_next_puts_due_questionnaires_first_and_names_groups_to_fill() -> None:
    roster = _roster([3, 1])
    assert roster.tlx_due() == [("P001", "lcca", "VO")]
    assert roster.what_next() == [
        "NASA-TLX due: P001 lcca/VO",
        "next trial: P001 lcca/HV trial 1",
        "enrol: 1 more novice",
    ]
    answered = Roster("s", 1, 1, roster.groups, roster.participants, {("P001", "lcca", "VO")})
    assert answered.tlx_due() == []


def test_braille_dots_follow_the_unicode_pattern() -> None:
    # Unicode Braille Patterns: dot 1 (top left) = U+2801, dot 8 (bottom right) = U+2880,
    # dots 1-8 all = U+28FF
    canvas = BrailleCanvas(2, 1)
    canvas.dot(0, 0)
    canvas.dot(3, 3)
    assert canvas.to_text().plain == "\u2801\u2880"
    for x in range(2):
        for y in range(4):
            canvas.dot(x, y)
    assert canvas.to_text().plain[0] == "\u28ff"
    canvas.dot(99, 99)  # off the canvas: ignored
    assert canvas.to_text().plain == "\u28ff\u2880"


def test_phantom_frame_keeps_the_arch_shape_on_one_scale() -> None:
    anatomy = ArchAnatomy()
    frame = PhantomFrame(anatomy, 40, 17)
    # the arch's top (x = -r, z = L + r) and its two feet (x = 0 and -2r at z = L) are
    # r above the feet on one scale in both axes
    r, length = anatomy.arch_radius_m, anatomy.descending_length_m
    top, left, right = (
        frame.to_dot(-r, length + r),
        frame.to_dot(0, length),
        frame.to_dot(-2 * r, length),
    )
    assert abs((left[1] - top[1]) - r * frame.scale) <= 1
    assert abs((left[0] - right[0]) - 2 * r * frame.scale) <= 1
    assert 0 <= right[0] < left[0] < 80
    assert 0 <= top[1] < 68


def test_gauge_and_sparkline_scale() -> None:
    bar = gauge("distal", 0.5, 1.0, 10).plain
    assert bar.count("█") == 5
    assert bar.count("░") == 5
    assert "0.50 N" in bar
    assert gauge("distal", 3.0, 1.0, 10).plain.count("█") == 10
    # maximum of each bin, on eight levels: 0 -> lowest, full scale -> highest
    assert sparkline((0.0, 0.0, 1.0, 0.5), 2, 1.0) == "▁█"
    assert sparkline((), 5, 1.0) == ""
    # NOTES pulls: the bar by magnitude, the number signed
    pull = gauge("demanded", -4.0, 10.0, 10, magnitude=True).plain
    assert pull.count("█") == 4
    assert "-4.00 N" in pull


def test_notes_scene_puts_the_tip_fornix_and_targets_on_their_columns() -> None:
    # 45 columns: depth 0-220 mm (target 200 mm + 20), roll -90..+90 deg, each over 44 steps
    task = get_task("notes")
    values = {c.name: 0.0 for c in task.sample_columns} | {
        "t_s": 1.0,
        "tip_x_m": 0.11,
        "region": REGIONS.index("canal"),
        "insertion_m": 0.11,
        "force_demanded_n": 1.0,
    }
    frame = LiveFrame(task, values, (), ())
    lines = notes_scene(frame, 45).plain.split("\n")
    assert lines[0].startswith("depth   110 mm   in the canal")
    axis, scope = lines[1], lines[2]
    assert axis.index("┃") == 18  # the fornix: 44 x 90/220 = 18.0
    # the target zone, 190-210 mm: 44 x 190/220 = 38.0 to 44 x 210/220 = 42.0
    assert [k for k, ch in enumerate(axis) if ch == "▓"] == [38, 39, 40, 41, 42]
    assert scope == "━" * 22 + "●"  # 110 mm: 44 x 110/220 = 22.0
    roll_axis = lines[6]
    # roll 0 sits on the zero mark (column 22); the target zone, 50-70 deg:
    # 44 x 140/180 = 34.2 -> 34 to 44 x 160/180 = 39.1 -> 39
    assert roll_axis.index("●") == 22
    assert "┼" not in roll_axis
    assert [k for k, ch in enumerate(roll_axis) if ch == "▓"] == list(range(34, 40))


def test_live_state_reads_notes_samples_the_notes_way() -> None:
    # two NOTES samples: a push of 3 N demanded (2.5 rendered), then a pull of -6 N
    col = {name: k for k, name in enumerate(NOTES_COLUMNS)}
    samples = np.zeros((2, len(NOTES_COLUMNS)))
    for k, (demanded, rendered, tip, torque) in enumerate(
        ((3.0, 2.5, 1.0, 0.02), (-6.0, -5.6, 0.0, -0.05))
    ):
        samples[k, col["t_s"]] = 0.01 * (k + 1)
        samples[k, col["force_demanded_n"]] = demanded
        samples[k, col["force_rendered_n"]] = rendered
        samples[k, col["tip_force_n"]] = tip
        samples[k, col["torque_demanded_n_m"]] = torque
        samples[k, col["insertion_m"]] = 0.05 * (k + 1)
    live = LiveState()
    live.start(get_task("notes"))
    live.push(samples)
    frame = live.frame()
    assert frame.task.name == "notes"
    v = frame.values
    assert (v["force_demanded_n"], v["force_rendered_n"], v["torque_demanded_n_m"]) == (
        -6.0,
        -5.6,
        -0.05,
    )
    assert frame.insertion_m == 0.1
    # the traces are magnitudes; the peaks are as the NOTES summary's (max |.|)
    assert frame.first_history == (3.0, 6.0)
    assert frame.second_history == (2.5, 5.6)
    assert live.peaks == [6.0, 1.0]


def test_the_simulation_prepares_in_a_daemon_thread_that_an_exit_does_not_wait_for() -> None:
    import threading

    from study.tui.trial_runner import Simulation

    seen: list[object] = []
    started = threading.Event()
    release = threading.Event()

    def load() -> object:
        started.set()
        release.wait(10)
        return "estimator"

    sim = Simulation(load)
    sim.ready = lambda: load()  # type: ignore[method-assign]  (no loop compiled here)
    sim.prepare_in_background(lambda: seen.append("done"), seen.append)
    assert started.wait(10)
    [thread] = [t for t in threading.enumerate() if t.name == "prepare-simulation"]
    assert thread.daemon  # the interpreter's exit does not wait for it
    release.set()
    thread.join(10)
    assert seen == ["done"]

    # a failure is handed to `failed`; a callback into an app that has gone is dropped
    def broken() -> object:
        raise OSError("estimator folder unreadable")

    def gone() -> None:
        raise RuntimeError("the app is not running")

    sim.ready = broken  # type: ignore[method-assign]
    sim.prepare_in_background(gone, seen.append)
    sim.prepare_in_background(gone, lambda exc: gone())
    for t in [t for t in threading.enumerate() if t.name == "prepare-simulation"]:
        t.join(10)
    assert [str(e) for e in seen[1:]] == ["estimator folder unreadable"]
