"""What the participant model cannot explain: the data's structure the traits lack.

A simulated participant is the same person in every trial: it neither learns nor tires,
and it does not remember which condition came first. Real people do. So after the fit,
the data are checked against people simulated from the fitted model with the same
design (`simulated`: same trials per condition, both orders), on three counts, and what
is found is reported rather than absorbed into the traits:

- **trend over trials** (learning or fatigue): each participant's slope of the log
  measure over their trial position, within condition (the condition means removed, so
  the HV - VO difference does not pass for a trend); the observed participants' slopes
  against the simulated ones, Welch's t-test (`scipy.stats.ttest_ind`). Needs >= 2
  trials per condition.
- **condition order**: each participant's HV - VO difference of the log measure; its
  mean in VO-first minus HV-first participants (a period effect shows here), observed
  against simulated: z = (d_obs - d_sim) / sqrt(se_obs^2 + se_sim^2), normal p.
- The trend and order tests of every measure are one family, Holm-corrected at
  `ALPHA` (`holm_flags`: statsmodels' `multipletests(method="holm")`'s values and
  rejections, without the garbage collection it runs on every call, which costs the
  more the larger the fit's heap).
- **group means the fitted model does not reproduce** (`summary_misfit`, a posterior
  predictive check): per group, measure and condition (VO, HV and each person's HV - VO),
  the observed people's means against the simulated people's, Welch's t-test, Holm over
  all of them at `ALPHA` as a family of its own. The simulated people are fitted to the
  observed, so the check is conservative; what it flags, no trait setting the fit chose
  reproduces (a trait held at its prior may be why, and the line says so).
- **a gap beyond its interval** (`summary_gaps`): per group, measure and condition, the
  observed people's mean against the simulated people's, by the interval of their gap:
  the two means' 95 % intervals (`summaries`) combined in quadrature on each side, on
  the log scale (the ratio observed / simulated) for a condition's mean of a positive
  measure, on the measure's own for the HV - VO difference. A gap whose interval
  excludes zero is a lack the line names, with its interval, even when the Welch test
  above does not pass Holm over every summary (with 4 people a group it seldom can): a
  reader sees the gap in the table and the figure, and the line must not say "nothing".
- **a participant no trait setting reproduces**: the smallest Mahalanobis distance D^2
  between the person's moments and the emulator's over the free traits (the others at
  the group's fitted means; L-BFGS-B within the emulator's range), with the covariance
  of the trial noise over the person's k trials plus what the group's spread of the
  fixed traits adds (over draws from the fitted model). D^2 is calibrated on the people
  simulated from the fit: c = their D^2's `CALIBRATION_Q` quantile over the chi-square's,
  matched in the upper tail rather than at the median because the trial noise has long
  tails (a peak force's spikes, a time capped at the give-up) and the emulator fits
  worse near the edge of its design; neither must flag a person. A person is an outlier
  when D^2 / c exceeds the
  chi-square quantile at 1 - OUTLIER_ALPHA / n (Bonferroni over the participants), with
  df = moments - free traits.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import minimize

from study.analysis.participant_fit.emulator import MomentEmulator, log_moment
from study.analysis.participant_fit.summaries import condition_values

ALPHA = 0.05
"""Family-wise error rate of the trend and order tests."""
Z95 = float(stats.norm.ppf(0.975))
"""The two-sided 95 % normal quantile (1.96)."""
OUTLIER_ALPHA = 0.01
"""Family-wise error rate of the outlier rule (Bonferroni over participants)."""
CALIBRATION_Q = 0.9
"""The quantile at which the simulated people's D^2 calibrates the chi-square scale."""


def holm_flags(rows: Sequence[dict[str, Any]], alpha: float) -> None:
    """Set each row's `p_holm` and `flagged` by Holm's step-down over the rows' `p` at
    `alpha`: statsmodels' `multipletests(p, alpha, "holm")` line for line (a NaN p is
    a member of the family, sorted last, as there; `study.analysis.stats.holm` leaves
    it out)."""
    p = np.array([r["p"] for r in rows], dtype=float)
    order = np.argsort(p)
    steps = np.arange(len(p), 0, -1)
    above = p[order] > alpha / steps
    reject = np.ones(len(p), bool)
    reject[order[np.argmax(above) :] if above.any() else []] = False
    adjusted = np.empty(len(p))
    adjusted[order] = np.minimum(np.maximum.accumulate(p[order] * steps), 1.0)
    for r, flag, ph in zip(rows, reject, adjusted, strict=True):
        r["p_holm"], r["flagged"] = float(ph), bool(flag)


def slopes(trials: pd.DataFrame, measure: str) -> pd.Series:
    """Per participant: the slope of the log measure over trial position, within
    condition (log units per trial); NaN with fewer than 2 trials in every condition."""
    frame = trials.assign(y=log_moment(trials[measure]), x=trials["position"].astype(float))
    keys = ["participant", "condition"]
    frame["dx"] = frame["x"] - frame.groupby(keys)["x"].transform("mean")
    frame["dy"] = frame["y"] - frame.groupby(keys)["y"].transform("mean")
    sums = (
        frame.assign(xy=frame["dx"] * frame["dy"], xx=frame["dx"] ** 2)
        .groupby("participant")[["xy", "xx"]]
        .sum()
    )
    return (sums["xy"] / sums["xx"].where(sums["xx"] > 0)).rename(measure)


def order_contrast(trials: pd.DataFrame, measure: str) -> tuple[float, float, int]:
    """(mean HV - VO of the log measure in VO-first minus HV-first people, its SE, people)."""
    y = trials.assign(y=log_moment(trials[measure]))
    wide = y.groupby(["participant", "order", "condition"])["y"].mean().unstack()
    d = (wide["HV"] - wide["VO"]).dropna().reset_index()
    a, b = d.loc[d["order"] == "VO-first", 0], d.loc[d["order"] == "HV-first", 0]
    if len(a) < 2 or len(b) < 2:
        return float("nan"), float("nan"), len(d)
    return float(a.mean() - b.mean()), float(np.sqrt(a.var() / len(a) + b.var() / len(b))), len(d)


def trend_and_order(
    observed: pd.DataFrame, simulated: pd.DataFrame, measures: Sequence[str]
) -> list[dict[str, Any]]:
    """One row per (check, measure): observed and simulated statistic, p, p_holm, flagged."""
    rows: list[dict[str, Any]] = []
    for m in measures:
        so, ss = slopes(observed, m).dropna(), slopes(simulated, m).dropna()
        if len(so) >= 2 and len(ss) >= 2:
            p = float(stats.ttest_ind(so, ss, equal_var=False).pvalue)
            rows.append(
                {
                    "check": "trend",
                    "measure": m,
                    "observed_pct_per_trial": 100 * float(np.expm1(so.mean())),
                    "simulated_pct_per_trial": 100 * float(np.expm1(ss.mean())),
                    "participants": len(so),
                    "p": p,
                }
            )
        do, se_o, n = order_contrast(observed, m)
        ds, se_s, _ = order_contrast(simulated, m)
        if np.isfinite(do) and np.isfinite(ds):
            z = (do - ds) / np.hypot(se_o, se_s)
            rows.append(
                {
                    "check": "order",
                    "measure": m,
                    "observed_vo_first_minus_hv_first_pct": 100 * float(np.expm1(do)),
                    "simulated_vo_first_minus_hv_first_pct": 100 * float(np.expm1(ds)),
                    "participants": n,
                    "p": float(2 * stats.norm.sf(abs(z))),
                }
            )
    if rows:
        holm_flags(rows, ALPHA)
    return rows


def min_distance(
    emulator: MomentEmulator,
    y: np.ndarray,
    k: int,
    mean: np.ndarray,
    free: list[int],
    fixed_cov: np.ndarray,
) -> float:
    """Smallest D^2 of one person's moments `y` over the free traits' settings."""
    inv = np.linalg.inv(emulator.person_noise_cov() / k + fixed_cov)
    low, high = emulator.box_

    def d2(x: np.ndarray) -> float:
        theta = mean.copy()
        theta[free] = x
        r = y - emulator.log_moments(theta)[0]
        return float(r @ inv @ r)

    if not free:
        return d2(np.array([]))
    scale = high[free] - low[free]
    out = minimize(
        lambda u: d2(low[free] + u * scale),
        (mean[free] - low[free]) / scale,
        method="L-BFGS-B",
        bounds=[(0.0, 1.0)] * len(free),
    )
    return float(out.fun)


def outliers(
    emulator: MomentEmulator,
    people: pd.DataFrame,
    simulated: pd.DataFrame,
    means: dict[str, np.ndarray],
    fixed_cov: dict[str, np.ndarray],
    free: list[int],
) -> dict[str, Any]:
    """The outlier rule over the observed `people` (person_moments frames), calibrated on
    the `simulated` people; `fixed_cov[group]`: the moments' covariance from the spread of
    the traits not in `free` (the ones searched over)."""
    names = emulator.moments_

    def distances(frame: pd.DataFrame) -> pd.Series:
        return pd.Series(
            {
                p: min_distance(
                    emulator,
                    row[names].to_numpy(float),
                    int(row["k"]),
                    means[row["group"]],
                    free,
                    fixed_cov[row["group"]],
                )
                for p, row in frame.iterrows()
            },
            dtype=float,
        )

    df = len(names) - len(free)
    sim = distances(simulated)
    c = max(
        float(np.percentile(sim, 100 * CALIBRATION_Q)) / stats.chi2.ppf(CALIBRATION_Q, df), 1e-9
    )
    obs = distances(people)
    scaled = {p: float(d / c) for p, d in obs.items()}
    limit = float(stats.chi2.ppf(1 - OUTLIER_ALPHA / max(len(obs), 1), df))
    return {
        "rule": f"D^2 / c > chi2({df}) quantile at 1 - {OUTLIER_ALPHA}/n",
        "calibration_c": round(c, 4),
        "simulated_max": round(float(sim.max() / c), 3),
        "limit": round(limit, 3),
        "df": df,
        "moments": list(names),
        "distance": {p: round(d, 3) for p, d in scaled.items()},
        "flagged": sorted(p for p, d in scaled.items() if d > limit),
    }


def summary_misfit(
    observed: pd.DataFrame,
    simulated: pd.DataFrame,
    measures: Sequence[str],
    groups: Sequence[str],
    held: Sequence[str] = (),
) -> dict[str, Any]:
    """Rows per (group, measure, condition): observed and simulated mean of the people's
    means, Welch's p, p_holm and flagged; `held`: the traits held at their priors (named
    in the line as a possible cause)."""
    rows: list[dict[str, Any]] = []
    pairs = zip(
        condition_values(observed, measures, groups),
        condition_values(simulated, measures, groups),
        strict=True,
    )
    for (group, m, label, a), (*_, b) in pairs:
        if len(a) < 2 or len(b) < 2:
            continue
        p = float(stats.ttest_ind(a, b, equal_var=False).pvalue)
        rows.append(
            {
                "group": group,
                "measure": m,
                "condition": label,
                "observed": float(a.mean()),
                "simulated": float(b.mean()),
                "p": p if np.isfinite(p) else 1.0,
            }
        )
    if rows:
        holm_flags(rows, ALPHA)
    return {"rows": rows, "flagged": [r for r in rows if r["flagged"]], "held": list(held)}


def _gap(obs: np.ndarray, sim: np.ndarray) -> tuple[float, float, float]:
    """(gap, low, high): observed minus simulated mean and the gap's 95 % interval from
    the two means' intervals (each (mean, low, high)), each side's half-widths in
    quadrature."""
    o, o_lo, o_hi = obs
    s, s_lo, s_hi = sim
    gap = float(o - s)
    low = gap - float(np.hypot(max(o - o_lo, 0.0), max(s_hi - s, 0.0)))
    high = gap + float(np.hypot(max(o_hi - o, 0.0), max(s - s_lo, 0.0)))
    return gap, low, high


def summary_gaps(table: pd.DataFrame, difference: str) -> dict[str, Any]:
    """The summaries (`summaries.summaries`' frame) whose observed mean lies beyond the
    simulated one by more than their gap's 95 % interval allows: rows of group, measure,
    condition, observed, simulated, their intervals, and the gap's (`gap_scale`: `ratio`
    for a condition's mean, observed / simulated; `difference` for the conditions'
    difference, labelled `difference`); `flagged` those whose gap's interval excludes
    zero."""
    keys = ["group", "measure", "condition"]
    obs = table[table["source"] == "observed"].set_index(keys)
    sim = table[table["source"] == "simulated"].set_index(keys)
    rows = []
    for key, o in obs.iterrows():
        if key not in sim.index:
            continue
        s = sim.loc[key]
        cols = ["mean", "ci_low", "ci_high"]
        a, b = o[cols].to_numpy(float), s[cols].to_numpy(float)
        if not np.all(np.isfinite([*a, *b])):
            continue
        # a condition's mean of a positive measure: the gap as a ratio, on the log scale
        ratio = key[2] != difference and bool(np.all(a > 0) and np.all(b > 0))
        gap, low, high = _gap(np.log(a), np.log(b)) if ratio else _gap(a, b)
        rows.append(
            {
                **dict(zip(keys, key, strict=True)),
                "observed": float(o["mean"]),
                "observed_ci95": [float(o["ci_low"]), float(o["ci_high"])],
                "simulated": float(s["mean"]),
                "simulated_ci95": [float(s["ci_low"]), float(s["ci_high"])],
                "gap_scale": "ratio" if ratio else "difference",
                "gap": float(np.exp(gap)) if ratio else gap,
                "gap_ci95": [float(np.exp(low)), float(np.exp(high))] if ratio else [low, high],
                "flagged": bool(low > 0 or high < 0),
            }
        )
    return {
        "rule": "observed minus simulated mean (their ratio for a condition's mean of a "
        "positive measure), 95 % interval from the two means' intervals in quadrature on "
        "each side; flagged when it excludes no gap",
        "rows": rows,
        "flagged": [r for r in rows if r["flagged"]],
    }


def _gap_text(r: dict[str, Any]) -> str:
    low, high = r["gap_ci95"]
    gap = (
        f"observed / simulated {r['gap']:.2f}, 95 % {low:.2f}-{high:.2f}"
        if r["gap_scale"] == "ratio"
        else f"observed - simulated {r['gap']:+.3g}, 95 % {low:+.3g} to {high:+.3g}"
    )
    return (
        f"{r['group']} {r['condition']} {r['measure']} ({r['observed']:.3g} observed vs "
        f"{r['simulated']:.3g} simulated: {gap})"
    )


def _check_parts(rows: list[dict[str, Any]]) -> list[str]:
    """The flagged trend and condition-order checks, as the line names them."""
    parts = []
    for r in rows:
        if not r["flagged"]:
            continue
        if r["check"] == "trend":
            parts.append(
                f"a trend over trials in {r['measure']} "
                f"({r['observed_pct_per_trial']:+.1f} %/trial observed vs "
                f"{r['simulated_pct_per_trial']:+.1f} % simulated, "
                f"p_holm = {r['p_holm']:.2g})"
            )
        else:
            parts.append(
                f"an effect of condition order on {r['measure']} (VO-first minus "
                f"HV-first {r['observed_vo_first_minus_hv_first_pct']:+.1f} % "
                f"observed vs {r['simulated_vo_first_minus_hv_first_pct']:+.1f} % "
                f"simulated, p_holm = {r['p_holm']:.2g})"
            )
    return parts


def _misfit_part(misfit: dict[str, Any] | None) -> list[str]:
    """The group means the fitted model does not reproduce (Holm), if any."""
    if misfit is None or not misfit["flagged"]:
        return []
    held = (
        f" (held at their priors, and perhaps why: {', '.join(misfit['held'])}; "
        "--weak-traits shrink fits them)"
        if misfit["held"]
        else ""
    )
    means = ", ".join(
        f"{r['group']} {r['condition']} {r['measure']} ({r['observed']:.3g} observed vs "
        f"{r['simulated']:.3g} simulated, p_holm = {r['p_holm']:.2g})"
        for r in misfit["flagged"]
    )
    return [f"group means the fitted model does not reproduce: {means}{held}"]


def _gap_part(misfit: dict[str, Any] | None, gaps: dict[str, Any] | None) -> list[str]:
    """The gaps beyond their own 95 % interval that the misfit test did not flag."""
    tested_misfit = {
        (r["group"], r["measure"], r["condition"]) for r in (misfit or {}).get("flagged", [])
    }
    beyond = [
        r
        for r in (gaps or {}).get("flagged", [])
        if (r["group"], r["measure"], r["condition"]) not in tested_misfit
    ]
    if not beyond:
        return []
    return [
        "group means the fitted model misses beyond their gap's 95 % interval (each "
        "summary's own interval; not significant after Holm over every summary): "
        + ", ".join(_gap_text(r) for r in beyond)
    ]


def lacks_line(
    rows: list[dict[str, Any]],
    outlier: dict[str, Any],
    misfit: dict[str, Any] | None = None,
    gaps: dict[str, Any] | None = None,
) -> str:
    """The one printed line: what the participant model lacks, or that nothing was found."""
    parts = _check_parts(rows)
    if outlier["flagged"]:
        parts.append(
            f"participant(s) {', '.join(outlier['flagged'])} that no trait setting "
            f"reproduces (D^2 above {outlier['limit']:.1f})"
        )
    parts += _misfit_part(misfit) + _gap_part(misfit, gaps)
    if parts:
        return "what the participants lack: " + "; ".join(parts)
    tested = [
        *sorted({r["check"] for r in rows}),
        "outliers",
        *(["group means"] if misfit is not None else []),
        *(["gaps"] if gaps is not None else []),
    ]
    line = f"what the participants lack: nothing the checks found ({', '.join(tested)})"
    widest = _widest_gap((gaps or {}).get("rows", []))
    if widest is not None:
        line += (
            f"; the largest gap, {_gap_text(widest)}, lies within its 95 % interval "
            "(too few people to tell it from chance, not shown to be nothing)"
        )
    return line


def _widest_gap(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The gap (`summary_gaps`' rows) nearest its interval's edge: the largest share of
    its half-width towards no gap that it spans (on the log scale for a ratio)."""

    def share(r: dict[str, Any]) -> float:
        gap, (low, high) = r["gap"], r["gap_ci95"]
        if r["gap_scale"] == "ratio":
            gap, low, high = np.log(gap), np.log(low), np.log(high)
        half = gap - low if gap > 0 else high - gap
        return float(abs(gap) / half) if half > 0 else 0.0

    spans = [r for r in rows if share(r) > 0]
    return max(spans, key=share) if spans else None


def emulator_check(
    table: pd.DataFrame,
    for_simulated: dict[tuple[str, str, str], float] | None = None,
    design_sd: dict[tuple[str, str, str], float] | None = None,
) -> dict[str, Any]:
    """The emulator against the people simulated from the fit: the estimates rest on the
    emulator's surface, the `simulated` summaries on the simulator itself. Per group,
    measure and condition (VO, HV, HV-VO): the emulator's mean for the population the
    simulated people were drawn from (`for_simulated`, by (group, measure, condition):
    the fit's replicates, `fit.replicate_prediction`; else the `model` rows' best-fit
    prediction) and whether it lies inside a 95 % interval of its difference from the
    simulated people's mean. Both are noisy: the people's mean by their sampling (the
    `simulated` row's bootstrap interval) and the emulator's by its finite design
    (`design_sd`, its SD over refits to resamples of the design,
    `fit.replicate_design_sd`); the interval adds the two in quadrature on each side
    (mean -/+ sqrt(half-width^2 + (1.96 design SD)^2)), so an emulator that agrees with
    the simulator leaves about 5 % outside. Without `design_sd` the people's interval
    alone. Each row also holds the best-fit prediction and whether the people's
    interval alone holds it. The printed line says how many lie outside, and the
    largest relative gap."""
    keys = ["group", "measure", "condition"]
    model = table[table["source"] == "model"].set_index(keys)
    simulated = table[table["source"] == "simulated"].set_index(keys)
    rows = []
    for key, sim in simulated.iterrows():
        # the emulator's own prediction (the `model` row's mean is corrected by the
        # discrepancy these same simulated people measure)
        best = float(model.loc[key, "emulator" if "emulator" in model.columns else "mean"])
        predicted = (for_simulated or {}).get(key, best)
        noise = float((design_sd or {}).get(key, 0.0))
        mean, low, high = float(sim["mean"]), float(sim["ci_low"]), float(sim["ci_high"])
        wide = (
            mean - float(np.hypot(mean - low, Z95 * noise)),
            mean + float(np.hypot(high - mean, Z95 * noise)),
        )
        rows.append(
            {
                **dict(zip(keys, key, strict=True)),
                "emulator": predicted,
                "emulator_best_fit": best,
                "emulator_design_sd": noise,
                "simulated": mean,
                "simulated_ci95": [low, high],
                "interval95": [wide[0], wide[1]],
                "inside": bool(wide[0] <= predicted <= wide[1]),
                "inside_people_only": bool(low <= predicted <= high),
                "inside_best_fit": bool(low <= best <= high),
            }
        )
    outside = [r for r in rows if not r["inside"]]
    counted = "the people's and the emulator's design noise" if design_sd else "the people's"
    if not outside:
        line = (
            f"the emulator's predictions lie inside the intervals of people simulated from "
            f"the fit ({len(rows)} summaries; 95 % intervals of {counted})"
        )
    else:
        worst = max(outside, key=lambda r: abs(r["emulator"] - r["simulated"]))
        line = (
            f"the emulator's prediction lies outside the interval of people simulated from "
            f"the fit in {len(outside)} of {len(rows)} summaries (95 % intervals of "
            f"{counted}; largest gap: "
            f"{worst['group']} {worst['condition']} {worst['measure']} {worst['emulator']:.3g} "
            f"vs {worst['simulated']:.3g}): the trait estimates rest on the emulator"
        )
    return {
        "rows": rows,
        "outside": len(outside),
        "outside_people_only": sum(not r["inside_people_only"] for r in rows),
        "outside_best_fit": sum(not r["inside_best_fit"] for r in rows),
        "compared": "the emulator's mean over the replicates the simulated people were drawn from"
        if for_simulated
        else "the emulator's prediction at the best fit",
        "interval": "95 % interval of the emulator's prediction minus the simulated people's "
        "mean: the people's bootstrap interval (their sampling) widened on each side by the "
        "emulator's design noise in quadrature (its prediction's SD over its mean surfaces "
        "refitted to bootstrap resamples of the design's settings, no new simulations)"
        if design_sd
        else "95 % bootstrap interval of the simulated people's mean (their sampling only)",
        "line": line,
    }
