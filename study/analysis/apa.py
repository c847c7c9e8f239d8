"""Numbers as APA prints them, with no dependency beyond the standard library.

Apart from `tables` so that the terminal app's analysis screen can format p-values
without importing the statistics (scipy.stats, statsmodels: about 1.9 s), which it
would otherwise load while its screens are mounted, before the run screen is ready.
"""

from __future__ import annotations

import math

STAR_LEVELS = (0.05, 0.01, 0.001)
"""The significance marks' thresholds (`figcheck.stars`): a printed p never rounds across
one of them, so the text and the figure's stars agree."""


def p_text(p: float | None) -> str:
    """p as APA prints it: three decimals and no leading zero; "< .001" below that,
    "> .999" above; "n/a" if unknown. Where three decimals would round p onto or across
    a significance threshold (.04996 -> ".050" beside a "*"), more decimals are printed
    until the text is on the same side as p (".04996").

    >>> p_text(0.0456), p_text(0.0002), p_text(float("nan")), p_text(1.0), p_text(0.04996)
    ('.046', '< .001', 'n/a', '> .999', '.04996')
    """
    if p is None or not math.isfinite(p):
        return "n/a"
    if p < 0.001:
        return "< .001"
    if p > 0.999:
        return "> .999"
    for digits in range(3, 10):
        shown = round(p, digits)
        if all((shown < level) == (p < level) for level in STAR_LEVELS):
            return f"{p:.{digits}f}".lstrip("0")
    return f"{p:.10f}".lstrip("0")


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
