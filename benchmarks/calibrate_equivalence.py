"""The calibration loop's results from two checkouts, compared recording by recording.

    PYTHONPATH=BASELINE python benchmarks/calibrate_equivalence.py report DIR_A
    PYTHONPATH=NEW python benchmarks/calibrate_equivalence.py report DIR_B
    python benchmarks/calibrate_equivalence.py compare DIR_A DIR_B --out OUT.json

`report` runs `Calibrator(...).fit(...).report()` of the checkout first on PYTHONPATH on
each recording below and writes one JSON per recording (and its CPU seconds) to DIR;
`compare` says, per recording, whether the named results are the same (effects added,
discovered terms, ambiguous families, verdict, where the structure remains, every
candidate's reason) and the largest relative difference of the numbers, per part of the
report (held-out errors, the effects' and the base's parameters with their intervals,
the coefficients, the rejected candidates' searched values and errors).

Recordings: SIMULATED follower recordings of `synthetic.follower_recording` (seed 7,
240 s at 200 Hz, effects at the JND's size: clean, stribeck, three effects, a ripple, a
delay) and of `general.general_recording` (pre-sliding memory + load-dependent
friction, seed 3; gain change + ripple + first-order lag, seed 5), and the EMPS drive's
measured recording (`--model rigid-axis`).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

SYNTHETIC = {
    "clean": (),
    "stribeck": ("stribeck",),
    "three": ("stribeck", "hysteresis", "drift"),
    "ripple": ("position_periodic",),
    "delay": ("delay",),
}
GENERAL = {
    "presliding_load": (("presliding_memory", "load_friction"), 3),
    "gain_ripple_lag": (("gain_change", "position_periodic", "lag"), 5),
}


def _recordings() -> dict[str, tuple[Any, Any]]:
    import teleop_core
    from teleop_core.calibration import FollowerBase
    from teleop_core.calibration.general import general_recording
    from teleop_core.calibration.rigid_axis import RigidAxisBase
    from teleop_core.calibration.synthetic import JND_N, follower_recording

    out: dict[str, tuple[Any, Any]] = {}
    follower = FollowerBase()
    for name, effects in SYNTHETIC.items():
        rec, _ = follower_recording(240.0, effects, rate_hz=200.0, seed=7, size_n=JND_N)
        out[name] = (follower, follower.data(rec))
    for name, (families, seed) in GENERAL.items():
        out[name] = (follower, general_recording(families, seed).data)
    emps = Path(teleop_core.__file__).parents[1] / "tests" / "data" / "emps" / "DATA_EMPS.mat"
    if emps.is_file():
        model = RigidAxisBase(train_fraction=0.75, mat_columns=("t", "qm", "gtau*vir"))
        out["emps"] = (model, model.read(emps))
    return out


def report(folder: Path) -> None:
    from teleop_core.calibration import Calibrator

    folder.mkdir(parents=True, exist_ok=True)
    for name, (model, data) in _recordings().items():
        start = time.process_time()
        result = Calibrator(model).fit(data).report()
        result["cpu_s"] = time.process_time() - start
        (folder / f"{name}.json").write_text(json.dumps(result, indent=1, default=float))
        print(name, f"{result['cpu_s']:.2f} s CPU", flush=True)


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(d, dict):
        return {k: v for key, x in d.items() for k, v in _flat(x, f"{prefix}.{key}").items()}
    if isinstance(d, list):
        return {k: v for i, x in enumerate(d) for k, v in _flat(x, f"{prefix}.{i}").items()}
    return {prefix.lstrip("."): d}


NAMED_PARTS = ("effects_added", "discovered_terms", "ambiguous_effects", "candidates")


def _named(r: dict[str, Any]) -> dict[str, Any]:
    """What the report names: families, terms, verdict, where, each candidate's reason."""
    return {
        "effects_added": [e["family"] for e in r["effects_added"]],
        "discovered_terms": [e["term"] for e in r["discovered_terms"]],
        "ambiguous_effects": [e["families"] for e in r["ambiguous_effects"]],
        "verdict": r["verdict"],
        "unexplained": (r["unexplained"] or {}).get("quantity"),
        "candidates": [
            (c["round"], c["family"], c["accepted"], c["reason"]) for c in r["candidates"]
        ],
    }


def _differences(a: dict[str, Any], b: dict[str, Any]) -> dict[str, float]:
    """Largest relative difference per part of the report (candidates: accepted and
    rejected apart)."""
    fa, fb = _flat(a), _flat(b)
    accepted = {i for i, c in enumerate(a["candidates"]) if c["accepted"]}
    worst: dict[str, float] = {}
    for key in fa.keys() & fb.keys():
        x, y = fa[key], fb[key]
        if key == "cpu_s" or isinstance(x, bool) or not isinstance(x, float | int):
            continue
        if not isinstance(y, float | int) or x == y:
            continue
        part = key.split(".")[0]
        if part in ("candidates", "candidates_rejected"):
            index = int(key.split(".")[1])
            part += ".accepted" if part == "candidates" and index in accepted else ".rejected"
        rel = abs(x - y) / max(abs(x), abs(y), 1e-300)
        worst[part] = max(worst.get(part, 0.0), rel)
    return dict(sorted(worst.items(), key=lambda kv: -kv[1]))


def compare(a_dir: Path, b_dir: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for path in sorted(a_dir.glob("*.json")):
        a = json.loads(path.read_text())
        b = json.loads((b_dir / path.name).read_text())
        named_a, named_b = _named(a), _named(b)
        out[path.stem] = {
            "same_named_results": named_a == named_b,
            "named": named_b | {"candidates": None},
            "named_differences": {
                k: [named_a[k], named_b[k]] for k in named_a if named_a[k] != named_b[k]
            },
            "cpu_s": [round(a["cpu_s"], 2), round(b["cpu_s"], 2)],
            "max_relative_difference": _differences(a, b),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("report").add_argument("folder", type=Path)
    cmp = sub.add_parser("compare")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    cmp.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if args.what == "report":
        report(args.folder)
    else:
        result = compare(args.a, args.b)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
        for name, r in result.items():
            print(name, r["same_named_results"], r["cpu_s"], r["max_relative_difference"])


if __name__ == "__main__":
    main()
