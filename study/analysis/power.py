"""Power of the VO-HV comparison by simulation, at the design's unequal group sizes.

R's Superpower computes power analytically for balanced designs only; the study's
20/8/8 groups are not, so power comes from simulating the design and running the
analysis's own tests on each simulated study.

Model per participant i of group g (outcome in SD units of one condition):
VO_i = u_i + e_i1, HV_i = u_i + delta_g + e_i2, u ~ N(0, rho), e ~ N(0, 1 - rho);
`rho` is the correlation between a participant's two conditions and `delta_g` the
group's standardised effect (HV - VO over the per-condition SD).

- Within each group: the analysis's rule (Shapiro-Wilk on the differences, then the
  paired t-test or the Wilcoxon signed-rank test), p < alpha.
- Group x condition interaction: with two conditions it is exactly the one-way ANOVA
  across groups of the paired differences (F and p identical to the mixed ANOVA's
  interaction term), which is what is computed. Its rejection rate is power only when
  the groups' effects differ; with equal effects there is no interaction and the rate is
  the test's type I error rate (about alpha), which `PowerResult.interaction_is_power`
  says and the figure labels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from study.analysis.stats import ALPHA, wilcoxon_signed_rank
from teleop_core.progress import Progress, no_progress

SCALES = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
"""Group sizes of the power curve, as multiples of the design's."""


@dataclass(frozen=True)
class PowerResult:
    sizes: dict[str, int]
    groups: dict[str, float]
    interaction: float | None
    """Rejection rate of the group x condition test (see `interaction_is_power`)."""
    effects: dict[str, float] = field(default_factory=dict)
    """The standardised effect simulated in each group."""

    @property
    def interaction_is_power(self) -> bool:
        """False when every group has the same effect: no interaction exists, so the
        interaction's rejection rate is a type I error rate."""
        return len(set(self.effects.values())) > 1


def _group_test(vo: np.ndarray, hv: np.ndarray) -> float:
    """The p of `compare_conditions`' rule, with its Wilcoxon (R's exact/asymptotic rule,
    not scipy's version-dependent default)."""
    diff = hv - vo
    normal = stats.shapiro(diff).pvalue >= ALPHA
    return float(stats.ttest_rel(hv, vo).pvalue if normal else wilcoxon_signed_rank(diff)[1])


def simulate_power(
    sizes: dict[str, int],
    effects: dict[str, float],
    rho: float,
    n_sim: int,
    rng: np.random.Generator,
    progress: Progress = no_progress,
) -> PowerResult:
    hits = dict.fromkeys(sizes, 0)
    interaction_hits = 0
    for i in range(n_sim):
        diffs = []
        for group, n in sizes.items():
            u = rng.normal(0.0, np.sqrt(rho), n)
            vo = u + rng.normal(0.0, np.sqrt(1 - rho), n)
            hv = u + effects[group] + rng.normal(0.0, np.sqrt(1 - rho), n)
            hits[group] += _group_test(vo, hv) < ALPHA
            diffs.append(hv - vo)
        if len(diffs) > 1:
            interaction_hits += stats.f_oneway(*diffs).pvalue < ALPHA
        progress("simulated studies", i + 1, n_sim)
    return PowerResult(
        sizes=dict(sizes),
        groups={g: hits[g] / n_sim for g in sizes},
        interaction=interaction_hits / n_sim if len(sizes) > 1 else None,
        effects={g: float(effects[g]) for g in sizes},
    )


def power_curve(
    sizes: dict[str, int],
    effects: dict[str, float],
    rho: float,
    n_sim: int,
    seed: int,
    progress: Progress = no_progress,
    scales: tuple[float, ...] = SCALES,
) -> list[tuple[float, PowerResult]]:
    out = []
    for k, scale in enumerate(scales):
        scaled = {g: max(3, round(n * scale)) for g, n in sizes.items()}
        rng = np.random.default_rng([seed, k])

        def told(step: str, i: int = 0, _n: int = 0, before: int = k * n_sim) -> None:
            progress(step, before + i, len(scales) * n_sim)  # counted over every scale

        out.append((scale, simulate_power(scaled, effects, rho, n_sim, rng, told)))
    return out
