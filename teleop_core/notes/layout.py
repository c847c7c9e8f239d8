"""The NOTES loop's sample rows, by name in the order the loop writes them: plain
constants in a module of their own (the task's declaration reads them without the
tissue's numerics)."""

from __future__ import annotations

from teleop_core.loop.layout import SAMPLE_COLUMNS as LOOP_SAMPLE_COLUMNS

SAMPLE_COLUMNS = (
    *LOOP_SAMPLE_COLUMNS[:6],
    "region",
    "force_demanded_n",
    "force_rendered_n",
    "tip_force_n",
    "dial_angle_rad",
    "torque_rendered_n_m",
    "torque_demanded_n_m",
)
"""Per sample, under the names the NOTES task stores them by: the loop's pose columns
(`teleop_core.loop.layout.SAMPLE_COLUMNS`), the region's code, the force the tissue
demands and the force the device renders, the tissue's force on the tip (fornix or
fold), the dial's angle, the torque rendered and the torque demanded."""
