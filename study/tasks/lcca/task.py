"""The LCCA task: a guidewire from the descending aorta into the left common carotid
([endovascular]), driven by the friction-wheel robot through the haptic dial.

Its trials are `study.tasks.lcca.trial` (loop, simulated participant, measures);
this module says what they are to the rest of the tool (`study.protocol.tasks`).
"""

from __future__ import annotations

from typing import Any, ClassVar

from study.protocol.tasks import LiveTrace, Measure, SampleColumn, Task, pose_columns, register

MAX_FORCE_N = 20.0
"""Largest peak force the guidewire drive can produce, N; beyond it an imported value is
a typo or a unit slip: the drive (K_t 0.043 N m/A, wheel radius 10 mm) would need
4.7 A, above a 2804 gimbal motor's rating (assumption, see teleop_core.follower.params)."""


class LccaTask(Task):
    name = "lcca"
    title = "LCCA guidewire navigation"
    has_dial = True
    default_haptic_gain_n_m_per_n = 0.02
    """The paper's G_h (`teleop_core.master.params.HapticParams`; a test keeps them equal)."""
    has_link = True
    regions = ("DAo", "arch", "AAo", "LSA", "LCCA", "BCT")
    """`teleop_core.phantom.anatomy.REGION_ABBREVIATIONS` (a test keeps them equal)."""
    sample_columns = (
        *pose_columns("guidewire inserted", "guidewire roll", "tip position, phantom frame"),
        SampleColumn("branch", "branch", "", "vessel the tip is in (DAo, arch, ...)"),
        SampleColumn(
            "reference_force_n",
            "proximal_force_n",
            "N",
            "true proximal insertion force (simulation) or reference sensor",
        ),
        SampleColumn(
            "proximal_force_n",
            "proximal_force_est_n",
            "N",
            "proximal force estimated from the motor current (what is rendered)",
        ),
        SampleColumn("distal_force_n", "distal_force_n", "N", "tip force on the vessel wall"),
        SampleColumn("dial_angle_rad", "dial_angle_rad", "rad", "haptic dial angle"),
        SampleColumn("dial_torque_n_m", "dial_torque_n_m", "N m", "torque on the hand"),
    )
    measures = (
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
    live_traces = (
        LiveTrace("proximal_force_n", "proximal", 2.0),
        LiveTrace("distal_force_n", "distal", 1.0),
    )
    live_peaks = live_traces
    live_scene = "study.tasks.lcca.scene:PhantomView"
    live_scene_title = "LCCA phantom (frontal)"
    key_hints = "↑↓ dial ←→ rotate space let go e end"
    trace_names: ClassVar[dict[str, str]] = {
        "reference_force_n": "proximal, reference",
        "proximal_force_n": "proximal, estimated",
        "distal_force_n": "distal (tip on wall)",
    }
    sign_note = (
        "Proximal force: positive resists insertion (pushing the wire in), negative "
        "resists withdrawal. Distal force: tip-wall contact, ≥\u00a00."
    )

    def haptic_gain(self, gain_n_m_per_n: float | None) -> float | None:
        """`gain_n_m_per_n` (finite, >= 0 N m/N), else the paper's G_h."""
        from study.tasks.lcca.trial import condition_haptics

        gain = super().haptic_gain(gain_n_m_per_n)
        if gain is not None:
            condition_haptics("HV", gain)
        return gain

    def session_context(self) -> Any:
        from teleop_core.phantom.lcca import LccaPhantom

        return LccaPhantom()

    def trial_figure(self, frame, title):
        from study.tasks.lcca.figures import plot_trial
        from teleop_core.phantom.lcca import LccaPhantom

        return plot_trial(frame, LccaPhantom(), title)

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

    fit_features = (
        "advance_speed_m_s",
        "approach_m",
        "approaches",
        "target_speed_ratio",
        "aim_error_rad",
        "turn_peak_s",
        "turn_swing_s",
        "stall_s",
        "stall_backoffs",
        "peak_felt_rise_n_m",
    )
    """`study.tasks.lcca.features.FEATURES` (a test keeps them equal)."""

    def trial_features(self, frame, context):
        from study.tasks.lcca.features import lcca_features
        from teleop_core.master.params import HapticParams
        from teleop_core.phantom.anatomy import REGION_ABBREVIATIONS, REGIONS

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

    def live_lines(self, values, condition=None):
        # VO renders no force on the dial: the stored torque is the return spring's and
        # the model's, none of it felt as feedback
        torque = (
            "torque on the hand: none (VO, no haptic feedback)"
            if condition == "VO"
            else f"torque on the hand {values['dial_torque_n_m'] * 1000:+5.1f} mN m"
        )
        return [
            f"tip in {self.regions[int(values['branch'])]}, inserted "
            f"{values['insertion_m'] * 1000:5.0f} mm",
            f"rotation {values['rotation_rad']:+5.2f} rad",
            f"dial {values['dial_angle_rad']:+5.2f} rad",
            torque,
        ]


TASK = register(LccaTask())
