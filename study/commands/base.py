"""What every `study` subcommand shares: the command classes that turn the packages'
input errors into one-line usage errors, and the common `--db` option."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from db.errors import DatabaseGoneError, DbInputError
from db.failures import classify
from study.commands.typed import strict_params
from study.errors import ReasonNeeded, StudyInputError
from study.protocol.free_text import OPT_OUT, NotPersonal, PersonalDataError
from teleop_core.errors import TeleopInputError
from teleop_core.progress import Heartbeat, describe

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress, TaskID
    from rich.status import Status
    from sqlalchemy import Engine

    from study.commands.progress_lines import LineStatus
    from study.protocol.participant_model import ParticipantModel
    from teleop_core import progress

USER_ERRORS = (DbInputError, DatabaseGoneError, StudyInputError, TeleopInputError)


class InputError(click.ClickException):
    """A package's input error, raised inside a command (keeps the command's context)."""

    exit_code = 2

    def __init__(self, message: str, ctx: click.Context) -> None:
        super().__init__(message)
        self.ctx = ctx


def database_failure(exc: BaseException, db_url: str | None = None) -> str | None:
    """One line for a database that cannot be used, naming its cause (`db.failures`:
    full, read-only, locked, disconnected, corrupt), or None for anything else.

    Integrity and programming errors are not here: they are bugs and keep their
    traceback. SQLAlchemy is imported only when a command has failed.
    """
    module = type(exc).__module__.split(".")[0]
    if module == "sqlalchemy":
        from sqlalchemy.exc import DatabaseError, IntegrityError, InterfaceError, ProgrammingError

        if not isinstance(exc, DatabaseError | InterfaceError) or isinstance(
            exc, IntegrityError | ProgrammingError
        ):
            return None
        orig: BaseException | None = exc.orig
    elif _driver_fault(exc, module):  # raised through a driver cursor (the sample writer's)
        orig = exc
    else:
        return None
    # lazy: db.engine (with sqlalchemy) costs 0.2 s at start-up
    from db.engine import describe, resolve_url

    try:
        shown = describe(resolve_url(db_url))
    except ValueError:
        shown = "the study database"
    return classify(orig if orig is not None else exc).line(shown)


def output_failure(ctx: click.Context, exc: BaseException) -> str | None:
    """One line for a file or folder a command was told to write (`--out`, `--json`...)
    that the system will not make there (a folder under /proc, a name too long, no
    permission), or None for any other error. A full disk is told by the commands
    themselves, with what they kept."""
    if not isinstance(exc, OSError) or not exc.filename:
        return None
    failed = Path(str(exc.filename)).absolute()
    for param in ctx.command.params:
        value = ctx.params.get(param.name or "")
        if not isinstance(value, Path) or not isinstance(param, click.Option):
            continue
        target = value.absolute()
        sibling = failed.parent == target.parent and failed.name.startswith(f".{target.name}.")
        if failed == target or target in failed.parents or sibling:  # sibling: its temp file
            return (
                f"{param.opts[0]} {value}: {target if sibling else failed} cannot be written "
                f"({exc.strerror or type(exc).__name__}); expected a folder or file that can "
                "be made and written there"
            )
    return None


def _driver_fault(exc: BaseException, module: str) -> bool:
    """Whether `exc` is SQLite's or psycopg's own error for a database that cannot be
    used (not a constraint or a programming error)."""
    if module == "sqlite3":
        import sqlite3 as driver
    elif module == "psycopg":
        import psycopg as driver  # type: ignore[no-redef]
    else:
        return False
    return isinstance(exc, driver.OperationalError | driver.DatabaseError) and not isinstance(
        exc, driver.IntegrityError | driver.ProgrammingError
    )


MAX_SEED = 2**32 - 1
SEED = click.IntRange(0, MAX_SEED)
"""A seed option's type: numpy's generators take 0 to 2^32 - 1 (a negative seed was a
traceback)."""


def refuse_non_finite(ctx: click.Context) -> None:
    """StudyInputError for a number option given as nan or +-inf: click's FloatRange lets
    them through (nan compares False with both bounds), and no option of `study` means
    anything by them."""

    for param in ctx.command.params:
        value = ctx.params.get(param.name or "")
        values = value if isinstance(value, tuple | list) else (value,)
        for v in values:
            if isinstance(v, float) and not math.isfinite(v):
                flag = param.opts[0] if param.opts else param.name
                kind = param.type
                bounds = f" {kind._describe_range()}" if isinstance(kind, click.FloatRange) else ""
                raise StudyInputError(f"{flag} {v!r}; expected a finite number{bounds}")


def refuse_linked_out(ctx: click.Context) -> None:
    """StudyInputError for an `--out` that is, or (for a relative path) goes through, a
    symbolic link: the files a command writes would land wherever the link points (the
    exports never write through a link). The folders above an absolute path are the
    system's (macOS's /tmp is a link) and not looked at."""
    for param in ctx.command.params:
        value = ctx.params.get(param.name or "")
        if "--out" not in getattr(param, "opts", ()) or not isinstance(value, Path):
            continue
        steps = [value] if value.is_absolute() else [value, *value.parents[:-1]]
        linked = next((s for s in steps if s.is_symlink()), None)
        if linked is not None:
            raise StudyInputError(
                f"--out {value}: {linked} is a symbolic link; expected a real folder or file "
                "path (nothing is written through a link)"
            )


FREE_TEXT_PARAMS = ("text", "reason")
"""The parameters that hold a note or a reason (`study.protocol.free_text`)."""


def keep_lookalike_text(ctx: click.Context) -> None:
    """With `--not-personal`, the command's note or reason is marked as one that only
    looks like contact details (`NotPersonal`), which the free-text check keeps."""
    if not ctx.params.pop("not_personal", False):
        return

    for name in FREE_TEXT_PARAMS:
        if isinstance(ctx.params.get(name), str):
            ctx.params[name] = NotPersonal(ctx.params[name])


not_personal_option = click.option(
    "--not-personal",
    "not_personal",
    is_flag=True,
    help="Keep a note or reason that only looks like an e-mail address or a phone number "
    "(a serial or lot number); the database holds no personal data.",
)


class StudyCommand(click.Command):
    """A `study` command: its options read what a person types strictly
    (`study.commands.typed`), and its packages' input errors end as one line."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)

        strict_params(self.params)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            keep_lookalike_text(ctx)
            refuse_non_finite(ctx)
            refuse_linked_out(ctx)
            return super().invoke(ctx)
        except USER_ERRORS as exc:
            raise InputError(with_flag(exc), ctx) from exc
        except Exception as exc:
            message = database_failure(exc, ctx.params.get("db_url")) or output_failure(ctx, exc)
            if message is None:
                raise
            raise InputError(message, ctx) from exc


def with_flag(exc: BaseException) -> str:
    """`exc`'s line with the command line's way out, where the package's message names
    none (it is shown by the terminal app too, which has its own fields)."""

    line = str(exc)
    if isinstance(exc, PersonalDataError):
        return f"{line}, or give {OPT_OUT} if it only looks like one"
    if isinstance(exc, ReasonNeeded):
        return f"{line} (--reason TEXT)"
    return line


def summary(command: click.Command) -> str:
    """A command's first sentence, whole: up to the first full stop that ends its first
    paragraph or comes before a capital (click's own short help cuts at a width, and at
    the stop of "Fig. 8" or "eq. 1")."""
    if command.short_help:
        return command.short_help
    paragraph = (command.help or "").strip().split("\n\n")[0]
    text = " ".join(paragraph.split())
    end = re.search(r"[.!?](?=\s+[A-Z`(]|$)", text)
    return text[: end.end()] if end else text


class StudyGroup(click.Group):
    command_class = StudyCommand
    group_class = type  # subgroups are StudyGroups too

    def sections(self, ctx: click.Context) -> list[tuple[str, list[click.Command]]]:
        """The subcommands under their headings, as `--help` and the reference list them."""
        commands = [self.get_command(ctx, name) for name in self.list_commands(ctx)]
        return [("Commands", [c for c in commands if c is not None and not c.hidden])]

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The subcommands with their whole first sentence (click cuts it to the width)."""
        for title, commands in self.sections(ctx):
            if commands:
                with formatter.section(title):
                    formatter.write_dl([(c.name or "", summary(c)) for c in commands])


db_option = click.option(
    "--db",
    "db_url",
    envvar="STUDY_DB",
    metavar="URL",
    default=None,
    help="Study database: SQLite path or URL (sqlite:///PATH?timeout=S waits S seconds for "
    "another program's lock; default 30), or postgresql+psycopg://... "
    "[default: ./study.db; env STUDY_DB]",
)


participants_option = click.option(
    "--participants",
    "participants_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="A fitted participant model (MODEL.json from `study participants fit`): simulated "
    "people are drawn from its trait distributions [default: the hand-set profiles].",
)


def load_participants(path: Path | None, task: str | None = None) -> ParticipantModel | None:
    """The model at `path` (one line and exit 2 if it is bad), or None."""
    if path is None:
        return None
    # lazy: study.protocol.participant_model (with numpy) costs 0.1 s at start-up
    from study.protocol.participant_model import load_model

    return load_model(path, task)


actor_option = click.option(
    "--actor",
    metavar="NAME",
    default=None,
    help="Who acts, for the audit log and session leases, e.g. an experimenter code "
    "[default: $STUDY_ACTOR, else user@host]",
)


def json_option(
    help: str | None = None, *, required: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """`--json FILE` (as `json_path`): where a command writes its numbers."""
    return click.option(
        "--json",
        "json_path",
        required=required,
        type=click.Path(dir_okay=False, path_type=Path),
        help=help,
    )


def count_option(
    flag: str, default: int, help: str | None = None, *, minimum: int = 1, dest: str | None = None
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """An option taking a whole number of at least `minimum`, its default shown."""
    names = (flag, dest) if dest else (flag,)
    kind = click.IntRange(min=minimum)
    return click.option(*names, type=kind, default=default, show_default=True, help=help)


def positive_option(
    flag: str, default: float | None, help: str | None = None, *, dest: str | None = None
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """An option taking a number above 0, its default shown (None: no default, and the
    help says what applies without one)."""
    names = (flag, dest) if dest else (flag,)
    kind = click.FloatRange(min=0, min_open=True)
    return click.option(*names, type=kind, default=default, show_default=True, help=help)


def file_option(
    flag: str, dest: str, help: str | None = None, *, required: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """An option naming one file (not a folder), as a Path."""
    kind = click.Path(dir_okay=False, path_type=Path)
    return click.option(flag, dest, required=required, type=kind, help=help)


def out_dir_option(
    help: str, required: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """`--out DIR` (as `out_dir`): the folder a command writes its files in."""
    return click.option(
        "--out",
        "out_dir",
        required=required,
        type=click.Path(file_okay=False, path_type=Path),
        help=help,
    )


def progress_bar(*columns: Any, transient: bool = True, console: Console | None = None) -> Progress:
    """The bar long commands show on stderr: by default what runs, k of n done, time
    remaining; `columns`: other Rich columns (Rich is imported only when a command shows
    it)."""
    # lazy: rich.console costs 23 ms at start-up
    from rich.console import Console

    # lazy: rich.progress costs 32 ms at start-up
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    if not columns:
        columns = (
            "[progress.description]{task.description}",
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
        )
    console = console or Console(stderr=True)
    if console.is_terminal:
        return Progress(*columns, transient=transient, console=console)
    # a bar draws nothing on a pipe or a log file: a line every ten seconds there
    from study.commands.progress_lines import LineProgress

    return LineProgress(*columns, console=console)


def progress_status(text: str, console: Console | None = None) -> Status | LineStatus:
    """The spinner long commands show on stderr with the step `text`; where stderr is no
    terminal, a line every ten seconds with the latest step instead."""
    # lazy: rich.console costs 23 ms at start-up
    from rich.console import Console

    console = console or Console(stderr=True)
    if console.is_terminal:
        return console.status(text)
    # lazy: study.commands.progress_lines (with rich) costs 35 ms at start-up
    from study.commands.progress_lines import LineStatus

    return LineStatus(text, console)


def bar_progress(bar: Progress, task: TaskID, *, describe: bool = True) -> progress.Progress:
    """The `teleop_core.progress.Progress` that moves `task` of `bar`: done of total (a
    step without a count leaves the bar's count as it is) and, with `describe`, the step
    as the task's description."""

    def told(step: str, done: int = 0, total: int = 0) -> None:
        fields: dict[str, Any] = {"description": step} if describe else {}
        if total:
            fields.update(completed=done, total=total)
        bar.update(task, **fields)

    return told


def status_progress(status: Status | LineStatus, prefix: str = "") -> progress.Progress:
    """The `teleop_core.progress.Progress` that shows each step on a Rich status line
    (`prefix`, then the step and its count), or that a `LineStatus` writes."""

    if isinstance(status, Heartbeat):
        return as_prefixed(status, prefix)

    def told(step: str, done: int = 0, total: int = 0) -> None:
        status.update(prefix + describe(step, done, total))

    return told


def as_prefixed(heartbeat: progress.Progress, prefix: str) -> progress.Progress:
    """`heartbeat` told every step with `prefix` before it."""

    def told(step: str, done: int = 0, total: int = 0) -> None:
        heartbeat(prefix + step, done, total)

    return told


def write_json_atomically(data: dict[str, Any], path: Path) -> None:
    """JSON to `path` through a temporary sibling, so a failure leaves no partial file
    (numpy numbers are written as plain numbers)."""

    # lazy: teleop_core.files costs 5 ms at start-up
    from teleop_core.files import write_atomically

    write_atomically(path, json.dumps(data, indent=2, default=float) + "\n")


def check_parent_folder(path: Path) -> None:
    """StudyInputError unless the folder a file is to be written in exists."""
    if not path.parent.is_dir():
        raise StudyInputError(f"folder {path.parent} for {path.name} does not exist")


@contextmanager
def opened_database(db_url: str | None) -> Iterator[Engine]:
    """The existing study database of `--db`, disposed of when the block ends."""
    # lazy: db.migrate (with sqlalchemy) costs 0.3 s at start-up
    from db.migrate import open_database

    engine = open_database(db_url, create=False)
    try:
        yield engine
    finally:
        engine.dispose()
