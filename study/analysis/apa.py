"""Numbers as APA prints them, with no dependency beyond the standard library.

Apart from `tables` so that the terminal app's analysis screen can format p-values
without importing the statistics (scipy.stats, statsmodels: about 1.9 s), which it
would otherwise load while its screens are mounted, before the run screen is ready
(issue 21).
"""

from __future__ import annotations

import math


def p_text(p: float | None) -> str:
    """p with three decimals and no leading zero; "< .001" below that; "n/a" if unknown.

    >>> p_text(0.0456), p_text(0.0002), p_text(float("nan"))
    ('.046', '< .001', 'n/a')
    """
    if p is None or not math.isfinite(p):
        return "n/a"
    return "< .001" if p < 0.001 else f"{p:.3f}".lstrip("0")
