"""One trial, run once: the loop a task builds, started with a driver and advanced to
its end or its time limit, then the task's measures of what it sampled.

`run_trial` is the only place a task's loop is stepped through a trial: `study
simulate`, the session runner (which streams every step to the database), the
campaigns, the participant fit and the benches all call it, so they cannot disagree
about what a trial is (its rendered haptic gain, its end, its measures). A caller that
must see each step (store it, pace it, stop it) passes `TrialSteps`; `simulate_trial`
is the headless trial of a simulated person with its TRIAL.csv frame and summary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from study.protocol.tasks import COMPLETION_TIME, Task, Traits, TrialLoop, TrialResult

if TYPE_CHECKING:
    from teleop_core.loop.drivers import Driver

STEP_S = 1.0
"""Simulated time advanced per step when the caller asks for no other."""


class TrialSteps:
    """What a caller sees of a running trial; every method does nothing by default.

    The session runner's steps store each one (a crash loses at most a step), pace the
    trial, hold and stop it between two steps."""

    def started(self, loop: TrialLoop) -> None:
        """The loop has started with its driver, its clock at 0."""

    def before_step(self, loop: TrialLoop) -> None:
        """Before each step; may block (a held trial) or raise (a stopped session)."""

    def after_step(self, loop: TrialLoop, samples: np.ndarray) -> None:
        """After each step: the rows it acquired (the task's `sample_columns`, the
        region as its index in `regions`; possibly none)."""

    def finished(self, loop: TrialLoop) -> None:
        """The loop has ended (its goal, the driver or the time limit), before the
        task measures the trial (the session commits its last samples here)."""


@dataclass
class TrialRun:
    """A trial that has run: its samples, how it ended and the task's measures."""

    samples: np.ndarray
    """Every row the loop acquired, in the task's `sample_columns` order."""
    success: bool
    completion_time_s: float
    measures: dict[str, float]
    """The task's stored measures by name (`completion_time_s` apart)."""
    extras: dict[str, Any]
    """Further summary values of the task's `trial_measures`."""
    rendered_gain: dict[str, float]
    """The summary's record of the gain the dial rendered at, under
    `haptic_gain_n_m_per_n` (0 in VO, which renders none); empty for a task without a
    dial."""
    ended: dict[str, str] = field(default_factory=dict)
    """How a trial at a physical phantom ended (`end`), empty for a simulated one."""


def rendered_gain(task: Task, condition: str, gain_n_m_per_n: float | None) -> dict[str, float]:
    """The summary's record of the haptic gain a trial renders at.

    Parameters
    ----------
    task : Task
        The trial's task.
    condition : str
        ``"VO"`` or ``"HV"``.
    gain_n_m_per_n : float or None
        The asked-for gain, N m/N (None: the task's default).

    Returns
    -------
    dict of str to float
        ``{"haptic_gain_n_m_per_n": 0.0}`` in VO (no haptic torque is rendered), the
        task's gain in HV; empty where the task has no dial.
    """
    if not task.has_dial:
        return {}
    gain = task.haptic_gain(gain_n_m_per_n)
    return {"haptic_gain_n_m_per_n": 0.0 if condition == "VO" or gain is None else gain}


def trial_end(
    task: Task, loop: Any, driver: Driver, samples: np.ndarray
) -> tuple[bool, float, dict[str, str]]:
    """The trial's success, completion time and the summary's record of its end.

    A simulated phantom decides success itself (its model's tip at the target) and the
    completion time is the last sample's. A physical one has no tip tracker: a person
    ends the trial as reached (`HardwareDriver.end`: the dial's button or the
    experimenter), success true at that moment; a trial that runs to the time limit is
    success false; `end` says which (`study_rows.TRIAL_ENDS`)."""
    if getattr(loop, "physical_follower", None) is None:
        return bool(loop.success), task.completion_time_s(samples), {}
    end = getattr(driver, "end", None)
    if end is None or not loop.done:
        return False, task.completion_time_s(samples), {"end": "time_limit"}
    return True, float(loop.done_s), {"end": end}


def run_trial(
    task: Task,
    condition: str,
    seed: int,
    driver: Driver,
    max_s: float,
    *,
    haptic_gain_n_m_per_n: float | None = None,
    estimator: Any = None,
    context: Any = None,
    link: Any = None,
    step_s: float = STEP_S,
    steps: TrialSteps | None = None,
) -> TrialRun:
    """Build the task's loop, run it with `driver` to its end or `max_s`, measure it.

    Parameters
    ----------
    task : Task
        The trial's task.
    condition : str
        ``"VO"`` or ``"HV"``.
    seed : int
        Seeds the loop (the same seed and driver give the same samples).
    driver : Driver
        The hand: a simulated participant, a keyboard or a device.
    max_s : float
        The trial's time limit, s.
    haptic_gain_n_m_per_n : float or None, optional
        The dial's haptic gain, N m/N, where the task has a dial (None: its default).
    estimator, context, link : optional
        As for `Task.make_loop`.
    step_s : float, optional
        Simulated time per step, s.
    steps : TrialSteps or None, optional
        Told of the start and of every step.

    Returns
    -------
    TrialRun
        The samples, the end and the task's measures.
    """
    steps = steps or TrialSteps()
    gain = rendered_gain(task, condition, haptic_gain_n_m_per_n)  # refuses a bad gain first
    loop = task.make_loop(
        condition,
        seed,
        haptic_gain_n_m_per_n=haptic_gain_n_m_per_n,
        estimator=estimator,
        context=context,
        link=link,
    )
    loop.start(driver)
    steps.started(loop)
    chunks = []
    while loop.t_s < max_s - 1e-9 and not loop.done:
        steps.before_step(loop)
        samples = loop.advance(min(step_s, max_s - loop.t_s))
        if len(samples):
            chunks.append(samples)
        steps.after_step(loop, samples)
    steps.finished(loop)
    width = len(task.sample_columns)
    samples = np.concatenate(chunks) if chunks else np.zeros((0, width))
    success, completion_s, ended = trial_end(task, loop, driver, samples)
    values, extras = task.trial_measures(samples, success)
    return TrialRun(samples, success, completion_s, values, extras, gain, ended)


def simulate_trial(
    task: Task,
    traits: Traits,
    condition: str,
    seed: int,
    max_s: float,
    *,
    haptic_gain_n_m_per_n: float | None = None,
    estimator: Any = None,
    link: Any = None,
    context: Any = None,
) -> TrialResult:
    """One headless trial of the simulated participant `traits`.

    Parameters
    ----------
    task : Task
        The trial's task.
    traits : Traits
        The simulated person.
    condition : str
        ``"VO"`` or ``"HV"``.
    seed : int
        Seeds the trial (the same seed gives the same samples, byte for byte).
    max_s : float
        The trial runs to its end or this many seconds.
    haptic_gain_n_m_per_n, estimator, link : optional
        As for `run_trial`.
    context : Any, optional
        As for `Task.make_loop`; built by `Task.session_context` when None.

    Returns
    -------
    TrialResult
        The trial's frame (TRIAL.csv) and its summary: the task, group, condition,
        rendered gain, seed, success, completion time, measures, the task's further
        values, what the simulated person noticed and the person's traits.
    """
    context = task.session_context() if context is None else context
    driver = task.simulated_driver(traits, max_s, context)
    run = run_trial(
        task,
        condition,
        seed,
        driver,
        max_s,
        haptic_gain_n_m_per_n=haptic_gain_n_m_per_n,
        estimator=estimator,
        context=context,
        link=link,
    )
    summary = {
        "task": task.name,
        "group": traits.group,
        "condition": condition,
        **run.rendered_gain,
        "seed": seed,
        "success": run.success,
        COMPLETION_TIME: run.completion_time_s,
        **run.measures,
        **run.extras,
        **task.driver_counts(driver),
        "participant": traits.to_dict(),
    }
    return TrialResult(task.trial_frame(run.samples), summary)
