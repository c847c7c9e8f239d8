"""What a person types, read strictly: the option and argument types of every command.

click's INT and FLOAT convert with Python's `int()` and `float()`, which take far more
than a person means by a number: `5_0`, Devanagari or Arabic-Indic digits, ` 7 `
and `1_000.5` all read as numbers. A NASA-TLX rating of `5_0` stored as 50 is nonsense
accepted. Every `study` command's number types are swapped here, when the command is
built (`strict_params`, called by `study.commands.base.StudyCommand`), for subclasses
that first require the text to be ASCII digits (a sign, a decimal point and an exponent
for decimals), then convert as click does, ranges included. Text options and arguments
refuse the empty string (no option of `study` means anything by `--db ''`, `--out ''`
or `--participant ''`: each silently meant the default before) and control characters.

Subclasses rather than a callback on each option, so that the commands' declarations
(and the options added later) need nothing: a declared `click.IntRange(0, 100)` stays
one, with its bounds, its help text and its error message.
"""

from __future__ import annotations

import re
import stat
from pathlib import Path
from typing import Any

import click

from study.errors import StudyInputError

WHOLE = re.compile(r"[+-]?[0-9]+")
DECIMAL = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
NON_FINITE = {"nan", "+nan", "-nan", "inf", "+inf", "-inf", "infinity", "+infinity", "-infinity"}
"""Spellings that reach the option's own check (`refuse_non_finite` names them)."""


def _check_text(
    value: Any, param: click.Parameter | None, ctx: click.Context | None, kind: click.ParamType
) -> None:
    if not isinstance(value, str):
        return
    if value == "":
        optional = param is not None and not param.required
        default = " (leave the option out for its default)" if optional else ""
        kind.fail(f"an empty value; expected a value{default}", param, ctx)
    if not value.isprintable():
        kind.fail(
            f"{value!r} holds control characters; expected printable text on one line", param, ctx
        )


def _check_number(
    value: Any,
    param: click.Parameter | None,
    ctx: click.Context | None,
    kind: click.ParamType,
    pattern: re.Pattern[str],
    expected: str,
) -> None:
    if not isinstance(value, str):
        return
    if pattern.fullmatch(value) or (pattern is DECIMAL and value.lower() in NON_FINITE):
        return
    kind.fail(f"{value!r}; expected {expected} in ASCII digits", param, ctx)


class StrictInt(click.types.IntParamType):
    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_number(value, param, ctx, self, WHOLE, "a whole number")
        return super().convert(value, param, ctx)


class StrictIntRange(click.IntRange):
    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_number(value, param, ctx, self, WHOLE, "a whole number")
        return super().convert(value, param, ctx)


class StrictFloat(click.types.FloatParamType):
    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_number(value, param, ctx, self, DECIMAL, "a decimal number")
        return super().convert(value, param, ctx)


class StrictFloatRange(click.FloatRange):
    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_number(value, param, ctx, self, DECIMAL, "a decimal number")
        return super().convert(value, param, ctx)


class StrictString(click.types.StringParamType):
    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_text(value, param, ctx, self)
        return super().convert(value, param, ctx)


class StrictPath(click.Path):
    """A path that is not empty (`--out ''` wrote into the current folder) and holds no
    control character."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        _check_text(value, param, ctx, self)
        path = super().convert(value, param, ctx)
        kind = _kind(Path(path)) if isinstance(path, str | Path) else None
        if kind is not None and kind != "a folder" and not self.file_okay:
            self.fail(f"{value!r} is {kind}; expected a folder (made if missing)", param, ctx)
        if kind is not None and kind not in ("a file", "a folder") and self.dir_okay is False:
            self.fail(f"{value!r} is {kind}; expected a regular file", param, ctx)
        return path


def _kind(path: Path) -> str | None:
    """What `path` is (None: nothing there)."""

    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return "a file"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "no regular file"


def _range(kind: type[click.IntRange | click.FloatRange], t: Any) -> click.ParamType:
    return kind(t.min, t.max, min_open=t.min_open, max_open=t.max_open, clamp=t.clamp)


def strict_type(t: click.ParamType) -> click.ParamType:
    """The strict counterpart of a click type (`t` itself where there is none)."""
    if type(t) is click.IntRange:
        return _range(StrictIntRange, t)
    if type(t) is click.FloatRange:
        return _range(StrictFloatRange, t)
    if type(t) is click.types.IntParamType:
        return StrictInt()
    if type(t) is click.types.FloatParamType:
        return StrictFloat()
    if type(t) is click.types.StringParamType:
        return StrictString()
    if type(t) is click.Path:
        strict = StrictPath()
        strict.__dict__.update(t.__dict__)
        return strict
    if isinstance(t, click.Tuple):
        t.types = [strict_type(inner) for inner in t.types]
    return t


def strict_params(params: list[click.Parameter]) -> None:
    """Give every parameter its strict type (in place; flags keep theirs)."""
    for p in params:
        if isinstance(p, click.Option) and p.is_flag:
            continue
        p.type = strict_type(p.type)


def comma_list(
    flag: str, text: str, allowed: tuple[str, ...] | None = None, *, unique: bool = True
) -> list[str]:
    """The items of a comma-separated option value, each stripped: an empty item
    (`pdf,,png`, a trailing comma), an item not `allowed`, or (when `unique`) one given
    twice is refused with one line naming it."""

    items = [item.strip() for item in text.split(",")]
    among = f" of {','.join(allowed)}" if allowed else ""
    expected = f"expected a comma-separated list{among}"
    if not text.strip() or "" in items:
        raise StudyInputError(f"{flag} {text!r} has an empty item; {expected}")
    for k, item in enumerate(items):
        if allowed is not None and item not in allowed:
            raise StudyInputError(f"{flag} {text!r}: {item!r} is not one; {expected}")
        if unique and item in items[:k]:
            raise StudyInputError(f"{flag} {text!r} names {item!r} twice; {expected}, each once")
    return items
