"""`LastingObserver`: one observer across the sessions of a program that runs many (the
terminal app's trials, a probe run), told what a single long session would be told."""

from __future__ import annotations

from typing import Any

from study.protocol.observer import LastingObserver, SessionInfo, SessionObserver


class Log(SessionObserver):
    def __init__(self) -> None:
        self.calls: list[tuple[Any, ...]] = []

    def session_started(self, session: SessionInfo) -> None:
        self.calls.append(("start", session.participant, session.driver, session.pace))

    def session_ended(self) -> None:
        self.calls.append(("end",))

    def event(self, kind: str, **fields: Any) -> None:
        self.calls.append((kind, fields["participant"]))


def _session(code: str, pace: float | None = 1.0, tasks: tuple = ("lcca",)) -> SessionInfo:
    return SessionInfo("s", code, "novice", "simulated", pace, tasks)  # type: ignore[arg-type]


def test_sessions_of_one_participant_are_one_until_something_changes() -> None:
    log = Log()
    lasting = LastingObserver(log)
    keys = {"study": "s", "group": "novice"}
    lasting.event("probe", participant="P001", driver="simulated", **keys)  # no session yet
    lasting.session_started(_session("P001"))  # trials follow probes: a session of its own
    lasting.session_ended()
    lasting.session_started(_session("P001"))  # the next trial: the same session
    lasting.event("questionnaire", participant="P001", **keys)
    lasting.session_ended()
    lasting.session_started(_session("P001", pace=None))  # another pace
    lasting.event("questionnaire", participant="P002", **keys)  # another participant
    lasting.close()
    lasting.close()  # once only
    assert log.calls == [
        ("start", "P001", "simulated", None),
        ("probe", "P001"),
        ("end",),
        ("start", "P001", "simulated", 1.0),
        ("questionnaire", "P001"),
        ("end",),
        ("start", "P001", "simulated", None),
        ("end",),
        ("start", "P002", "keyboard", None),
        ("questionnaire", "P002"),
        ("end",),
    ]


def test_a_session_that_failed_to_start_is_ended_and_not_kept() -> None:
    class Refuses(Log):
        def session_started(self, session: SessionInfo) -> None:
            super().session_started(session)
            raise RuntimeError("no instrument")

    log = Refuses()
    lasting = LastingObserver(log)
    for _ in range(2):
        try:
            lasting.session_started(_session("P001"))
        except RuntimeError:
            pass
    lasting.close()
    assert log.calls == [("start", "P001", "simulated", 1.0), ("end",)] * 2


def test_progress_and_storage_waits_reach_every_observer_through_both_wrappers() -> None:
    """The session's progress and its waits for the database are observer events like
    the others: `Observers` tells each observer in order, `LastingObserver` passes them on."""
    from study.protocol.observer import Observers

    class Waits(SessionObserver):
        def __init__(self, name: str, calls: list[tuple[Any, ...]]) -> None:
            self.name, self.calls = name, calls

        def trial_progress(self, pending: Any, k: int, n: int) -> None:
            self.calls.append((self.name, "progress", pending, k, n))

        def storage_wait(self, waited_s: float | None, held: int) -> None:
            self.calls.append((self.name, "wait", waited_s, held))

    calls: list[tuple[Any, ...]] = []
    both = LastingObserver(Observers([Waits("a", calls), Waits("b", calls)]))
    both.trial_progress("first", 0, 2)
    both.storage_wait(0.25, 40)
    both.storage_wait(None, 0)
    assert calls == [
        ("a", "progress", "first", 0, 2),
        ("b", "progress", "first", 0, 2),
        ("a", "wait", 0.25, 40),
        ("b", "wait", 0.25, 40),
        ("a", "wait", None, 0),
        ("b", "wait", None, 0),
    ]
