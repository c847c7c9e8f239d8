"""Numbers as APA prints them, with no dependency beyond the standard library.

Apart from `tables` so that the terminal app's analysis screen can format p-values
without importing the statistics (scipy.stats, statsmodels: about 1.9 s), which it
would otherwise load while its screens are mounted, before the run screen is ready.
"""

from __future__ import annotations

import math
import re

STAR_LEVELS = (0.05, 0.01, 0.001)
"""The significance marks' thresholds (`figcheck.stars`): a printed p never rounds across
one of them, so the text and the figure's stars agree."""


def p_text(p: float | None) -> str:
    """p as APA prints it: three decimals and no leading zero; "< .001" below that,
    "> .999" above; "n/a" if unknown. Where three decimals would round p onto or across
    a significance threshold (.04996 -> ".050" beside a "*"), the threshold itself is
    printed as the bound ("< .05"): never more than three decimals, and the text stays on
    the same side of every threshold as p (and as the figure's stars).

    >>> p_text(0.0456), p_text(0.0002), p_text(float("nan")), p_text(1.0), p_text(0.04996)
    ('.046', '< .001', 'n/a', '> .999', '< .05')
    """
    if p is None or not math.isfinite(p):
        return "n/a"
    if p < 0.001:
        return "< .001"
    if p > 0.999:
        return "> .999"
    shown = round(p, 3)
    crossed = [level for level in STAR_LEVELS if p < level <= shown]
    if crossed:
        return "< " + f"{min(crossed):g}".lstrip("0")
    return f"{p:.3f}".lstrip("0")


def p_eq(p: float | None) -> str:
    """'p = .047', 'p < .001', 'p > .999' or 'p = n/a'."""
    text = p_text(p)
    return f"p {text}" if text.startswith(("<", ">")) else f"p = {text}"


ALPHA_SIGN = "\N{GREEK SMALL LETTER ALPHA}"
"""The significance level's symbol, as APA writes it."""


def alpha_text(alpha: float) -> str:
    """A significance level as APA prints it: no leading zero.

    >>> alpha_text(0.05)
    '.05'
    """
    return f"{alpha:g}".lstrip("0")


def bounded_text(x: float | None, digits: int = 2) -> str:
    """A statistic that cannot exceed 1 in size (a correlation, partial eta squared), with
    no leading zero (APA 6.36); "n/a" if unknown.

    >>> bounded_text(0.6532), bounded_text(-0.25), bounded_text(1.0)
    ('.65', '-.25', '1.00')
    """
    if x is None or not math.isfinite(x):
        return "n/a"
    text = f"{x:.{digits}f}"
    return text.replace("0.", ".", 1) if text.lstrip("-").startswith("0.") else text


_MARKDOWN_SPECIAL = re.compile(r"[\\|`]|<(?=[A-Za-z/!?])|&(?=#?\w+;)")
"""What a Markdown table cell escapes: the column separator, the backslash that would
escape it, inline code, and a `<` or `&` that would start raw HTML or an entity (`p <
.001` stays as it is)."""


def markdown_escape(value: object) -> str:
    r"""A table cell's text as Markdown shows it literally, on one line.

    >>> markdown_escape("a|b<i>")
    'a\\|b&lt;i>'
    """
    text = " ".join(str(value).split())
    return _MARKDOWN_SPECIAL.sub(
        lambda m: {"<": "&lt;", "&": "&amp;"}.get(m.group(0), "\\" + m.group(0)), text
    )
