"""`study tlx pairs|enter|show`: NASA-TLX questionnaires from the command line."""

from __future__ import annotations

import json

import click
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.models.study import Participant
from study.commands.base import (
    StudyGroup,
    actor_option,
    db_option,
    not_personal_option,
    opened_database,
)
from study.commands.typed import comma_list
from study.errors import StudyInputError
from study.protocol.roster import load_study
from study.protocol.tlx import pair_order, response_scores, scored_tlx, store_tlx


@click.group("tlx", cls=StudyGroup)
def tlx() -> None:
    """NASA-TLX: six ratings (0-100, steps of 5) and 15 pairwise comparisons per block.

    \b
    Example:
      study tlx enter --participant P001 --task lcca --condition HV --mental 55 ...
    """


@tlx.command("pairs")
@click.option("--participant", "code", required=True, help="The participant's code, e.g. P001.")
@db_option
def pairs_cmd(code: str, db_url: str | None) -> None:
    """The 15 comparisons in the order this participant is shown them.

    \b
    Example:
      study tlx pairs --participant P001
    """
    with opened_database(db_url) as engine:
        with Session(engine) as session:
            study, _ = load_study(session)
            if session.scalars(select(Participant).where(Participant.code == code)).first() is None:
                raise StudyInputError(
                    f"unknown participant {code!r}; expected a code from `study schedule`"
                )
    for k, (left, right) in enumerate(pair_order(study.seed, code), 1):
        click.echo(f"{k:>2}. {left} or {right}")


def _rating(name: str):
    return click.option(
        f"--{name}", type=int, required=True, help=f"{name} rating, 0-100 in steps of 5"
    )


@tlx.command("enter")
@click.option("--participant", "code", required=True, help="The participant's code, e.g. P001.")
@click.option("--task", required=True, help="The block's task, e.g. lcca.")
@click.option("--condition", required=True, help="The block's condition, VO or HV.")
@_rating("mental")
@_rating("physical")
@_rating("temporal")
@_rating("performance")
@_rating("effort")
@_rating("frustration")
@click.option(
    "--choices",
    help="The 15 subscales chosen, comma-separated, in the order of `study tlx pairs`.",
)
@click.option(
    "--reason",
    help="Why a stored questionnaire is being edited, or why a block with no completed "
    "trial gets one (required for both; kept in the audit log).",
)
@actor_option
@not_personal_option
@db_option
def enter_cmd(
    code: str,
    task: str,
    condition: str,
    choices: str | None,
    reason: str | None,
    actor: str | None,
    db_url: str | None,
    **ratings: int,
) -> None:
    """Store a questionnaire for one task x condition block (or edit the stored one).

    \b
    Example:
      study tlx enter --participant P001 --task lcca --condition HV --mental 55 \
          --physical 30 --temporal 40 --performance 25 --effort 50 --frustration 20
    """

    chosen = comma_list("--choices", choices, unique=False) if choices is not None else None
    with opened_database(db_url) as engine:
        response, new = store_tlx(engine, code, task, condition, ratings, chosen, reason, actor)
    _, raw, weighted = response_scores(response)
    scores = f"raw TLX {raw:.1f}"
    if weighted is not None:
        scores += f", weighted TLX {weighted:.1f}"
    click.echo(f"{code} {task}/{condition}: {'stored' if new else 'updated'}; {scores}")


@tlx.command("show")
@click.option("--participant", "code", default=None, help="One participant [default: all].")
@click.option(
    "--json", "as_json", is_flag=True, help="Print the scores as JSON instead of a table."
)
@db_option
def show_cmd(code: str | None, as_json: bool, db_url: str | None) -> None:
    """Stored questionnaires with their raw and weighted scores.

    \b
    Example:
      study tlx show --json
    """
    with opened_database(db_url) as engine:
        scored = scored_tlx(engine, code)
    rows = [
        {k: v for k, v in r.items() if k != "group"}
        for r in sorted(scored, key=lambda r: r["participant"])
    ]
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    for r in rows:
        weighted = "-" if r["tlx_weighted"] is None else f"{r['tlx_weighted']:.1f}"
        click.echo(
            f"{r['participant']} {r['task']}/{r['condition']}: raw {r['tlx_raw']:.1f}, "
            f"weighted {weighted}"
        )
