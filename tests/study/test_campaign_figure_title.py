"""A campaign figure's title says what it plots: power or the effect, against the swept
factor, or at the one sample size a campaign without a swept factor draws (its name,
which may promise a curve, comes after)."""

from __future__ import annotations

import pandas as pd

from study.campaign.figures import plot_factor, plotted


def _summary(scales: list[float]) -> pd.DataFrame:
    rows = []
    for scale in scales:
        for group, n in (("outsider", 3), ("novice", 3), ("expert", 4)):
            n = round(n * scale)
            rows.append(
                {
                    "group_scale": scale,
                    "group": group,
                    "measure": "completion_time_s",
                    "n": n,
                    "power": 0.5,
                    "power_ci_low": 0.3,
                    "power_ci_high": 0.7,
                    "effect_mean": -0.4,
                    "effect_ci_low": -0.8,
                    "effect_ci_high": 0.0,
                }
            )
    return pd.DataFrame(rows)


def test_one_sample_size_is_titled_as_one() -> None:
    summary = _summary([1.0])
    title = plotted(summary, ["group_scale"], None, "power")
    assert title == (
        "Power of HV vs VO (p < .05) per group at one sample size "
        "(outsider 3, novice 3, expert 4; group_scale 1)"
    )
    fig = plot_factor(summary, ["group_scale"], None, "power", "Power against sample size")
    drawn = fig._suptitle.get_text()
    assert drawn.startswith(title)
    assert '"Power against sample size"' in drawn
    assert "simulated participants" in drawn


def test_a_swept_factor_is_titled_against_it() -> None:
    summary = _summary([1.0, 2.0])
    assert plotted(summary, ["group_scale"], "group_scale", "effect") == (
        "Effect of HV vs VO (Hedges' g_av, HV - VO) per group against group size scale (2 values)"
    )
