"""Where a participant fit's time goes: wall, the fit's own CPU and its simulation
workers' CPU per step, in one process (no command line, no figure).

    PYTHONPATH=CHECKOUT python benchmarks/participant_fit_phases.py DEMO_DB \\
        --design 32 --repeats 2 --check 4 --bootstrap 20 [--json OUT]

A step's row runs from the fit's first report of it (`progress`) to the next step's
first report (`trials`: reading the study's trials; the emulator's first report comes
when its first setting is simulated, so the row before it holds that setting's start);
a worker's CPU counts when its pool is shut down (with one pool for the whole fit, at
its end). DEMO_DB is fitted in place: pass a copy. Works on checkouts whose fit has
`fit_study` (this one) or `fit_participants` (commit 222c262).
"""

from __future__ import annotations

import argparse
import itertools
import json
import resource
import time
from pathlib import Path


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def main() -> None:
    start = time.monotonic()
    parser = argparse.ArgumentParser()
    parser.add_argument("db")
    parser.add_argument("--design", type=int, default=320)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--check", type=int, default=24)
    parser.add_argument("--bootstrap", type=int, default=100)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    from db.engine import describe, resolve_url
    from study.analysis.participant_fit import fit as fit_module
    from study.commands.base import opened_database

    settings = fit_module.FitSettings(
        design=args.design, repeats=args.repeats, check=args.check, bootstrap=args.bootstrap
    )
    marks = [("trials", time.monotonic(), *_cpu())]
    last: list[str] = []

    def progress(step: str, k: int = 0, n: int = 0) -> None:
        if not last or last[-1] != step:
            marks.append((step, time.monotonic(), *_cpu()))
            last.append(step)

    run = getattr(fit_module, "fit_study", None) or fit_module.fit_participants
    with opened_database(args.db) as engine:
        run(engine, "lcca", settings, describe(resolve_url(args.db)), progress)
    marks.append(("end", time.monotonic(), *_cpu()))
    # a step's row runs from its first report to the next step's first report
    rows = []
    bounds = [("start", start, 0.0, 0.0), *marks]
    for i, ((step, t0, own0, ch0), (_, t1, own1, ch1)) in enumerate(itertools.pairwise(bounds)):
        rows.append(
            {
                "step": "imports" if i == 0 else step,
                "wall_s": t1 - t0,
                "own_cpu_s": own1 - own0,
                "workers_cpu_s": ch1 - ch0,
            }
        )
    for r in rows:
        print(
            f"{r['step']:12s} wall {r['wall_s']:7.2f}  own {r['own_cpu_s']:7.2f}  "
            f"workers {r['workers_cpu_s']:7.2f}"
        )
    if args.json:
        args.json.write_text(json.dumps({"settings": vars(args) | {"json": None}, "rows": rows}))


if __name__ == "__main__":
    main()
