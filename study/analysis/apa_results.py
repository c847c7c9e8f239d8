"""The analysis' results and exclusions as sentences in APA style (methods.md, tables).

`comparison_sentence` prints one comparison (`t(7) = 2.41, p = .047`, "< .001", no
leading zero on p or on a correlation, each effect size with its interval);
`exclusion_sentences` turns the exclusion lines of `Analysis.exclusions` into sentences
a paper can take (the withdrawals stated, the invalid trials with their task, the
questionnaires without pairwise choices); `success_sentence` prints a McNemar test.
"""

from __future__ import annotations

import math
import re
from typing import Any

from study.analysis.apa import bounded_text, markdown_escape, p_eq

Row = dict[str, Any]


def _num(x: float | None, digits: int = 2) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _sig(x: float | None) -> str:
    """A value in the measure's unit, to three significant digits."""
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3g}"


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and math.isfinite(x)


def _t_numbers(r: Row) -> list[str]:
    """The t-based numbers every comparison with a spread has."""
    parts = [
        f"M(HV - VO) = {_sig(r['mean_diff'])}, 95 % CI [{_sig(r['diff_ci_low'])}, "
        f"{_sig(r['diff_ci_high'])}]",
        f"d_z = {_num(r['dz'])}, 95 % CI [{_num(r['dz_ci_low'])}, {_num(r['dz_ci_high'])}]",
    ]
    if _finite(r.get("g_av")):
        parts.append(f"g_av = {_num(r['g_av'])}")
    if _finite(r.get("bf10")):
        parts.append(f"BF10 = {_num(r['bf10'])}")
    if _finite(r.get("tost_p")):
        parts.append(f"TOST {p_eq(r['tost_p'])}, bounds ±{_sig(r['tost_bound'])}")
    return parts


def comparison_sentence(r: Row) -> str:
    """One comparison row (`comparisons.COMPARISON_COLUMNS`) as an APA sentence."""
    head = f"{r['task']}, {r['measure']}, {markdown_escape(r['group'])} (n = {r['n']})"
    if r["test"] == "none":
        return f"{head}: not testable: {r['not_testable']} (outside the Holm family)."
    holm = p_eq(r["p_holm"]).replace("p", "p(Holm)", 1) if _finite(r["p_holm"]) else ""
    if r["test"] == "paired_t":
        test = f"t({int(r['n']) - 1}) = {_num(r['statistic'])}, {p_eq(r['p'])}"
    else:
        test = (
            f"Wilcoxon V = {_num(r['statistic'], 1)}, {p_eq(r['p'])} ({r['p_method']}), "
            f"r_rb = {bounded_text(r['effect_size'])}"
        )
    parts = [test, holm] if holm else [test]
    if _finite(r.get("constant_diff")):
        parts.insert(0, f"every difference is {_sig(r['constant_diff'])}, so no t statistic")
    elif _finite(r.get("dz")):
        parts += _t_numbers(r)
    return f"{head}: " + "; ".join(parts) + "."


def success_sentence(r: Row) -> str:
    """One exact McNemar row (`success.SUCCESS_COLUMNS`) as a sentence."""
    return (
        f"{r['task']}, success, {markdown_escape(r['group'])} (n = {r['n']}): "
        f"{r['success_vo']} succeeded in "
        f"VO, {r['success_hv']} in HV; {r['vo_only']} in VO only, {r['hv_only']} in HV "
        f"only; exact McNemar {p_eq(r['p'])}, {p_eq(r['p_holm']).replace('p', 'p(Holm)', 1)}."
    )


_WITHDRAWN = re.compile(r"^(?P<task>[^:]+): excluded (?P<code>\S+) \(withdrawn: (?P<why>.*)\)$")
_INVALID = re.compile(r"^(?P<task>[^/]+)/all measures: excluded (?P<what>.+) \(marked invalid: ")
_NO_TLX = re.compile(r"^(?P<task>[^/]+)/tlx_\*: excluded (?P<codes>.+) \(no questionnaires\)$")
_CHOICELESS = re.compile(r"^(?P<task>[^/]+)/tlx_weighted: excluded (?P<what>.+) \(questionnaire")
_FEW = re.compile(r"^(?P<label>.+): n = (?P<n>\d+) pairs, too few to test$")
_MISSING = re.compile(r"^(?P<label>[^:]+): excluded (?P<who>.+one condition missing.*)$")


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _withdrawals(lines: list[str]) -> list[str]:
    reasons: dict[str, str] = {}
    for line in lines:
        m = _WITHDRAWN.match(line)
        if m:
            reasons.setdefault(m["code"], m["why"].split("; no data stored")[0])
    return [
        f"{code} withdrew from the study ({why or 'no reason given'}) and was excluded from "
        "every analysis."
        for code, why in reasons.items()
    ]


def _invalid(lines: list[str]) -> list[str]:
    by_task: dict[str, list[str]] = {}
    for line in lines:
        m = _INVALID.match(line)
        if m:
            reason = line.split("(marked invalid: ", 1)[1]
            by_task.setdefault(m["task"], []).append(f"{m['what']} ({reason}")
    out = []
    for task, trials in by_task.items():
        n = len(trials)
        out.append(
            f"{_plural(n, 'trial')} of the {task} task marked invalid by the "
            f"experimenter {'was' if n == 1 else 'were'} left out: " + "; ".join(trials) + "."
        )
    return out


def _questionnaires(lines: list[str]) -> list[str]:
    out = []
    choiceless: dict[str, list[str]] = {}
    for line in lines:
        m = _NO_TLX.match(line)
        if m:
            verb = "are" if "," in m["codes"] else "is"
            out.append(
                f"{m['codes']} filled in no questionnaire in the {m['task']} task and "
                f"{verb} not in its NASA-TLX analyses."
            )
        m = _CHOICELESS.match(line)
        if m:
            choiceless.setdefault(m["task"], []).append(m["what"])
    for task, which in choiceless.items():
        out.append(
            f"{_plural(len(which), 'questionnaire')} of the {task} task had ratings but no "
            f"pairwise choices ({', '.join(which)}); they count in the raw TLX and the "
            "subscales, not in the weighted TLX."
        )
    return out


def _pairs(lines: list[str]) -> list[str]:
    missing = [f"{m['label']}: {m['who']}" for m in map(_MISSING.match, lines) if m]
    few = [f"{m['label']} ({m['n']} pairs)" for m in map(_FEW.match, lines) if m]
    out = []
    if missing:
        out.append(
            "Participants without both conditions were left out of that comparison: "
            + "; ".join(missing)
            + "."
        )
    if few:
        out.append("Not tested, fewer than 3 complete pairs: " + "; ".join(few) + ".")
    return out


def exclusion_sentences(lines: list[str]) -> list[str]:
    """The exclusion lines as sentences: withdrawals, invalid trials, questionnaires,
    missing conditions and groups too small to test (every line is also listed as it
    is under "Exclusions")."""
    return [*_withdrawals(lines), *_invalid(lines), *_questionnaires(lines), *_pairs(lines)]
