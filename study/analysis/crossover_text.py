"""The crossover's checks in words: the methods paragraph, the JSON description and the
table cells (`crossover` computes them; `methods` and `tables` place them).

Apart from `crossover` so that the text can be written from `analysis.json`'s rows
without the statistics, and so that a change of wording is a change in one place.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from study.analysis.apa import p_eq, p_text

if TYPE_CHECKING:
    from study.analysis.stats import Analysis

EFFECT_WORDS = {
    "period": "period effect (second block minus first)",
    "carry_over": "carry-over (VO after HV minus HV after VO)",
    "trial_position": "trial position (slope per trial within a block)",
}
ALPHA_TEXT = ".05"


def design_checks_method() -> str:
    """The checks' method, one paragraph (captions and methods.md)."""
    return (
        "Crossover checks: for each task and measure, the mixed model value ~ condition * "
        "group + (1 | participant) was extended by three terms. The period effect is each "
        "participant's second block of the task minus the first. The differential "
        "carry-over is VO after HV minus HV after VO, estimable between participants only. "
        "When a block held several trials, the trial position within the block entered "
        "too, centred, as a slope per trial. Each term was tested by its t with "
        "Satterthwaite df; where the participant variance was estimated at zero (a "
        "singular fit), the period and the trial position were tested against the "
        "within-participant residual, participants as fixed effects. All checks of the "
        "study were one "
        f"family, Holm-corrected; a check with a corrected p below {ALPHA_TEXT} was added "
        "to the model, and the HV - VO effect (marginal means over the groups) is reported "
        "before and after. Where a carry-over was added, the first-period comparison "
        "(first block only, between participants) is reported too."
    )


def design_checks_json() -> dict[str, Any]:
    return {
        "effects": dict(EFFECT_WORDS),
        "test": "t test of the added term in the mixed model, Satterthwaite df",
        "singular_fit": (
            "period and trial position tested against the within-participant residual "
            "(participants as fixed effects)"
        ),
        "correction": "Holm across every check of the study",
        "added_when": f"p_holm < {ALPHA_TEXT}",
        "condition_effect": "HV - VO marginal contrast, groups weighted equally",
    }


def _estimate(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3g}"


def _found(analysis: Analysis) -> str:
    """What the checks found, in words."""
    checks = analysis.design_checks
    if not checks:
        return (
            "No crossover checks could be made (the trials carry no block order or too "
            "few participants)."
        )
    added = [r for r in checks if r["added"]]
    if not added:
        low = min(checks, key=lambda r: r["p_holm"])
        return (
            f"None of the {len(checks)} checks called for a term; the model was kept as it "
            f"was. The smallest corrected p was that of the "
            f"{EFFECT_WORDS[low['effect']].split(' (')[0]} of {low['task']}/{low['measure']}, "
            f"{p_eq(low['p_holm'])}."
        )
    parts = []
    for r in added:
        before, after = r["condition_before"], r["condition_after"]
        parts.append(
            f"{r['task']}/{r['measure']}: a {EFFECT_WORDS[r['effect']]} of "
            f"{_estimate(r['estimate'])} (95 % CI {_estimate(r['ci'][0])} to "
            f"{_estimate(r['ci'][1])}, corrected {p_eq(r['p_holm'])}) was added; the "
            f"HV - VO effect was {_estimate(before['estimate'])} ({p_eq(before['p'])}) "
            f"before and {_estimate(after['estimate'])} ({p_eq(after['p'])}) after"
        )
    first = [f for f in analysis.design_fit if f.get("first_period")]
    for f in first:
        fp = f["first_period"]
        parts.append(
            f"{f['task']}/{f['measure']}, first period only ({fp['participants']} "
            f"participants, between participants): HV - VO {_estimate(fp['estimate'])} "
            f"(95 % CI {_estimate(fp['ci'][0])} to {_estimate(fp['ci'][1])}, "
            f"{p_eq(fp['p'])})"
        )
    return f"Of {len(checks)} checks, {len(added)} called for a term. " + "; ".join(parts) + "."


def design_checks_paragraph(analysis: Analysis) -> str:
    """methods.md's paragraph: what was checked and what was found."""
    return f"{design_checks_method()} {_found(analysis)}"


def _effect_text(c: dict[str, Any]) -> str:
    return f"{_estimate(c['estimate'])} ({p_eq(c['p'])})"


def design_checks_cells(checks: list[dict[str, Any]]) -> tuple[tuple[str, ...], list[list[Any]]]:
    """The design-checks table's header and formatted cells."""
    header = ("task", "measure", "effect", "estimate", "95 % CI", "p", "p (Holm)", "added",
              "HV - VO before", "HV - VO after")  # fmt: skip
    cells = [
        [
            r["task"],
            r["measure"],
            r["effect"].replace("_", " "),
            _estimate(r["estimate"]),
            f"[{_estimate(r['ci'][0])}, {_estimate(r['ci'][1])}]",
            p_text(r["p"]),
            p_text(r["p_holm"]),
            "yes" if r["added"] else "no",
            _effect_text(r["condition_before"]),
            _effect_text(r["condition_after"]),
        ]
        for r in checks
    ]
    return header, cells
