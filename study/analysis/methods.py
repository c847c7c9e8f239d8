"""The methods as a reviewer reads them: one sentence per analysis for table captions, and
`methods.md`, a paragraph a paper can start from, with the software versions.

The sentences state what `study.analysis.stats` does (test, correction, sums-of-squares
type, df or p method, exact or asymptotic) and nothing it does not; they live beside
the numbers' code so that a change of method is a change of text in one place.
"""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

from study.analysis.crossover_text import design_checks_json, design_checks_paragraph
from study.analysis.mixed_model import DEFAULT_DDF
from study.analysis.stats import ALPHA, DEFAULT_SS_TYPE, EXACT_MAX_N, RESOLUTION_REL

if TYPE_CHECKING:
    from study.analysis.stats import Analysis

PACKAGES = ("haptic-study", "numpy", "scipy", "statsmodels", "pandas", "matplotlib")
"""The packages that compute or draw the results (`COMPUTED_BY` says which does what)."""

COMPUTED_BY = (
    "Shapiro-Wilk (Royston's AS R94, as R's shapiro.test), paired t, Wilcoxon signed-rank "
    "p-values (exact or normal approximation, as R's wilcox.test) and the F, t and normal "
    "distributions (the regularized incomplete beta function and the normal integral), "
    "Hedges' g_av, the rank-biserial correlation, Holm's correction, the mixed ANOVA's "
    "sums of squares (closed form, two conditions): haptic-study's own code with numpy, "
    "checked in its tests against R (afex, stats), scipy and pingouin; the mixed model: "
    "statsmodels' MixedLM (REML), its Satterthwaite and Kenward-Roger df haptic-study's "
    "own code, checked against R's lme4, lmerTest, pbkrtest and emmeans"
)

WILCOXON_RULE = (
    "differences equal to within "
    f"{RESOLUTION_REL:g} of the data's magnitude are treated as equal (and as zero when that "
    "close to zero), so ties come from the data's resolution and not from rounding noise; "
    f"exact p when there are fewer than {EXACT_MAX_N} differences, none zero and none tied "
    "in absolute value; otherwise zero differences are dropped and p is the normal "
    "approximation with tie-corrected variance and continuity correction (the rule of R's "
    "wilcox.test)"
)


def comparison_method() -> str:
    return (
        "VO vs HV within each group on participant means. Shapiro-Wilk on the paired "
        f"differences (alpha = {ALPHA:g}) chooses the test: a two-sided paired t-test (effect "
        "size Hedges' g_av, Lakens 2013) when they look normal, otherwise a two-sided "
        f"Wilcoxon signed-rank test ({WILCOXON_RULE}; statistic V, the sum of the ranks of the "
        "positive HV - VO differences, as R reports it; effect size the matched-pairs "
        "rank-biserial correlation, Kerby 2014). Paired t-tests are reported with their df "
        "(pairs - 1). p (Holm): Holm-corrected across the groups "
        "of each task and measure."
    )


def anova_method(ss_type: int) -> str:
    default = " (the default)" if ss_type == DEFAULT_SS_TYPE else ""
    weighting = (
        "the condition effect is tested on the participant-weighted mean"
        if ss_type == 2
        else "the condition effect is tested on the unweighted mean of the group means"
    )
    return (
        "Mixed ANOVA on participant means: group between, condition within. "
        f"Type {'II' if ss_type == 2 else 'III'} sums of squares{default}, sum-to-zero "
        f"contrasts; with unequal groups {weighting}. "
        "F tests with their exact df (two conditions, so no sphericity correction); effect "
        "size partial eta squared."
    )


def lmm_method(ddf: str = DEFAULT_DDF, references: list[str] | None = None) -> str:
    refs = "; ".join(references or []) or "condition VO, the alphabetically first group"
    return (
        "Linear mixed model over all measured trials, value ~ condition * group + "
        "(1 | participant), fitted by REML (lme4's optimum). "
        f"Treatment coding, reference levels: {refs}; the condition coefficient is the "
        "HV - VO difference in the reference group. The condition effect is reported as "
        "the marginal means of the conditions averaged over the groups with equal weights "
        "and their difference (as emmeans). "
        f"t tests with {ddf} degrees of freedom (as lmerTest"
        + (" and pbkrtest" if ddf == "Kenward-Roger" else "")
        + "), 95 % confidence intervals from the same df. A fit whose participant-intercept "
        "SD is below 1e-4 of the residual SD is reported as singular (lme4's isSingular)."
    )


def _lmm_references(analysis: Analysis) -> list[str]:
    rows = analysis.lmm_rows
    return list(dict.fromkeys(r["reference"] for r in rows if r.get("kind") == "coefficient"))


def software_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def methods_json(analysis: Analysis) -> dict[str, Any]:
    return {
        "comparisons": {
            "unit": "participant means per task x condition",
            "normality": f"Shapiro-Wilk on the paired differences, alpha {ALPHA:g}",
            "tests": {
                "paired_t": "two-sided paired t-test (df = pairs - 1), effect size Hedges' g_av",
                "wilcoxon": "two-sided Wilcoxon signed-rank test, statistic V (sum of "
                "the ranks of the positive HV - VO differences, R's V), "
                "effect size matched-pairs rank-biserial correlation",
            },
            "wilcoxon_p": WILCOXON_RULE,
            "correction": "Holm across the groups of each task x measure",
        },
        "mixed_anova": {
            "ss_type": analysis.ss_type,
            "default_ss_type": DEFAULT_SS_TYPE,
            "contrasts": "sum-to-zero",
            "df": "exact (two conditions: no sphericity correction)",
            "effect_size": "partial eta squared",
        },
        "lmm": {
            "estimation": "REML",
            "p": f"t tests with {analysis.ddf} df",
            "df": analysis.ddf,
            "formula": "value ~ condition * group + (1 | participant)",
            "reference": _lmm_references(analysis),
            "condition_effect": "marginal means averaged over the groups with equal "
            "weights, and their difference (emmeans)",
            "singular": "participant-intercept SD below 1e-4 of the residual SD",
        },
        "design_checks": design_checks_json(),
        "computed_by": COMPUTED_BY,
        "software": software_versions(),
    }


def _groups(analysis: Analysis) -> str:
    sizes: dict[Any, int] = {}
    for r in analysis.descriptive_rows:
        sizes[r["group"]] = max(sizes.get(r["group"], 0), r["n"])
    if not sizes:
        return "no participants"
    return ", ".join(f"{n} {g}" for g, n in sizes.items())


def _invalid(analysis: Analysis) -> str:
    """The sentence naming the trials the experimenter marked invalid, with the reasons."""
    marked = [e.split(": excluded ", 1)[1] for e in analysis.exclusions if "(marked invalid: " in e]
    if not marked:
        return ""
    return (
        f" {len(marked)} measured trial{'s' if len(marked) > 1 else ''} marked invalid by "
        f"the experimenter {'were' if len(marked) > 1 else 'was'} left out: "
        + "; ".join(m.replace("(marked invalid: ", "(") for m in marked)
        + "."
    )


def methods_markdown(analysis: Analysis) -> str:
    """`methods.md`: the statistics paragraph, the data source and the software."""
    counts = ", ".join(f"{n} {d}" for d, n in analysis.source.trials_by_driver.items() if n)
    measures = ", ".join(dict.fromkeys(r["measure"] for r in analysis.descriptive_rows))
    source = (
        f"**{analysis.source.note}.** These results describe simulated participants and "
        "are not evidence about people.\n\n"
        if analysis.source.note
        else ""
    )
    software = ", ".join(f"{k} {v}" for k, v in software_versions().items())
    return (
        "# Statistical methods\n\n"
        f"{source}"
        f"Data: {counts or 'no trials'} (trials by driver); participants per group at most "
        f"{_groups(analysis)}. Measures: {measures or 'none'}. Each participant's trials of "
        "a block were averaged, and participant means were the unit of analysis; "
        "participants without both conditions of a comparison were excluded from it "
        f"({len(analysis.exclusions)} exclusions, listed with the tables).{_invalid(analysis)}\n\n"
        f"{comparison_method()}\n\n"
        f"{anova_method(analysis.ss_type)}\n\n"
        f"{lmm_method(analysis.ddf, _lmm_references(analysis))}\n\n"
        f"{design_checks_paragraph(analysis)}\n\n"
        f"Computed by: {COMPUTED_BY}.\n\n"
        f"Software: {software}.\n"
    )
