"""`study trial list|invalidate|revalidate`: a participant's trials, and a measured trial
marked invalid (kept, audited, left out of the analysis) or valid again."""

from __future__ import annotations

import click

from study.commands.base import (
    StudyGroup,
    actor_option,
    db_option,
    not_personal_option,
    opened_database,
)
from study.errors import StudyInputError

MAX_ID = 2**63 - 1
"""The largest id a database row can have (SQLite's and PostgreSQL's 64-bit integers)."""
REASON_HELP = "Why (kept in the audit log; an invalid trial's reason is listed by the analysis)."


@click.group("trial", cls=StudyGroup)
def trial() -> None:
    """A participant's trials; mark a measured trial invalid or valid again (audited).

    \b
    Example:
      study trial list --participant P001
    """


@trial.command("list")
@click.argument("old_code", metavar="[CODE]", required=False, default=None)
@click.option(
    "--participant",
    "code",
    default=None,
    help="The participant's code, e.g. P001 (a code given as the argument, the older "
    "form, still works for this release and warns).",
)
@db_option
def trial_list(old_code: str | None, code: str | None, db_url: str | None) -> None:
    """Every trial row of a participant (attempts and interrupted trials included),
    with its id, status, completion time, success, measures and validity.

    \b
    Example:
      study trial list --participant P001
    """
    # lazy: study.protocol.participant_record (with sqlalchemy) costs 0.4 s at start-up
    from study.protocol.participant_record import participant_record

    code = _participant(old_code, code)

    with opened_database(db_url) as engine:
        record = participant_record(engine, code)
    if not record.trials:
        click.echo(f"{code}: no trials stored")
    for t in record.trials:
        time_s = "" if t.completion_time_s is None else f" {t.completion_time_s:.2f} s"
        success = "" if t.success is None else (" success" if t.success else " no success")
        measures = "".join(f" {k}={v:.3g}" for k, v in t.measures.items())
        state = f" INVALID ({t.invalid_reason})" if t.invalid_reason else ""
        why = f" ({t.why})" if t.status == "interrupted" and t.why else ""
        click.echo(
            f"{t.id:>6} {t.task}/{t.condition} {t.label()} attempt {t.attempt}: "
            f"{t.status}{why}{time_s}{success}{measures}{state}"
        )


def _participant(old_code: str | None, code: str | None) -> str:
    """The participant of `study trial list`: `--participant`, or the positional code of
    the older form with a deprecation warning on stderr."""
    if old_code is not None and code is not None and old_code != code:
        raise StudyInputError(
            f"participant {old_code!r} and --participant {code!r}; expected one code"
        )
    if code is None and old_code is None:
        raise StudyInputError("no participant; expected --participant CODE")
    if code is None:
        click.echo(
            "study trial list: warning: the positional CODE is deprecated and goes in the "
            f"next release; use --participant {old_code}",
            err=True,
        )
    return code or str(old_code)


def _mark(trial_id: int, valid: bool, reason: str, actor: str | None, db_url: str | None) -> None:
    # lazy: study.protocol.corrections (with sqlalchemy) costs 0.4 s at start-up
    from study.protocol.corrections import mark_trial

    with opened_database(db_url) as engine:
        what = mark_trial(engine, trial_id, valid, reason, actor)
    if valid:
        click.echo(f"trial {trial_id} ({what}) is valid again ({reason}); the analysis counts it")
    else:
        click.echo(
            f"trial {trial_id} ({what}) marked invalid ({reason}); kept, and left out of "
            "the analysis with its reason"
        )


@trial.command("invalidate")
@click.argument("trial_id", metavar="ID", type=click.IntRange(min=1, max=MAX_ID))
@click.option("--reason", required=True, help=REASON_HELP)
@actor_option
@not_personal_option
@db_option
def trial_invalidate(trial_id: int, reason: str, actor: str | None, db_url: str | None) -> None:
    """Mark completed measured trial ID invalid: kept with its samples, audited, left out
    of `study analyze` and listed among its exclusions with the reason.

    \b
    Example:
      study trial invalidate 17 --reason "dial came loose"
    """
    _mark(trial_id, False, reason, actor, db_url)


@trial.command("revalidate")
@click.argument("trial_id", metavar="ID", type=click.IntRange(min=1, max=MAX_ID))
@click.option("--reason", required=True, help=REASON_HELP)
@actor_option
@not_personal_option
@db_option
def trial_revalidate(trial_id: int, reason: str, actor: str | None, db_url: str | None) -> None:
    """Mark trial ID, marked invalid earlier, valid again (audited).

    \b
    Example:
      study trial revalidate 17 --reason "marked by mistake"
    """
    _mark(trial_id, True, reason, actor, db_url)
