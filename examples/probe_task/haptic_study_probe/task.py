"""The probe task as haptic-study sees it: its regions, sample columns, measures, live
traces and figure. The entry point `haptic_study.tasks: probe` names `TASK`; the
registry registers it when a design or a command asks for the task.
"""

from __future__ import annotations

from typing import ClassVar

from haptic_study_probe.loop import AIM_RAD, ProbeDriver, ProbeLoop
from study.protocol.tasks import LiveTrace, Measure, SampleColumn, Task, pose_columns


class ProbeTask(Task):
    name = "probe"
    title = "Probe insertion"
    regions = ("medium", "depth")
    sample_columns = (
        *pose_columns(
            "probe depth",
            "probe roll (none)",
            "tip position",
            insertion_name="depth_m",
            rotation_name="roll_rad",
        ),
        SampleColumn("where", "branch", "", "medium or at depth"),
        SampleColumn("push_force_n", "proximal_force_n", "N", "the medium's push back"),
        SampleColumn("aim_rad", "dial_angle_rad", "rad", "the hand's aim"),
        SampleColumn("medium_speed_m_s", None, "m/s", "the probe's speed through the medium"),
    )
    measures = (
        Measure(
            "peak_push_force_n",
            "N",
            "peak push force",
            "largest push of the medium",
            max_value=10.0,
        ),
    )
    live_traces = (LiveTrace("push_force_n", "push", 2.0), LiveTrace("aim_rad", "aim", 1.0))
    live_peaks = live_traces
    trace_names: ClassVar[dict[str, str]] = {"push_force_n": "push (medium)"}
    sign_note = "Push force: positive resists insertion."
    track_length_m = 0.1

    def make_loop(
        self,
        condition,
        seed,
        *,
        haptic_gain_n_m_per_n=None,
        estimator=None,
        context=None,
        link=None,
    ):
        return ProbeLoop(condition)

    def simulated_driver(self, traits, max_s, context):
        return ProbeDriver(AIM_RAD)

    def trial_measures(self, samples, success):
        push = self.column_index()["push_force_n"]
        return {"peak_push_force_n": float(samples[:, push].max())}, {}


TASK = ProbeTask()
