"""The `study` command: parses arguments and calls the packages; owns no logic of its own.

Every error a user can cause ends here as one line on stderr, `study CMD: error: ...`,
naming the bad value and what was expected, with exit status 2: click's usage errors
(unknown option, bad value, missing argument) and the packages' input errors
(`DbInputError`, `StudyInputError`, `TeleopInputError`, all `ValueError`s).
Subcommands live in `study.commands`, imported only when they are called (`COMMANDS`).
"""

from __future__ import annotations

import gc
import importlib
import sys
from typing import Any

import click

from study.commands.base import USER_ERRORS, InputError, StudyGroup

EXIT_USER_ERROR = 2

COMMANDS = {
    "analyze": "study.commands.analyze:analyze",
    "bench": "study.commands.bench:bench",
    "calibrate": "study.commands.calibrate:calibrate",
    "campaign": "study.commands.campaign:campaign",
    "characterize": "study.commands.characterize:characterize",
    "db": "study.commands.database:database",
    "demo": "study.commands.figures:demo",
    "design": "study.commands.plan:design_group",
    "estimator": "study.commands.estimator:estimator",
    "example-data": "study.commands.example_data:example_data",
    "export": "study.commands.exchange:export_cmd",
    "figures": "study.commands.figures:figures",
    "hardware": "study.commands.hardware:hardware",
    "identify": "study.commands.identify:identify",
    "import": "study.commands.exchange:import_cmd",
    "import-xdf": "study.commands.lsl:import_xdf",
    "init": "study.commands.plan:init",
    "lsl-config": "study.commands.lsl:lsl_config",
    "participant": "study.commands.plan:participant",
    "participants": "study.commands.participants:participants",
    "power": "study.commands.power:power",
    "probe": "study.commands.probe:probe",
    "run": "study.commands.run:run",
    "schedule": "study.commands.plan:schedule_cmd",
    "simulate": "study.commands.simulate:simulate",
    "tlx": "study.commands.tlx:tlx",
    "trial": "study.commands.trial:trial",
    "tui": "study.commands.tui:tui",
}
"""Every subcommand: its name -> "module:attribute", imported when it is called."""


SECTIONS = (
    ("Plan the study", ("design", "init", "participant", "schedule", "power")),
    (
        "Run the sessions",
        ("tui", "run", "hardware", "probe", "tlx", "trial", "import-xdf", "lsl-config"),
    ),
    ("Analyse", ("analyze", "figures", "export", "import")),
    ("Calibrate the robot", ("calibrate", "estimator", "characterize", "identify")),
    ("Simulate", ("demo", "simulate", "participants", "campaign")),
    ("Maintain", ("db", "bench", "example-data")),
)
"""`study --help` lists the commands by the part of the lab's work they belong to, in
the order of a study; a command in no section is listed under "Other"."""

START_HERE = (
    "Start here: `study demo --out demo/` runs a whole simulated study (database, "
    "statistics, figures); `study design template > design.toml` begins a real one. "
    "`study COMMAND --help` shows a command's options and an example."
)


class LazyStudyGroup(StudyGroup):
    """The top-level group: a subcommand's module is imported only when that command runs
    (or `--help` lists them all).

    Importing every command module up front pulled in SQLAlchemy's ORM, numpy and Rich
    for any `study` call, about half a second before `study tui` could start drawing.
    This is the pattern of click's documentation ("Lazily Loading Subcommands"); click
    has no built-in lazy group.
    """

    def __init__(self, *args: Any, lazy: dict[str, str], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy = lazy

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy})

    def get_command(self, ctx: click.Context | None, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in self.lazy:
            module, _, attribute = self.lazy[cmd_name].partition(":")
            command = getattr(importlib.import_module(module), attribute)
            if command.name != cmd_name:  # pragma: no cover - a wrong COMMANDS entry
                raise RuntimeError(f"{self.lazy[cmd_name]} is {command.name!r}, not {cmd_name!r}")
            self.add_command(command)
        return self.commands.get(cmd_name)

    start_here = START_HERE

    def sections(self, ctx: click.Context) -> list[tuple[str, list[click.Command]]]:
        """The commands by the part of the lab's work they belong to (`SECTIONS`)."""
        listed = {name for _, names in SECTIONS for name in names}
        others = tuple(n for n in self.list_commands(ctx) if n not in listed)
        out = []
        for title, names in (*SECTIONS, ("Other", others)):
            commands = [self.get_command(ctx, name) for name in names]
            shown = [c for c in commands if c is not None and not c.hidden]
            if shown:
                out.append((title, shown))
        return out

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """A "start here" line, then the commands by section."""
        formatter.write_paragraph()
        formatter.write_text(self.start_here)
        super().format_commands(ctx, formatter)


@click.group(
    cls=LazyStudyGroup,
    lazy=COMMANDS,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    no_args_is_help=True,
)
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=lambda ctx, _param, value: _print_version(ctx) if value else None,
    help="Show the version and exit.",
)
def cli() -> None:
    """haptic-study: plan, run, store and analyse haptic teleoperation user studies.

    The database is ./study.db unless --db URL or the STUDY_DB environment variable
    names another (an SQLite path or URL, or postgresql+psycopg://... for multi-site
    studies).

    \b
    Example:
      study demo --out demo/
      study design template > design.toml
    """


def _print_version(ctx: click.Context) -> None:
    """`study --version`, read from the installed metadata (click's version_option would
    need the version whenever `study` starts)."""
    # lazy: importlib.metadata costs `study tui` some 30 ms at start-up
    from importlib.metadata import PackageNotFoundError, version

    try:
        installed = version("haptic-study")
    except PackageNotFoundError:  # running from a source tree that was never installed
        installed = "0+unknown"
    click.echo(f"study, version {installed}")
    ctx.exit()


def _one_line(message: str) -> str:
    return " ".join(part.strip() for part in message.strip().splitlines() if part.strip())


def _command_path(args: list[str]) -> str:
    """`study SUB CMD` as far as `args` name known commands (for errors without a context)."""
    path = ["study"]
    group: click.Command = cli
    for token in args:
        if not isinstance(group, click.Group):
            break
        command = group.get_command(click.Context(group), token)
        if command is None:
            break
        path.append(token)
        group = command
    return " ".join(path)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `study` console script; returns the exit status."""
    args = sys.argv[1:] if argv is None else argv
    try:
        result = cli.main(args, prog_name="study", standalone_mode=False)
    except click.exceptions.NoArgsIsHelpError as exc:
        click.echo(exc.format_message())
        return 0
    except InputError as exc:
        click.echo(f"{exc.ctx.command_path}: error: {_one_line(exc.message)}", err=True)
        return EXIT_USER_ERROR
    except click.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx is not None else _command_path(args)
        message = _one_line(exc.format_message())
        click.echo(f"{where}: error: {message} (see `{where} --help`)", err=True)
        return EXIT_USER_ERROR
    except click.ClickException as exc:  # e.g. a file that cannot be opened
        click.echo(f"study: error: {_one_line(exc.format_message())}", err=True)
        return EXIT_USER_ERROR
    except USER_ERRORS as exc:  # raised outside any command
        click.echo(f"study: error: {_one_line(str(exc))}", err=True)
        return EXIT_USER_ERROR
    except click.exceptions.Abort:
        click.echo("study: aborted", err=True)
        return 130
    except click.exceptions.Exit as exc:
        return exc.exit_code
    return result if isinstance(result, int) else 0


def entry() -> None:
    """The `study` console script (and `python -m study.cli`): `main`, then exit.

    Before the interpreter exits, the command's garbage is collected once (every
    finaliser of what it made runs here) and what is left, the imported modules, is
    frozen out of the collector: the collections of the interpreter's own shutdown then
    skip the hundreds of thousands of objects that scipy, pandas, statsmodels and
    pingouin create at import, which otherwise cost a short command such as `study
    analyze` a large share of its CPU time (`benchmarks/analyze_vs_r.py` measures it).
    Tests call `main`, which leaves the collector alone.
    """
    status = main()
    gc.collect()
    gc.freeze()
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    entry()
