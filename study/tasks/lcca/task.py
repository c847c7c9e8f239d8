"""The LCCA task: a guidewire from the descending aorta into the left common carotid
([endovascular]), driven by the friction-wheel robot through the haptic dial.

Its trials are `study.tasks.lcca.trial` (loop, simulated participant, measures);
this module says what they are to the rest of the tool (`study.protocol.tasks`).
"""

from __future__ import annotations

from typing import Any

from study.protocol.tasks import (
    Measure,
    Task,
    TaskDeclaration,
    described,
    pose_columns,
    register,
)
from study.tasks.lcca.feature_names import FIT_FEATURES
from teleop_core.loop.layout import SAMPLE_COLUMNS as LOOP_SAMPLE_COLUMNS
from teleop_core.master.params import HapticParams
from teleop_core.phantom.regions import REGION_ABBREVIATIONS, REGIONS

MAX_FORCE_N = 20.0
"""Largest peak force the guidewire drive can produce, N; beyond it an imported value is
a typo or a unit slip: the drive (K_t 0.043 N m/A, wheel radius 10 mm) would need
4.7 A, above a 2804 gimbal motor's rating (assumption, see teleop_core.follower.params)."""


SAMPLE_COLUMNS = described(
    LOOP_SAMPLE_COLUMNS,
    {
        **{
            c.name: (c.unit, c.description)
            for c in pose_columns(
                "guidewire inserted", "guidewire roll", "tip position, phantom frame"
            )
        },
        "branch": ("", "vessel the tip is in (DAo, arch, ...)"),
        "reference_force_n": (
            "N",
            "true proximal insertion force (simulation) or reference sensor",
        ),
        "proximal_force_n": (
            "N",
            "proximal force estimated from the motor current (what is rendered)",
        ),
        "distal_force_n": ("N", "tip force on the vessel wall"),
        "dial_angle_rad": ("rad", "haptic dial angle"),
        "dial_torque_n_m": ("N m", "torque on the hand"),
    },
)
"""The loop's rows in the loop's order, under its names (the loop declares them once:
`teleop_core.loop.layout.SAMPLE_COLUMNS`), each with its unit and meaning."""
MEASURES = (
    Measure(
        "peak_proximal_force_n",
        "N",
        "peak proximal force",
        "largest proximal insertion force (the drive's estimate)",
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "peak_distal_force_n",
        "N",
        "peak distal force",
        "largest distal force on the phantom",
        max_value=MAX_FORCE_N,
    ),
    Measure(
        "wall_contacts",
        "",
        "wall contacts",
        "times the distal force rose through 0.2 N",
        analysed=False,
        integer=True,
    ),
)
DECLARATION = TaskDeclaration(
    name="lcca",
    title="LCCA guidewire navigation",
    regions=REGION_ABBREVIATIONS,
    sample_columns=SAMPLE_COLUMNS,
    measures=MEASURES,
    region_column="branch",
    has_dial=True,
    # the paper's G_h
    default_haptic_gain_n_m_per_n=HapticParams().haptic_gain_n_m_per_n,
    has_link=True,
    fit_features=FIT_FEATURES,
)


class LccaTask(Task):
    declaration = DECLARATION

    def session_context(self) -> Any:
        from teleop_core.phantom.lcca import LccaPhantom

        return LccaPhantom()

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
        from study.tasks.lcca.trial import lcca_loop

        return lcca_loop(condition, seed, estimator, haptic_gain_n_m_per_n, context, link)

    def summary_line(self, summary):
        return (
            f"peak proximal {summary['peak_proximal_force_n']:.3f} N, "
            f"peak distal {summary['peak_distal_force_n']:.3f} N, "
            f"{summary['wall_contacts']} wall contacts"
        )

    def simulated_driver(self, traits, max_s, context):
        from study.tasks.lcca.simulated_participant import SimulatedParticipant

        return SimulatedParticipant(traits, context, max_s)

    def trial_measures(self, samples, success):
        from study.tasks.lcca.trial import measures

        result = measures(self.trial_frame(samples), success)
        stored = {m.name: result[m.name] for m in self.measures}
        return stored, {
            "peak_proximal_reference_force_n": result["peak_proximal_reference_force_n"]
        }

    def trial_features(self, frame, context):
        from study.tasks.lcca.features import lcca_features
        from teleop_core.master.params import HapticParams

        target = context.anatomy.target
        phi = next(b.phi_rad for b in context.anatomy.branches if b.name == target)
        # TRIAL.csv names regions in full, the samples table by their abbreviation
        names = {target, REGION_ABBREVIATIONS[REGIONS.index(target)]}
        route = {*names, *REGIONS[:3], *REGION_ABBREVIATIONS[:3]}  # the aorta, then the target
        spring = HapticParams().spring_n_m_per_rad
        return lcca_features(frame, context.ostium_m(target), phi, names, spring, route)

    def driver_counts(self, driver):
        from study.tasks.lcca.simulated_participant import SimulatedParticipant

        if isinstance(driver, SimulatedParticipant):
            # the person's state in this trial (their traits varied from trial to trial)
            state = {k: v for k, v in driver.traits.to_dict().items() if k != "group"}
            return {
                "attempts": driver.attempt,
                "obstacles_felt": driver.obstacles_felt,
                "obstacles_seen": driver.obstacles_seen,
                "trial_state": state,
            }
        return {}

    def trial_frame(self, samples):
        from study.tasks.lcca.trial import trial_frame

        return trial_frame(samples)


TASK = register(LccaTask())
