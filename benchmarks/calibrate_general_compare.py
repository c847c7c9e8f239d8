"""Per-family shares of two runs of `study bench calibrate --generalise` on the same
recordings (matched by seed): what a change to the loop did.

    python benchmarks/calibrate_general_compare.py BEFORE.json AFTER.json > OUT.md

Only the recordings both runs hold are compared (a run with --count 1 holds the first
recording of every single-family group and of the clean ones of a run with a larger
count at the same --seed; its mixtures of three are drawn otherwise).
"""

from __future__ import annotations

import json
import sys

from study.bench.calibrate_general import summarise

KEYS = ("within_2x_oracle", "right_first", "wrong_named", "ambiguous", "honest")


def pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def main(before_path: str, after_path: str) -> None:
    before = {r["seed"]: r for r in json.load(open(before_path))["runs"]}
    after = {r["seed"]: r for r in json.load(open(after_path))["runs"]}
    # the same seed and the same injected families (a mixture drawn for another count
    # is another recording)
    seeds = sorted(
        s for s in set(before) & set(after) if before[s]["families"] == after[s]["families"]
    )
    b = summarise([before[s] for s in seeds])
    a = summarise([after[s] for s in seeds])
    print(
        f"SIMULATED recordings; {len(seeds)} recordings held by both runs (seeds "
        f"{seeds[0]}-{seeds[-1]}); each cell: before -> after.\n"
    )
    print("| family | n | " + " | ".join(KEYS) + " |")
    print("|---|---|" + "---|" * len(KEYS))
    for name, g in a["per_group"].items():
        old = b["per_group"][name]
        cells = [f"{pct(old[k])} -> {pct(g[k])}" for k in KEYS]
        print(f"| {name} | {g['recordings']} | " + " | ".join(cells) + " |")
    print(
        "\nOverall: "
        + ", ".join(
            f"{k} {pct(b['overall'][k]) if isinstance(b['overall'][k], float) else b['overall'][k]}"
            f" -> {pct(a['overall'][k]) if isinstance(a['overall'][k], float) else a['overall'][k]}"
            for k in (
                "within_2x_oracle",
                "wrong_named",
                "clean_untouched",
                "not_explained_end_structure_remains",
            )
        )
    )
    print("\nRecordings whose names changed:")
    for s in seeds:
        if (before[s]["named"], before[s]["ambiguous"]) != (
            after[s]["named"],
            after[s]["ambiguous"],
        ):
            print(
                f"- {s} {'+'.join(after[s]['families']) or 'clean'}: named "
                f"{before[s]['named']} ambiguous {before[s]['ambiguous']} -> named "
                f"{after[s]['named']} ambiguous {after[s]['ambiguous']}"
            )


if __name__ == "__main__":
    main(*sys.argv[1:3])
