"""`study init`, `study design template`, `study participant add`, `study schedule`."""

from __future__ import annotations

import json
from pathlib import Path

import click

from db.engine import resolve_url
from db.migrate import open_database
from study.commands.base import (
    StudyCommand,
    StudyGroup,
    actor_option,
    db_option,
    file_option,
    not_personal_option,
    opened_database,
)
from study.protocol.csv_input import read_text_file
from study.protocol.demo_marks import STARTED, demo_state
from study.protocol.design import TEMPLATE, parse_design
from study.protocol.roster import create_study, enrol, schedule


@click.command("init", cls=StudyCommand)
@file_option(
    "--design", "design_path", "The study design (TOML; `study design template` prints one)."
)
@db_option
def init(design_path: Path, db_url: str | None) -> None:
    """Create the study database from a design file.

    \b
    Example:
      study init --design design.toml --db lab.db
    """

    text = read_text_file(design_path, "design file", "a UTF-8 TOML file")
    design = parse_design(text, str(design_path))  # all checks before anything is written
    url = resolve_url(db_url)
    new_file = (
        Path(url.database)
        if url.get_backend_name() == "sqlite"
        and url.database not in (None, "", ":memory:")
        and not Path(url.database).exists()
        else None
    )
    engine = open_database(url, create=True)
    try:
        create_study(engine, design, text)
    except BaseException:
        # nothing half-written: a database file this command created goes again
        engine.dispose()
        if new_file is not None:
            for suffix in ("", "-wal", "-shm", "-journal"):
                Path(f"{new_file}{suffix}").unlink(missing_ok=True)
        raise
    finally:
        engine.dispose()
    sizes = ", ".join(f"{g} {n}" for g, n in design.groups.items())
    click.echo(
        f"created study {design.name!r}: groups {sizes}; conditions "
        f"{'/'.join(design.conditions)} ({design.counterbalancing}); tasks "
        f"{', '.join(design.tasks)}; {design.practice_trials} practice + "
        f"{design.trials_per_condition} trials per block"
    )
    # lazy: study.protocol.traits costs 3 ms at start-up
    from study.protocol.traits import PROFILES

    unsimulated = [g for g in design.groups if g not in PROFILES]
    if unsimulated:
        click.echo(
            f"note: no simulated participant profile for group(s) {', '.join(unsimulated)} "
            f"(profiles: {', '.join(PROFILES)}): their sessions are run by a person "
            "(--driver keyboard or hardware) or drawn from a participant model fitted to "
            "them (study run --participants MODEL)"
        )


@click.group("design", cls=StudyGroup)
def design_group() -> None:
    """Study design files.

    \b
    Example:
      study design template > design.toml
    """


@design_group.command("template")
def template() -> None:
    """Print a commented default design (the paper's 20/8/8 study).

    \b
    Example:
      study design template > design.toml
    """
    click.echo(TEMPLATE, nl=False)


@click.group("participant", cls=StudyGroup)
def participant() -> None:
    """Enrol participants (pseudonymous codes only); withdraw, reinstate, correct a group.

    \b
    Example:
      study participant add --group novice --count 8
    """


@participant.command("add")
@click.option("--group", required=True, help="Experience group, by its name in the design.")
@click.option("--site", default=None, help="Lab enrolling the participant (multi-site studies).")
@click.option(
    "--count",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="How many participants to enrol in the group, each with the next code.",
)
@click.option(
    "--beyond-target",
    is_flag=True,
    help="Enrol past the group's target in the design (replacements); audited.",
)
@actor_option
@db_option
def participant_add(
    group: str,
    site: str | None,
    count: int,
    beyond_target: bool,
    actor: str | None,
    db_url: str | None,
) -> None:
    """Enrol the next participant(s) of a group: code, condition order and schedule (all
    of them or none; at most the group's target unless --beyond-target).

    \b
    Example:
      study participant add --group novice --count 8
    """
    with opened_database(db_url) as engine:
        added = enrol(engine, group, site, count, beyond_target=beyond_target, actor=actor)
    for p in added:
        click.echo(f"{p.code} ({p.group}): conditions {' then '.join(p.condition_order)}")


@participant.command("withdraw")
@click.argument("code")
@click.option("--reason", required=True, help="Why (kept in the audit log and the analysis).")
@click.option("--actor", default=None, help="Who records it [default: $STUDY_ACTOR or user@host].")
@not_personal_option
@db_option
def participant_withdraw(code: str, reason: str, actor: str | None, db_url: str | None) -> None:
    """Withdraw a participant: kept and marked, no more sessions, left out of the analysis.

    \b
    Example:
      study participant withdraw P004 --reason "felt unwell"
    """
    # lazy: study.protocol.withdrawal costs 4 ms at start-up
    from study.protocol.withdrawal import withdraw

    with opened_database(db_url) as engine:
        withdraw(engine, code, reason, actor)
    click.echo(f"{code} withdrawn ({reason}); their data are kept and left out of the analysis")


@participant.command("reinstate")
@click.argument("code")
@click.option("--reason", required=True, help="Why the withdrawal is undone (audit log).")
@actor_option
@not_personal_option
@db_option
def participant_reinstate(code: str, reason: str, actor: str | None, db_url: str | None) -> None:
    """Undo a withdrawal (audited): the participant continues where they stopped and the
    analysis counts them again.

    \b
    Example:
      study participant reinstate P004 --reason "withdrawn by mistake"
    """
    # lazy: study.protocol.corrections costs 6 ms at start-up
    from study.protocol.corrections import reinstate

    with opened_database(db_url) as engine:
        reinstate(engine, code, reason, actor)
    click.echo(f"{code} is in the study again ({reason}); their sessions go on")


@participant.command("correct-group")
@click.argument("code")
@click.option("--group", required=True, help="The right experience group, by its design name.")
@click.option("--reason", required=True, help="Why the group is corrected (audit log).")
@click.option(
    "--beyond-target", is_flag=True, help="Move past the new group's target in the design."
)
@actor_option
@not_personal_option
@db_option
def participant_correct_group(
    code: str,
    group: str,
    reason: str,
    beyond_target: bool,
    actor: str | None,
    db_url: str | None,
) -> None:
    """Correct a participant's group before their first trial (audited): they take the
    new group's next counterbalanced condition order; refused once a trial is stored.

    \b
    Example:
      study participant correct-group P004 --group expert --reason "registered in the wrong group"
    """
    # lazy: study.protocol.corrections costs 6 ms at start-up
    from study.protocol.corrections import correct_group

    with opened_database(db_url) as engine:
        order = correct_group(engine, code, group, reason, actor, beyond_target=beyond_target)
    click.echo(f"{code} ({group}): conditions {' then '.join(order)} ({reason})")


@participant.command("note")
@click.argument("code")
@click.argument("text")
@click.option(
    "--session",
    "on_session",
    is_flag=True,
    help="A note on today's session, kept beside the others (audit log).",
)
@click.option("--actor", default=None, help="Who records it [default: $STUDY_ACTOR or user@host].")
@not_personal_option
@db_option
def participant_note(
    code: str, text: str, on_session: bool, actor: str | None, db_url: str | None
) -> None:
    """Set a participant's note, or add a note on their session (pseudonymous: no names
    or contact details).

    \b
    Example:
      study participant note P004 "wore glasses"
    """
    # lazy: study.protocol.withdrawal costs 4 ms at start-up
    from study.protocol.withdrawal import add_session_note, set_note

    with opened_database(db_url) as engine:
        (add_session_note if on_session else set_note)(engine, code, text, actor)
    click.echo(f"{code}: {'session note' if on_session else 'note'} kept")


@click.command("schedule", cls=StudyCommand)
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@db_option
def schedule_cmd(as_json: bool, db_url: str | None) -> None:
    """The plan and progress: groups filling up, each participant's blocks.

    \b
    Example:
      study schedule --db lab.db
    """

    with opened_database(db_url) as engine:
        plan = schedule(engine)
        demo = demo_state(engine)
    incomplete = demo is not None and demo[0] == STARTED
    if as_json:
        click.echo(json.dumps({**plan, "incomplete_demo": incomplete}, indent=2))
        return
    click.echo(f"study: {plan['study']}")
    if incomplete:
        click.echo(
            "  an INCOMPLETE demo (stopped halfway): `study demo` with the same options "
            "and folder finishes it"
        )
    for g, fill in plan["groups"].items():
        click.echo(f"  {g:<10} {fill['enrolled']:>3} of {fill['target']}")
    for p in plan["participants"]:
        blocks = "  ".join(
            f"{b['task']}/{b['condition']} {b['completed']}/{b['planned']}" for b in p["blocks"]
        )
        click.echo(f"{p['code']:<8} {p['group']:<10} {'-'.join(p['condition_order']):<6} {blocks}")
