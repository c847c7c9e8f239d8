"""The command-line reference page, written from the `study` command itself.

The site's reference shows what `study COMMAND --help` shows: each command's whole help
text, its usage line, its subcommands with their summaries, and its options as click
writes them in `--help` (`Option.get_help_record`: the flags, the help, the default and
whether it is required). An `Example:` paragraph becomes a shell block.

mkdocs-click did this job before; it renders an option's default from the attribute
itself (click 8.2 and later keep `Sentinel.UNSET` there for "no default"), writes "N/A"
for an option without help and cuts a subcommand's summary at its first line break,
so the page said other things than `--help`. This module uses only click's public
help API, so the two cannot drift apart.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterator

import click

from study.commands.base import StudyGroup, summary

EXAMPLE = "Example:"
"""The head of the paragraph every command's help ends with."""


def walk(
    command: click.Command, ctx: click.Context
) -> Iterator[tuple[click.Command, click.Context]]:
    """`command` and every command below it, depth first, each with its context."""
    yield command, ctx
    if isinstance(command, StudyGroup):
        for _, subs in command.sections(ctx):
            for sub in subs:
                yield from walk(sub, context(sub, sub.name or "", ctx))


def context(command: click.Command, name: str, parent: click.Context | None) -> click.Context:
    """The context `--help` is written in (the group's settings, e.g. `-h`, apply)."""
    return command.make_context(name, [], parent=parent, resilient_parsing=True)


def anchor(ctx: click.Context) -> str:
    """The heading's id: `study-tlx-enter`."""
    return ctx.command_path.replace(" ", "-")


def paragraphs(text: str) -> list[list[str]]:
    """The help text's paragraphs, each a list of lines (click's `\\b` kept as a first
    line where the paragraph is not to be re-wrapped)."""
    out: list[list[str]] = []
    for block in text.strip().split("\n\n"):
        lines = block.splitlines()
        if lines:
            out.append(lines)
    return out


def help_markdown(text: str) -> list[str]:
    """The help text as Markdown: prose paragraphs as they are, the example as a shell
    block, other unwrapped (`\\b`) paragraphs as text blocks."""
    lines: list[str] = []
    for block in paragraphs(inspect.cleandoc(text)):
        kept = block[0].strip() == "\b"
        body = block[1:] if kept else block
        if not body:
            continue
        if body[0].strip() == EXAMPLE:
            code = [line[2:] if line.startswith("  ") else line for line in body[1:]]
            lines += ["**Example:**", "", "```bash", *code, "```", ""]
        elif kept:
            lines += ["```text", *body, "```", ""]
        else:
            lines += [" ".join(line.strip() for line in body), ""]
    return lines


def cell(text: str) -> str:
    """Text for a table cell: one line, pipes escaped."""
    return " ".join(text.split()).replace("|", "\\|")


def command_markdown(command: click.Command, ctx: click.Context, level: int) -> list[str]:
    """One command's section: heading, help, usage, subcommands, options."""
    heading = "#" * min(level, 6)
    lines = [f"{heading} {ctx.command_path} {{ #{anchor(ctx)} }}", ""]
    lines += help_markdown(command.help or "")
    start_here = getattr(command, "start_here", "")
    if start_here:
        lines += [f"**{start_here}**", ""]
    usage = " ".join([ctx.command_path, *command.collect_usage_pieces(ctx)])
    lines += ["```text", usage, "```", ""]
    if isinstance(command, StudyGroup):
        for title, subs in command.sections(ctx):
            lines += [f"| {cell(title.lower())} | what it does |", "|---|---|"]
            for sub in subs:
                link = f"[{sub.name}](#{anchor(ctx)}-{sub.name})"
                lines.append(f"| {link} | {cell(summary(sub))} |")
            lines.append("")
    options = [p for p in command.get_params(ctx) if isinstance(p, click.Option)]
    records = [p.get_help_record(ctx) for p in options]
    rows = [r for r in records if r is not None]
    if rows:
        lines += ["| option | what it is |", "|---|---|"]
        lines += [f"| `{cell(flags)}` | {cell(text)} |" for flags, text in rows]
        lines.append("")
    return lines


def cli_reference(command: click.Command, name: str = "study", level: int = 2) -> str:
    """The Markdown of every command under `command` (the `study` group), in the order
    of `--help`, each under a heading one level below its parent's."""
    root = context(command, name, None)
    depth0 = len(root.command_path.split())
    lines: list[str] = []
    for sub, ctx in walk(command, root):
        depth = len(ctx.command_path.split()) - depth0
        lines += command_markdown(sub, ctx, level + depth)
    return "\n".join(lines) + "\n"
