"""The app's pure parts: what is next in a schedule, the Braille canvas, the gauges."""

from __future__ import annotations

from study.tui.live_view import BrailleCanvas, PhantomFrame, gauge, sparkline
from study.tui.services import Roster
from teleop_core.phantom.anatomy import ArchAnatomy


def _roster(completed: list[int], practice: int = 1, per_block: int = 3) -> Roster:
    blocks = [
        {"block_index": k, "task": "lcca", "condition": c, "planned": per_block,
         "completed": n, "interrupted": 0}
        for k, (c, n) in enumerate(zip(("VO", "HV"), completed, strict=True))
    ]  # fmt: skip
    row = {
        "code": "P001", "group": "novice", "site": None, "condition_order": ["VO", "HV"],
        "trials_planned": 2 * per_block, "trials_completed": sum(completed), "blocks": blocks,
    }  # fmt: skip
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
    top, left, right = frame.to_dot(-r, length + r), frame.to_dot(0, length), frame.to_dot(
        -2 * r, length)  # fmt: skip
    assert abs((left[1] - top[1]) - r * frame.scale) <= 1
    assert abs((left[0] - right[0]) - 2 * r * frame.scale) <= 1
    assert 0 <= right[0] < left[0] < 80 and 0 <= top[1] < 68


def test_gauge_and_sparkline_scale() -> None:
    bar = gauge("distal", 0.5, 1.0, 10).plain
    assert bar.count("█") == 5 and bar.count("░") == 5 and "0.50 N" in bar
    assert gauge("distal", 3.0, 1.0, 10).plain.count("█") == 10
    # maximum of each bin, on eight levels: 0 -> lowest, full scale -> highest
    assert sparkline((0.0, 0.0, 1.0, 0.5), 2, 1.0) == "▁█"
    assert sparkline((), 5, 1.0) == ""
