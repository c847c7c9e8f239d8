"""Every participant of a study pooled over the groups: each LCCA measure's VO and HV
mean over participants and a two-sided paired t test (scipy.stats.ttest_rel), which
`study analyze` gives per group only. For the README's figures of the SIMULATED demo
study:

    study demo --seed 1 --out demo/ && python benchmarks/demo_pooled.py demo/demo.db
"""

from __future__ import annotations

import argparse
from pathlib import Path

MEASURES = ("tlx_weighted", "peak_proximal_force_n", "peak_distal_force_n", "completion_time_s")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description="Pooled VO and HV means over every participant and a paired t test, "
        "per LCCA measure, of a study database."
    )
    parser.add_argument("db", type=Path, help="the study's SQLite file (e.g. demo/demo.db)")
    args = parser.parse_args(argv)
    if not args.db.is_file():
        parser.exit(2, f"database {args.db}; expected an existing SQLite file\n")

    from scipy import stats

    from db.migrate import open_database
    from study.analysis.frames import participant_means, tlx_frame, trial_frame

    engine = open_database(str(args.db), create=False)
    try:
        means = participant_means(trial_frame(engine), tlx_frame(engine))
    finally:
        engine.dispose()
    means = means[means["task"] == "lcca"]
    for measure in MEASURES:
        m = means[means["measure"] == measure].pivot(
            index="participant", columns="condition", values="value"
        )
        m = m.dropna()
        n = len(m)
        t, p = stats.ttest_rel(m["HV"].to_numpy(), m["VO"].to_numpy())
        print(
            f"{measure}: {n} participants, VO {m['VO'].mean():.3f}, HV {m['HV'].mean():.3f}, "
            f"HV / VO - 1 = {m['HV'].mean() / m['VO'].mean() - 1:+.3f}, "
            f"paired t({n - 1}) = {t:.2f}, p = {p:.2g}"
        )


if __name__ == "__main__":
    main()
