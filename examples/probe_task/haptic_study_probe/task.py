"""The probe task as haptic-study sees it: its declaration (regions, sample columns,
measures) and the three hooks of a `Task`. The entry point `haptic_study.tasks: probe`
names `TASK`; the registry registers it when a design or a command asks for the task.
How the run screen and the figures draw it is in `live.py` and `figures.py`.
"""

from __future__ import annotations

from haptic_study_probe.loop import AIM_RAD, ProbeDriver, ProbeLoop
from study.protocol.tasks import Measure, SampleColumn, Task, TaskDeclaration, pose_columns

DECLARATION = TaskDeclaration(
    name="probe",
    title="Probe insertion",
    regions=("medium", "depth"),
    sample_columns=(
        *pose_columns(
            "probe depth",
            "probe roll (none)",
            "tip position",
            insertion_name="depth_m",
            rotation_name="roll_rad",
        ),
        SampleColumn("where", "", "medium or at depth"),
        SampleColumn("push_force_n", "N", "the medium's push back"),
        SampleColumn("aim_rad", "rad", "the hand's aim"),
        SampleColumn("medium_speed_m_s", "m/s", "the probe's speed through the medium"),
    ),
    measures=(
        Measure(
            "peak_push_force_n",
            "N",
            "peak push force",
            "largest push of the medium",
            max_value=10.0,
        ),
    ),
    region_column="where",
)


class ProbeTask(Task):
    declaration = DECLARATION

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
