"""The NOTES task's live scene, drawn beside the run screen's readout: the scope's depth
along the canal (introitus, posterior fornix, peritoneal cavity, target) and its roll
against the target roll (`notes_scene`), a widget redrawn whole at each frame. `VIEW` is
the NOTES task's view on the run screen (`study.tui.task_views`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from rich.text import Text

from study.protocol.tasks import LiveTrace, Task
from study.tui.live_view import TARGET_STYLE, TIP_STYLE
from study.tui.scenes import SceneView, axis_column
from study.tui.task_views import LiveView, register_view
from study.tui.trial_runner import LiveFrame

NOTES_DEPTH_PAST_TARGET_M = 0.02
"""How far past the NOTES target the depth axis runs."""
NOTES_ROLL_SPAN_RAD = math.pi / 2
"""The roll axis runs from -90 to +90 degrees."""
FULL_SCALE_N = 10.0
"""Full scale of the live force gauges: the surgeons' mean max push, 9.9 N, near which
the fornix tears (`teleop_core.notes.task.PUSH_BENCHMARK_N`)."""


def notes_region(code: int) -> str:
    from teleop_core.notes.regions import REGIONS

    return REGIONS[code] if 0 <= code < len(REGIONS) else "?"


def notes_scene(frame: LiveFrame | None, cols: int) -> Text:
    """The NOTES scope as text: its depth from the introitus and its roll, each on an axis
    with the posterior fornix and the target marked (`teleop_core.notes.task`)."""
    from teleop_core.notes.task import (
        FORNIX_M,
        TARGET_M,
        TARGET_ROLL_RAD,
        TARGET_ROLL_TOLERANCE_RAD,
        TARGET_TOLERANCE_M,
    )

    cols = max(cols, 20)
    end_m = TARGET_M + NOTES_DEPTH_PAST_TARGET_M
    depth = frame.insertion_m if frame is not None else 0.0
    roll = frame.rotation_rad if frame is not None else 0.0
    breached = frame is not None and notes_region(frame.branch) in ("cavity", "target", "fold")

    def column(depth_m: float) -> int:
        return axis_column(depth_m, 0.0, end_m, cols)

    def roll_column(roll_rad: float) -> int:
        return axis_column(roll_rad, -NOTES_ROLL_SPAN_RAD, NOTES_ROLL_SPAN_RAD, cols)

    def axis(marks: dict[int, tuple[str, str]], zone: range) -> None:
        """One axis line: `marks` (column -> character, style) over the target zone."""
        for c in range(cols):
            if c in marks:
                text.append(*marks[c])
            elif c in zone:
                text.append("▓", TARGET_STYLE)
            else:
                text.append("─", "dim")
        text.append("\n")

    text = Text(no_wrap=True, overflow="crop")
    where = f"in the {notes_region(frame.branch)}" if frame is not None else "(no sample yet)"
    text.append(f"depth {depth * 1000:5.0f} mm   {where}\n")
    # the canal, the fornix (dim once breached) and the target zone; then the scope
    fornix = column(FORNIX_M)
    target = range(column(TARGET_M - TARGET_TOLERANCE_M), column(TARGET_M + TARGET_TOLERANCE_M) + 1)
    axis({fornix: ("┃", "dim" if breached else "bold")}, target)
    text.append("━" * column(depth), "bold")
    text.append("●\n", TIP_STYLE)
    labels = [" "] * cols
    for at, word in ((0, "introitus"), (fornix, "fornix"), (target.start, "target")):
        for k, ch in enumerate(word[: max(cols - at, 0)]):
            labels[at + k] = ch
    text.append("".join(labels), "dim")
    # the roll: the scope's mark over the zero mark and the target zone
    text.append(
        f"\n\nroll {math.degrees(roll):+5.0f} deg   target "
        f"{math.degrees(TARGET_ROLL_RAD):+.0f} +/- {math.degrees(TARGET_ROLL_TOLERANCE_RAD):.0f}\n"
    )
    zero = roll_column(0.0)
    target_roll = range(
        roll_column(TARGET_ROLL_RAD - TARGET_ROLL_TOLERANCE_RAD),
        roll_column(TARGET_ROLL_RAD + TARGET_ROLL_TOLERANCE_RAD) + 1,
    )
    axis({zero: ("┼", "dim"), roll_column(roll): ("●", TIP_STYLE)}, target_roll)
    left = f"-{math.degrees(NOTES_ROLL_SPAN_RAD):.0f}"
    right = f"+{math.degrees(NOTES_ROLL_SPAN_RAD):.0f}"
    scale = (left + " " * max(zero - len(left), 1) + "0").ljust(cols - len(right))
    text.append(scale[: cols - len(right)] + right, "dim")
    return text


class NotesView(SceneView):
    """The NOTES scope's depth and roll (`notes_scene`)."""

    DEFAULT_CSS = """
    NotesView { width: 1fr; height: 1fr; min-height: 8; background: $surface; }
    """

    def scene(self, frame: LiveFrame | None, cols: int) -> Text:
        return notes_scene(frame, cols)


def notes_lines(task: Task, values: Mapping[str, float], condition: str | None) -> list[str]:
    """The readout: the fornix on the tip, the torque demanded and rendered."""
    rendered = (
        "torque rendered: none (VO, no haptic feedback)"
        if condition == "VO"
        else f"torque rendered {values['torque_rendered_n_m'] * 1000:+6.1f} mN m"
    )
    return [
        f"tip on the fornix {values['tip_force_n']:5.2f} N",
        f"torque demanded {values['torque_demanded_n_m'] * 1000:+6.1f} mN m",
        rendered,
    ]


VIEW = register_view(
    "notes",
    LiveView(
        traces=(
            LiveTrace("force_demanded_n", "demanded", FULL_SCALE_N, magnitude=True),
            LiveTrace("force_rendered_n", "rendered", FULL_SCALE_N, magnitude=True),
        ),
        peaks=(
            LiveTrace("force_demanded_n", "demanded", FULL_SCALE_N, magnitude=True),
            LiveTrace("tip_force_n", "on the fornix", FULL_SCALE_N, magnitude=True),
        ),
        scene=NotesView,
        scene_title="NOTES: scope depth and roll",
        keyboard_aim_label="insertion-speed aim",
        key_hints="↑↓ push/pull ←→ roll space let go e end",
        lines=notes_lines,
    ),
)
