"""What every `study` subcommand shares: the command classes that turn the packages'
input errors into one-line usage errors, and the common `--db` option."""

from __future__ import annotations

from typing import Any

import click

from db.errors import DbInputError
from study.errors import StudyInputError
from teleop_core.errors import TeleopInputError

USER_ERRORS = (DbInputError, StudyInputError, TeleopInputError)


class InputError(click.ClickException):
    """A package's input error, raised inside a command (keeps the command's context)."""

    exit_code = 2

    def __init__(self, message: str, ctx: click.Context) -> None:
        super().__init__(message)
        self.ctx = ctx


class StudyCommand(click.Command):
    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except USER_ERRORS as exc:
            raise InputError(str(exc), ctx) from exc


class StudyGroup(click.Group):
    command_class = StudyCommand
    group_class = type  # subgroups are StudyGroups too


db_option = click.option(
    "--db",
    "db_url",
    envvar="STUDY_DB",
    metavar="URL",
    default=None,
    help="Study database: SQLite path or URL, or postgresql+psycopg://... "
    "[default: ./study.db; env STUDY_DB]",
)
