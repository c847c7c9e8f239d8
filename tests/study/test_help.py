"""Help a person can start from, checked from the click commands themselves.

`study --help` lists the commands by the lab's day with a "start here" line; every
option of every command has a help text; every command's help ends with an example
whose options that command accepts; every summary is a whole sentence; and the
generated reference page shows what `--help` shows (no `Sentinel.UNSET`, no "N/A").
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Iterator

import click
import pytest

from study.cli import SECTIONS, cli, main
from study.commands.base import summary
from study.commands.reference import EXAMPLE, cli_reference, context, walk


def every_command() -> Iterator[tuple[str, click.Command, click.Context]]:
    for command, ctx in walk(cli, context(cli, "study", None)):
        yield ctx.command_path, command, ctx


COMMANDS = list(every_command())
IDS = [path for path, _, _ in COMMANDS]


def example_lines(command: click.Command) -> list[str]:
    """The lines of the help's `Example:` paragraph, continuation lines joined."""
    text = (command.help or "").replace("\b", "")
    paragraphs = [p.strip().splitlines() for p in re.split(r"\n\s*\n", text) if p.strip()]
    found = [p for p in paragraphs if p[0].strip() == EXAMPLE]
    if not found:
        return []
    joined: list[str] = []
    for line in (line.strip() for line in found[-1][1:]):
        if joined and joined[-1].endswith("\\"):
            joined[-1] = joined[-1][:-1] + " " + line
        else:
            joined.append(line)
    return joined


def test_an_example_line_is_read_as_a_shell_would() -> None:
    def fake() -> None:
        """Do it.

        \b
        Example:
          study tlx enter --participant P001 \\
              --mental 55
        """

    command = click.command("x")(fake)
    assert example_lines(command) == ["study tlx enter --participant P001  --mental 55"]


@pytest.mark.parametrize(("path", "command", "ctx"), COMMANDS, ids=IDS)
def test_every_option_has_help(path: str, command: click.Command, ctx: click.Context) -> None:
    bare = [
        p.opts[0]
        for p in command.get_params(ctx)
        if isinstance(p, click.Option) and not p.hidden and not (p.help or "").strip()
    ]
    assert not bare, f"{path}: options without help: {bare}"


@pytest.mark.parametrize(("path", "command", "ctx"), COMMANDS, ids=IDS)
def test_every_command_shows_an_example_it_accepts(
    path: str, command: click.Command, ctx: click.Context
) -> None:
    lines = example_lines(command)
    assert lines, f"{path}: its help has no Example: paragraph"
    for line in lines:
        words = shlex.split(line, comments=True)
        for stop in (">", "&&", "|"):
            if stop in words:
                words = words[: words.index(stop)]
        words = [w for w in words if w != "..."]
        assert words[0] == "study", line
        # walk the groups down to the command the example calls, then parse its options
        target: click.Command = cli
        parent = None
        rest = words[1:]
        name = "study"
        while isinstance(target, click.Group) and rest and not rest[0].startswith("-"):
            parent = context(target, name, parent)
            name, rest = rest[0], rest[1:]
            found = target.get_command(parent, name)
            assert found is not None, f"{path}: example {line!r} names no command {name!r}"
            target = found
        if not isinstance(target, click.Group):
            # every option the example gives is one the command has (click refuses others)
            target.make_context(name, list(rest), parent=parent, resilient_parsing=True)
            flags = {f for p in target.params for f in (*p.opts, *p.secondary_opts)}
            given = {w.split("=")[0] for w in rest if w.startswith("--")}
            assert given <= flags, f"{path}: example {line!r} gives {sorted(given - flags)}"


@pytest.mark.parametrize(("path", "command", "ctx"), COMMANDS, ids=IDS)
def test_every_summary_is_a_whole_sentence(
    path: str, command: click.Command, ctx: click.Context
) -> None:
    text = summary(command)
    assert text.endswith("."), f"{path}: summary {text!r} does not end a sentence"
    assert not text.endswith(("Fig.", "eq.", "Figs.", "e.g.")), f"{path}: {text!r} is cut"


def test_the_top_help_groups_the_commands_by_the_lab_day(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "Start here: `study demo --out demo/`" in out
    heads = [line[:-1] for line in out.splitlines() if line.endswith(":") and line[0] != " "]
    assert heads == ["Options", *(title for title, _ in SECTIONS)]
    # every command once, under its section, in the section's order
    listed = re.findall(r"^  ([a-z][\w-]*)  ", out, re.MULTILINE)
    ctx = context(cli, "study", None)
    assert sorted(listed) == sorted(cli.list_commands(ctx))
    assert listed == [name for _, names in SECTIONS for name in names]
    # summaries are whole: the dial's bench is not cut at "Figs."
    assert main(["bench", "--help"]) == 0
    assert "Figs. 10-11 of the endovascular haptics paper" in " ".join(
        capsys.readouterr().out.split()
    )


def test_the_reference_shows_what_help_shows() -> None:
    page = cli_reference(cli)
    assert "Sentinel" not in page
    assert "N/A" not in page
    assert "[endovascular]" not in page
    assert "Start here" in page
    for path, command, ctx in COMMANDS:
        for param in command.get_params(ctx):
            record = param.get_help_record(ctx) if isinstance(param, click.Option) else None
            if record is not None:
                flags, text = record
                row = f"| `{flags.replace('|', chr(92) + '|')}` | "
                assert row in page, f"{path}: {flags} missing from the reference"
                assert " ".join(text.split()).replace("|", "\\|") in page, f"{path}: {flags}"
        assert f"{{ #{path.replace(' ', '-')} }}" in page
