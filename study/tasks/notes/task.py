"""The NOTES task: the 2-DOF haptic device rolling and pushing an endoscope through the
posterior fornix to a target in the abdomen ([notes]).

Its trials are `study.tasks.notes.trial` (loop, simulated participant, measures);
this module says what they are to the rest of the tool (`study.protocol.tasks`). The
device has no haptic dial gain: HV renders the tissue's resistance within the device's
continuous limits, VO nothing.
"""

from __future__ import annotations

from study.protocol.tasks import (
    Measure,
    Task,
    TaskDeclaration,
    described,
    pose_columns,
    register,
)
from teleop_core.notes.layout import SAMPLE_COLUMNS as NOTES_SAMPLE_COLUMNS
from teleop_core.notes.regions import REGIONS

MAX_FORCE_N = 25.0
"""Largest force the NOTES hand can push (`teleop_core.notes.task.HAND_MAX_FORCE_N`);
beyond it an imported value is a typo or a unit slip."""
SAMPLE_COLUMNS = described(
    NOTES_SAMPLE_COLUMNS,
    {
        **{
            c.name: (c.unit, c.description)
            for c in pose_columns("scope depth from the introitus", "scope roll", "tip position")
        },
        "region": ("", "where the tip is (canal, fornix, ...)"),
        "force_demanded_n": ("N", "tissue resistance on the scope, positive resisting insertion"),
        "force_rendered_n": ("N", "force the device renders (saturates at its continuous limit)"),
        "tip_force_n": ("N", "the tissue's push on the tip (the fornix or the fold)"),
        "dial_angle_rad": ("rad", "the hand's aim (rate input)"),
        "torque_rendered_n_m": ("N m", "torque rendered"),
        "torque_demanded_n_m": (
            "N m",
            "tissue resistance to roll, positive resisting clockwise roll",
        ),
    },
)
"""The NOTES loop's rows in the loop's order, under its names (the loop declares them
once: `teleop_core.notes.layout.SAMPLE_COLUMNS`), each with its unit and meaning."""
MEASURES = (
    Measure(
        "peak_force_demanded_n",
        "N",
        "peak demanded force",
        "largest |force| the tissue demanded of the scope",
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_tip_force_n",
        "N",
        "peak tip force",
        "largest force of the fornix or the fold on the tip",
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_force_rendered_n",
        "N",
        "peak rendered force",
        "largest |force| the device rendered",
        analysed=False,
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_torque_demanded_n_m",
        "N m",
        "peak demanded torque",
        "largest |torque| the tissue demanded",
        analysed=False,
    ),
    Measure(
        "peak_torque_rendered_n_m",
        "N m",
        "peak rendered torque",
        "largest |torque| the device rendered",
        analysed=False,
    ),
    Measure(
        "peak_push_n",
        "N",
        "peak push",
        "largest demanded push (force resisting insertion), as the surgeons' max push of [notes]",
        analysed=False,
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_pull_n",
        "N",
        "peak pull",
        "largest demanded pull (force resisting withdrawal), a magnitude",
        analysed=False,
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_torque_cw_n_m",
        "N m",
        "peak CW torque",
        "largest demanded torque resisting a clockwise roll",
        analysed=False,
    ),
    Measure(
        "peak_torque_ccw_n_m",
        "N m",
        "peak CCW torque",
        "largest demanded torque resisting a counter-clockwise roll, a magnitude",
        analysed=False,
    ),
    Measure(
        "push_over_capacity_fraction",
        "",
        "push over capacity",
        "share of samples with the demanded push above the device's continuous force (5.62 N)",
        analysed=False,
        max_value=1.0,
    ),
)
DECLARATION = TaskDeclaration(
    name="notes",
    title="NOTES endoscopy",
    regions=REGIONS,
    sample_columns=SAMPLE_COLUMNS,
    measures=MEASURES,
    region_column="region",
)


class NotesTask(Task):
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
        from study.tasks.notes.trial import notes_loop

        self.haptic_gain(haptic_gain_n_m_per_n)  # refuses a gain: the device has no dial
        return notes_loop(condition, seed)

    def summary_line(self, summary):
        return (
            f"peak force demanded {summary['peak_force_demanded_n']:.2f} N / rendered "
            f"{summary['peak_force_rendered_n']:.2f} N, peak torque demanded "
            f"{summary['peak_torque_demanded_n_m'] * 1e3:.1f} N mm / rendered "
            f"{summary['peak_torque_rendered_n_m'] * 1e3:.1f} N mm, push over capacity "
            f"{summary['push_over_capacity_fraction']:.1%} of the time"
        )

    def simulated_driver(self, traits, max_s, context):
        from study.tasks.notes.trial import NotesParticipant

        return NotesParticipant(traits, max_s)

    def trial_measures(self, samples, success):
        from study.tasks.notes.trial import measures

        result = measures(self.trial_frame(samples), success)
        stored = {m.name: result[m.name] for m in self.measures}
        extras = {"device_limits": result["device_limits"]}
        return stored, extras

    def driver_counts(self, driver):
        from study.tasks.notes.trial import NotesParticipant

        if not isinstance(driver, NotesParticipant):
            return {}
        # the person's state in this trial (their traits varied from trial to trial)
        state = {k: v for k, v in driver.traits.to_dict().items() if k != "group"}
        return {"stalls_seen": driver.stalls_seen, "trial_state": state}


TASK = register(NotesTask())
