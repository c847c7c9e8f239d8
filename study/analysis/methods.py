"""The methods as a paper takes them: one sentence per analysis for table captions, and
`methods.md`, short paragraphs in APA style (the data and exclusions, the tests, the
results as APA sentences, the software).

The sentences state what the analysis does (test, correction, sums-of-squares type,
exact or asymptotic p) and nothing of how it is programmed; they live beside the
numbers' code so that a change of method is a change of text in one place. The APA
numbers (`t(7) = 2.41, p = .047`) are `apa_results`'.
"""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

from study.analysis.apa import ALPHA_SIGN, alpha_text, markdown_escape
from study.analysis.apa_results import comparison_sentence, exclusion_sentences, success_sentence
from study.analysis.crossover_text import design_checks_json, design_checks_paragraph
from study.analysis.mixed_model import DEFAULT_DDF
from study.analysis.paired import RESOLUTION_DIGITS
from study.analysis.signed_rank import EXACT_MAX_N
from study.analysis.stats import ALPHA, DEFAULT_SS_TYPE

if TYPE_CHECKING:
    from study.analysis.stats import Analysis

PACKAGES = (
    "haptic-study",
    "numpy",
    "scipy",
    "pandas",
    "pingouin",
    "statsmodels",
    "matplotlib",
)
"""The packages that compute or draw the results (`COMPUTED_BY` says which does what)."""

COMPUTED_BY = (
    "scipy.stats: Shapiro-Wilk, paired t, TOST, t and F distributions, the noncentral t "
    "interval of d_z; pingouin: Holm's correction and the JZS Bayes factor; statsmodels: "
    "the exact McNemar test and the mixed model's REML fit (MixedLM); haptic-study: the "
    "exact conditional signed-rank distribution, the mixed ANOVA's sums of squares and the "
    "mixed model's Satterthwaite and Kenward-Roger df, checked against R's coin, afex, "
    "lme4, lmerTest, pbkrtest and emmeans"
)

WILCOXON_RULE = (
    f"below {EXACT_MAX_N} pairs its p is exact: the permutation distribution of the "
    "observed ranks, ties and zeros included; zeros are ranked and carry no sign "
    f"(Pratt, 1959). From {EXACT_MAX_N} pairs on, p is the normal approximation of that "
    "distribution"
)


def comparison_method() -> str:
    """The paired comparisons in short sentences (captions and methods.md)."""
    return (
        "HV was compared with VO within each group on the participant means. "
        "Differences were compared at the resolution of the data (to "
        f"{RESOLUTION_DIGITS} significant digits), so rounding error decides no test. "
        f"A Shapiro-Wilk test ({ALPHA_SIGN} = {alpha_text(ALPHA)}) on the differences "
        "chose the test: a "
        "two-sided paired t-test when they did not depart from normality, otherwise a "
        "two-sided Wilcoxon signed-rank test. "
        "When every difference was the same, no t statistic exists and the signed-rank "
        "test was used. When every difference was zero, the comparison was not testable "
        "and is reported so, outside the Holm family. "
        f"For the signed-rank test, {WILCOXON_RULE}; V is the sum of the ranks of the "
        "positive differences. "
        "Effect sizes: the mean difference HV - VO with its 95 % CI; Cohen's d_z with "
        "its 95 % CI from the noncentral t distribution; Hedges' g_av, corrected with "
        "n - 1 df (Lakens, 2013); and for the signed-rank test the matched-pairs "
        "rank-biserial correlation (Kerby, 2014). "
        "p values were Holm-corrected across the testable groups of each task and "
        "measure; each row names its family."
    )


def evidence_method(bounds_text: str) -> str:
    """The equivalence test and the Bayes factor."""
    tost = (
        "Equivalence was tested with two one-sided paired t-tests (TOST; Schuirmann, 1987) "
        f"against the design's bounds ({bounds_text}); equivalence is shown when the "
        "TOST p is below .05."
        if bounds_text
        else "The design sets no equivalence bounds, so no equivalence test was run."
    )
    return (
        f"{tost} BF10 is the JZS Bayes factor of the paired t-test, with a Cauchy prior "
        "of scale √2/2 on the standardised effect (Rouder et al., 2009); BF10 below "
        "1/3 favours no difference, above 3 a difference."
    )


def success_method() -> str:
    return (
        "A participant succeeded in a condition when every measured trial of the block "
        "succeeded. Success in VO and HV was compared within each group with an exact "
        "McNemar test, Holm-corrected across the groups."
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
    refs = (
        "; ".join(map(markdown_escape, references or []))
        or "condition VO, the alphabetically first group"
    )
    return (
        "Linear mixed model over all trials, value ~ condition * group + "
        "(1 | participant), fitted by REML. "
        f"Treatment coding, reference levels: {refs}; the condition coefficient is the "
        "HV - VO difference in the reference group. The condition effect is reported as "
        "the marginal means of the conditions averaged over the groups with equal weights "
        "and their difference (as emmeans). "
        f"t tests with {ddf} degrees of freedom, as in lmerTest"
        + (" and pbkrtest" if ddf == "Kenward-Roger" else "")
        + "; 95 % confidence intervals from the same df. A fit whose participant-intercept "
        "SD is below 0.0001 times the residual SD is reported as singular."
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
            "normality": "Shapiro-Wilk on the paired differences, "
            f"{ALPHA_SIGN} = {alpha_text(ALPHA)}",
            "tests": {
                "paired_t": "two-sided paired t-test (df = pairs - 1), effect size Hedges' "
                "g_av (correction with n - 1 df) beside Cohen's d_z with its CI",
                "wilcoxon": "two-sided Wilcoxon signed-rank test, statistic V (sum of "
                "the ranks of the positive HV - VO differences), "
                "effect size matched-pairs rank-biserial correlation",
                "none": "not testable: every difference is zero",
            },
            "wilcoxon_p": WILCOXON_RULE,
            "constant_differences": "no t statistic: the exact signed-rank test; all "
            "zero: not testable, outside the Holm family",
            "resolution": f"differences compared to {RESOLUTION_DIGITS} significant digits "
            "of the data's magnitude",
            "correction": "Holm across the testable groups of each task x measure "
            "(holm_family names them)",
            "equivalence": {
                "test": "TOST, two one-sided paired t-tests",
                "fraction_of_vo_mean": analysis.bounds.fraction,
                "absolute": dict(analysis.bounds.absolute),
            },
            "bayes_factor": "JZS BF10, Cauchy prior scale √2/2 (Rouder et al. 2009)",
        },
        "success": success_method(),
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
            "singular": "participant-intercept SD below 0.0001 times the residual SD",
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
    return ", ".join(f"{n} {markdown_escape(g)}" for g, n in sizes.items())


def _data(analysis: Analysis) -> str:
    """The data paragraph: the trials by driver, the groups, the measures, who was left out."""
    total = sum(analysis.source.trials_by_driver.values())
    drivers = ", ".join(f"{n} {d}" for d, n in analysis.source.trials_by_driver.items() if n)
    tasks = ", ".join(analysis.tasks) or "no task"
    measures = ", ".join(dict.fromkeys(r["measure"] for r in analysis.descriptive_rows))
    sentences = [
        f"The analysis used {total} trials of {tasks} ({drivers or 'none'}).",
        *_forces_sentence(analysis),
        *_end_sentence(analysis),
        f"Participants per group: at most {_groups(analysis)}.",
        f"Measures: {measures or 'none'}.",
        "Each participant's trials of a block were averaged; participant means were the "
        "unit of analysis.",
        *exclusion_sentences(analysis.exclusions),
    ]
    return " ".join(sentences)


def _forces_sentence(analysis: Analysis) -> list[str]:
    """Where the forces came from, when any trial's were measured on a physical phantom,
    or when people drove a simulated follower (their actions measured, not the forces)."""
    forces = analysis.forces_by_source
    measured = forces.get("measured", 0)
    simulated = forces.get("simulated", 0)
    people = simulated - analysis.source.simulated  # keyboard and dial-only hardware trials
    if measured:
        sentence = (
            f"The forces of {measured} of them were measured, with the real drive in a "
            "physical phantom (the proximal reference and distal forces from the lab's "
            "sensors, the proximal estimate from the drive's current)"
        )
        if simulated:
            sentence += f"; those of {simulated} came from the simulated follower and phantom"
        return [sentence + "."]
    if people > 0:
        return [
            f"The forces of the {people} trials people drove came from the simulated "
            "follower and phantom (no drive unit in the loop)."
        ]
    return []


def _end_sentence(analysis: Analysis) -> list[str]:
    """Who decided the success and completion time of the physical-phantom trials
    (nothing in the loop sees the tip there)."""
    ends = analysis.ends
    if not ends:
        return []
    said = [
        f"{ends[key]} by {who}"
        for key, who in (
            ("button", "the participant's button"),
            ("experimenter", "the experimenter"),
        )
        if ends.get(key)
    ]
    sentence = (
        f"On the physical phantom a person judged when the tip reached the target, which "
        f"ended the trial as a success: {' and '.join(said) or 'in no trial'}"
    )
    limit = ends.get("time_limit", 0)
    if limit:
        sentence += f"; {limit} reached the time limit and count as failures"
    return [sentence + "."]


def _results(analysis: Analysis) -> str:
    lines = [f"- {comparison_sentence(r)}" for r in analysis.comparison_rows]
    lines += [f"- {success_sentence(r)}" for r in analysis.success_rows]
    return "\n".join(lines) or "No comparison could be tested."


def methods_markdown(analysis: Analysis) -> str:
    """`methods.md`: the data, the methods, the results in APA style, every exclusion."""
    source = (
        f"**{analysis.source.note}.** These results describe simulated participants and "
        "are not evidence about people.\n\n"
        if analysis.source.note
        else ""
    )
    software = ", ".join(f"{k} {v}" for k, v in software_versions().items())
    exclusions = "\n".join(f"- {e}" for e in analysis.exclusions) or "None."
    return (
        "# Statistical methods\n\n"
        f"{source}"
        f"{_data(analysis)}\n\n"
        f"{comparison_method()}\n\n"
        f"{evidence_method(analysis.bounds.describe())}\n\n"
        f"{success_method()}\n\n"
        f"{anova_method(analysis.ss_type)}\n\n"
        f"{lmm_method(analysis.ddf, _lmm_references(analysis))}\n\n"
        f"{design_checks_paragraph(analysis)}\n\n"
        "## Results of the paired comparisons\n\n"
        f"{_results(analysis)}\n\n"
        "## Exclusions\n\n"
        f"{exclusions}\n\n"
        f"Software: {software}.\n"
    )
