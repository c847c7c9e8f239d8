"""How long work tells how far it has come: one protocol for every progress callback.

Long work (a session, training, a calibration, a fit, an export, a bench) takes a
`progress` argument of type `Progress` and calls it with the step it is on and, where
the work can be counted, how many of how many units are done:

    progress("training the GRU")                # a step that cannot be counted
    progress("epoch 3: validation RMSE 0.041 N", 3, 100)
    progress("samples", 120, 288)

`total` is 0 when the step is not counted. The caller decides what to show (a Rich
progress bar on the command line, a status line in the terminal app, nothing in a
test); `no_progress` is the default that shows nothing, and `describe` the one-line
form of a call. It lives in `teleop_core` (plain Python, no dependency) so that the
numerics and the application share it.
"""

from __future__ import annotations

from typing import Protocol

__all__ = ["Progress", "as_step", "describe", "no_progress"]


class Progress(Protocol):
    """A progress callback: `progress(step, done=0, total=0)`.

    `step` says what runs now in one short line (e.g. ``"round 2: stribeck"``), `done`
    how many units of it are done and `total` how many it has (0: not counted). The
    arguments are passed by position, so a function or lambda with other parameter
    names is a `Progress` too.
    """

    def __call__(self, step: str, done: int = 0, total: int = 0, /) -> None:
        """Tell how far the work has come.

        Parameters
        ----------
        step : str
            What runs now, one short line.
        done : int, optional
            Units of the step done so far.
        total : int, optional
            Units the step has in all; 0 when it is not counted.
        """


def no_progress(step: str, done: int = 0, total: int = 0) -> None:
    """The `Progress` that shows nothing (the default of every long function).

    Parameters
    ----------
    step : str
        What runs now (ignored).
    done : int, optional
        Units of the step done so far (ignored).
    total : int, optional
        Units the step has in all (ignored).
    """


def describe(step: str, done: int = 0, total: int = 0) -> str:
    """One line for a call of a `Progress`.

    Parameters
    ----------
    step : str
        What runs now.
    done : int, optional
        Units of the step done so far.
    total : int, optional
        Units the step has in all; 0 when it is not counted.

    Returns
    -------
    str
        ``"step (done/total)"`` when the step is counted, else ``"step"``.

    Examples
    --------
    >>> describe("samples", 3, 10)
    'samples (3/10)'
    >>> describe("compiling the loop")
    'compiling the loop'
    """
    return f"{step} ({done}/{total})" if total else step


def as_step(progress: Progress, step: str) -> Progress:
    """`progress` told every call as `step` (keeping the count): for a part of larger
    work that the caller names.

    Parameters
    ----------
    progress : Progress
        The `Progress` to tell.
    step : str
        The step every call is told as, whatever step the caller gives.

    Returns
    -------
    Progress
        A `Progress` passing each call's count on to `progress` under `step`.

    Examples
    --------
    >>> seen = []
    >>> as_step(lambda s, d=0, t=0: seen.append((s, d, t)), "emulator")("trial", 2, 5)
    >>> seen
    [('emulator', 2, 5)]
    """

    def told(_step: str, done: int = 0, total: int = 0) -> None:
        progress(step, done, total)

    return told
