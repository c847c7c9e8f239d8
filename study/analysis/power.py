"""Power of the VO-HV comparison by simulation, at the design's unequal group sizes.

R's Superpower computes power analytically for balanced designs only; the study's
20/8/8 groups are not, so power comes from simulating the design and running the
analysis's own tests on each simulated study.

Model per participant i of group g (outcome in SD units of one condition):
VO_i = u_i + e_i1, HV_i = u_i + delta_g + e_i2, u ~ N(0, rho), e ~ N(0, 1 - rho);
`rho` is the correlation between a participant's two conditions and `delta_g` the
group's standardised effect in per-condition SDs (HV - VO over the SD of one
condition). The differences' SD is sqrt(2 (1 - rho)), so Cohen's d_z of the paired
differences is delta_g / sqrt(2 (1 - rho)) (`dz_of`): equal to delta_g only at rho = .5.

- Within each group: the analysis's rule (`paired.paired_p`: Shapiro-Wilk on the
  differences, then the paired t-test or the signed-rank test), and then Holm's
  correction across the groups, as `study analyze` applies it: a group's power is the
  rate of Holm-adjusted p < alpha (`groups`; the uncorrected rate is
  `groups_uncorrected`).
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

from study.analysis.comparisons import holm
from study.analysis.paired import paired_p
from study.analysis.stats import ALPHA
from teleop_core.progress import Progress, no_progress

SCALES = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
"""Group sizes of the power curve, as multiples of the design's."""


CORRECTION = "Holm across the groups (as study analyze)"
"""The correction the per-group power applies."""


def dz_of(effect: float, rho: float) -> float:
    """Cohen's d_z of the paired differences of an effect in per-condition SDs."""
    return float(effect / np.sqrt(2 * (1 - rho)))


@dataclass(frozen=True)
class PowerResult:
    sizes: dict[str, int]
    groups: dict[str, float]
    """Per group, the rate of Holm-adjusted p < alpha (`CORRECTION`)."""
    interaction: float | None
    """Rejection rate of the group x condition test (see `interaction_is_power`)."""
    effects: dict[str, float] = field(default_factory=dict)
    """The standardised effect simulated in each group (per-condition SDs)."""
    groups_uncorrected: dict[str, float] = field(default_factory=dict)
    """Per group, the rate of unadjusted p < alpha."""

    @property
    def interaction_is_power(self) -> bool:
        """False when every group has the same effect: no interaction exists, so the
        interaction's rejection rate is a type I error rate."""
        return len(set(self.effects.values())) > 1


def simulate_power(
    sizes: dict[str, int],
    effects: dict[str, float],
    rho: float,
    n_sim: int,
    rng: np.random.Generator,
    progress: Progress = no_progress,
) -> PowerResult:
    hits = dict.fromkeys(sizes, 0)
    raw_hits = dict.fromkeys(sizes, 0)
    interaction_hits = 0
    for i in range(n_sim):
        diffs, p = [], []
        for group, n in sizes.items():
            u = rng.normal(0.0, np.sqrt(rho), n)
            vo = u + rng.normal(0.0, np.sqrt(1 - rho), n)
            hv = u + effects[group] + rng.normal(0.0, np.sqrt(1 - rho), n)
            p.append(paired_p(vo, hv))
            diffs.append(hv - vo)
        for group, raw, adjusted in zip(sizes, p, holm(np.array(p)), strict=True):
            raw_hits[group] += raw < ALPHA
            hits[group] += adjusted < ALPHA
        if len(diffs) > 1:
            interaction_hits += stats.f_oneway(*diffs).pvalue < ALPHA
        progress("simulated studies", i + 1, n_sim)
    return PowerResult(
        sizes=dict(sizes),
        groups={g: hits[g] / n_sim for g in sizes},
        interaction=interaction_hits / n_sim if len(sizes) > 1 else None,
        effects={g: float(effects[g]) for g in sizes},
        groups_uncorrected={g: raw_hits[g] / n_sim for g in sizes},
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
