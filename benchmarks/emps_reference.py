"""EMPS: the plain IDIM-LS references, the calibration loop, and the simulation task.

Run: `python benchmarks/emps_reference.py [--out benchmarks/results/emps_reference.json]`

Independent of the test suite and of the loop's own derivative code: the references are
built here from scipy and numpy calls alone.

1. Plain IDIM-LS (Janot, Gautier, Brunot 2019): position low-passed by a 4th-order
   Butterworth run with `scipy.signal.filtfilt` (its default odd padding), central
   differences (`numpy.gradient`), least squares on the first 75 % of the samples,
   RMSE of the force on the last 25 %; with one viscous and Coulomb term (the
   benchmark's reference model) and with viscous + Coulomb per direction of motion.
2. The calibration loop (`Calibrator` on `RigidAxisBase`) on the same split.
3. The benchmark's simulation task on the estimation file: the identified direct
   model M q'' = u - f(q') driven by the measured force u = gtau * vir, integrated
   from the recording's first position at rest (free run: the measured position is
   never fed back), RMSE of the position in mm over the last 25 % of the samples.
   f(q') is each model's friction (and offset) at zero acceleration, read from its
   design matrix over a fine grid of speeds; stiction: while the speed is zero and
   |u - f(0+-)| is below the break-away force, the axis stays put.

DATA_EMPS.mat: A. Janot, M. Gautier, M. Brunot, "Data Set and Reference Models of EMPS",
Workshop on Nonlinear System Identification Benchmarks, 2019. Measured data.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.io import loadmat

from teleop_core.calibration import Calibrator
from teleop_core.calibration.fitting import design
from teleop_core.calibration.rigid_axis import RigidAxisBase

EMPS = Path(__file__).parent.parent / "study" / "example_data" / "emps" / "DATA_EMPS.mat"


def plain_idim(t, q, u, cutoff_hz, per_direction, cut):  # type: ignore[no-untyped-def]
    fs = 1.0 / float(np.median(np.diff(t)))
    b, a = signal.butter(4, cutoff_hz / (fs / 2))
    qd = np.gradient(signal.filtfilt(b, a, q), t)
    qdd = np.gradient(qd, t)
    one = np.ones_like(t)
    if per_direction:
        X = np.column_stack([qdd, qd * (qd > 0), qd * (qd < 0), qd > 0, qd < 0, one])
    else:
        X = np.column_stack([qdd, qd, np.sign(qd), one])
    c, *_ = np.linalg.lstsq(X[:cut], u[:cut], rcond=None)
    e = u[cut:] - X[cut:] @ c
    return float(np.sqrt(np.mean(e * e))), c


def free_run(t, u, q0, mass, friction, breakaway):  # type: ignore[no-untyped-def]
    """Semi-implicit Euler of M q'' = u - friction(q'), with stiction at rest."""
    q = np.empty_like(t)
    q[0], v = q0, 0.0
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        if v == 0.0:
            lo, hi = breakaway
            if lo <= u[k] <= hi:  # stuck
                q[k + 1] = q[k]
                continue
        f = friction(v if v != 0.0 else np.sign(u[k]) * 1e-9)
        v_new = v + dt * (u[k] - f) / mass
        if v != 0.0 and np.sign(v_new) != np.sign(v):
            v_new = 0.0  # friction stops the axis; it does not reverse it
        v = v_new
        q[k + 1] = q[k] + dt * v
    return q


def friction_table(f_of_v):  # type: ignore[no-untyped-def]
    grid = np.concatenate([-np.geomspace(1.0, 1e-7, 400), np.geomspace(1e-7, 1.0, 400)])
    table = f_of_v(grid)

    def friction(v: float) -> float:
        return float(np.interp(v, grid, table))

    return friction, (float(table[399]), float(table[400]))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    raw = loadmat(EMPS)
    t, q = raw["t"].ravel(), raw["qm"].ravel()
    u = (raw["gtau"] * raw["vir"]).ravel()
    n = len(t)
    cut = round(0.75 * n)
    last = slice(cut, n)
    out: dict = {
        "data": "EMPS estimation file DATA_EMPS.mat, measured (Janot, Gautier, Brunot 2019)",
        "split": "first 75 % training, last 25 % held out",
    }
    plain = {}
    for cutoff in (50.0, 75.0, 100.0, 150.0):
        r1, _ = plain_idim(t, q, u, cutoff, False, cut)
        r2, _ = plain_idim(t, q, u, cutoff, True, cut)
        plain[f"{cutoff:g}"] = {"base_rmse_n": r1, "per_direction_rmse_n": r2}
    out["plain_idim_ls"] = plain
    # the loop
    model = RigidAxisBase(mat_columns=("t", "qm", "gtau*vir"))
    data = model.read(EMPS)
    t0 = time.perf_counter()
    cal = Calibrator(model).fit(data)
    rep = cal.report()
    out["loop"] = {
        "seconds": time.perf_counter() - t0,
        "rmse_before_n": rep["rmse_before"],
        "rmse_after_n": rep["rmse_after"],
        "effects_added": [(e["family"], e["params"]) for e in rep["effects_added"]],
        "verdict": rep["verdict"],
        "derivative_cutoff_hz": rep["preparation"]["derivative_cutoff_hz"],
    }
    # the simulation task
    sims = {}
    _, c_ref = plain_idim(t, q, u, 100.0, False, cut)
    _, c_dir = plain_idim(t, q, u, 100.0, True, cut)
    models = {
        "plain_idim_ls_100hz": (
            c_ref[0],
            lambda v: c_ref[1] * v + c_ref[2] * np.sign(v) + c_ref[3],
        ),
        "plain_idim_ls_per_direction_100hz": (
            c_dir[0],
            lambda v: (
                c_dir[1] * v * (v > 0)
                + c_dir[2] * v * (v < 0)
                + c_dir[3] * (v > 0)
                + c_dir[4] * (v < 0)
                + c_dir[5]
            ),
        ),
    }
    coef = cal.model_.coef
    base = cal.base_

    def loop_friction(v):  # type: ignore[no-untyped-def]
        s = {
            "t": np.zeros_like(v),
            "angle": np.zeros_like(v),
            "speed": v,
            "accel": 0 * v,
            "direction": v,
            "direction_sign": np.sign(v),
        }
        X, _ = design(base, s, cal.chain_)
        return X @ coef

    models["loop"] = (coef[0], loop_friction)
    for name, (mass, f) in models.items():
        friction, breakaway = friction_table(f)
        qs = free_run(t, u, q[0], float(mass), friction, breakaway)
        err = (qs[last] - q[last]) * 1e3
        sims[name] = {
            "rmse_mm_last_25_percent": float(np.sqrt(np.mean(err * err))),
            "rmse_mm_all": float(np.sqrt(np.mean(((qs - q) * 1e3) ** 2))),
        }
    out["simulation_free_run"] = sims
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
