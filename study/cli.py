"""The `study` command: parses arguments and calls the packages; owns no logic of its own.

Every error a user can cause ends here as one line on stderr, `study CMD: error: ...`,
naming the bad value and what was expected, with exit status 2: click's usage errors
(unknown option, bad value, missing argument) and the packages' input errors
(`DbInputError`, `StudyInputError`, `TeleopInputError`, all `ValueError`s).
Subcommand groups live in `study.commands`, one module each.
"""

from __future__ import annotations

import sys

import click

from study import __version__
from study.commands.analyze import analyze
from study.commands.base import USER_ERRORS, InputError, StudyGroup
from study.commands.bench import bench
from study.commands.calibrate import calibrate
from study.commands.characterize import characterize
from study.commands.database import database
from study.commands.estimator import estimator
from study.commands.exchange import export_cmd, import_cmd
from study.commands.figures import demo, figures
from study.commands.identify import identify
from study.commands.plan import design_group, init, participant, schedule_cmd
from study.commands.power import power
from study.commands.run import run
from study.commands.simulate import simulate
from study.commands.tlx import tlx
from study.commands.tui import tui

EXIT_USER_ERROR = 2


@click.group(
    cls=StudyGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    no_args_is_help=True,
)
@click.version_option(__version__, prog_name="study")
def cli() -> None:
    """haptic-study: plan, run, store and analyse haptic teleoperation user studies.

    The database is ./study.db unless --db URL or the STUDY_DB environment variable
    names another (an SQLite path or URL, or postgresql+psycopg://... for multi-site
    studies).
    """


cli.add_command(database)
cli.add_command(bench)
cli.add_command(estimator)
cli.add_command(simulate)
cli.add_command(init)
cli.add_command(design_group)
cli.add_command(participant)
cli.add_command(schedule_cmd)
cli.add_command(run)
cli.add_command(tlx)
cli.add_command(import_cmd)
cli.add_command(export_cmd)
cli.add_command(analyze)
cli.add_command(figures)
cli.add_command(demo)
cli.add_command(power)
cli.add_command(tui)
cli.add_command(calibrate)
cli.add_command(characterize)
cli.add_command(identify)


def _one_line(message: str) -> str:
    return " ".join(part.strip() for part in message.strip().splitlines() if part.strip())


def _command_path(args: list[str]) -> str:
    """`study SUB CMD` as far as `args` name known commands (for errors without a context)."""
    path, group = ["study"], cli
    for token in args:
        command = group.commands.get(token) if isinstance(group, click.Group) else None
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
