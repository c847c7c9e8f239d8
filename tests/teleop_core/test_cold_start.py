"""A fresh process: no PyTorch to run a trained estimator, no compilation of the loop
kernel after the first process (issue 21). Each check runs in its own interpreter,
since what is imported or compiled is a property of a process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from teleop_core.loop import kernel
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import SimulatedOperator
from teleop_core.loop.environments import tube_with_wall

TRIAL = """
import json, sys
import numpy as np
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import SimulatedOperator
from teleop_core.loop.environments import tube_with_wall
from teleop_core.loop import kernel
from study.protocol.default_estimator import load_estimator

env = tube_with_wall(friction_n_per_m=8.0)
run = TeleopLoop(environment=env, estimator=load_estimator(), seed=5).run(
    3.0, SimulatedOperator()
)
k = kernel.kernel_for(env.fn)
np.save(sys.argv[1], run.samples)
print(json.dumps({
    "torch": "torch" in sys.modules,
    "hits": sum(k.stats.cache_hits.values()),
    "misses": sum(k.stats.cache_misses.values()),
    "cached_module": k.__module__,
}))
"""


def _trial_process(tmp_path: Path, name: str) -> dict[str, object]:
    env = {**os.environ, "HAPTIC_STUDY_CACHE": str(tmp_path / "cache")}
    done = subprocess.run(
        [sys.executable, "-c", TRIAL, str(tmp_path / name)],
        env=env, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result: dict[str, object] = json.loads(done.stdout.splitlines()[-1])
    return result


def test_a_second_process_loads_the_loop_kernel_and_never_imports_torch(tmp_path: Path) -> None:
    first = _trial_process(tmp_path, "first.npy")
    second = _trial_process(tmp_path, "second.npy")
    # the first process compiles the kernel into the cache, the second only loads it
    assert first["misses"] == 1 and first["hits"] == 0
    assert second["hits"] == 1 and second["misses"] == 0
    assert str(second["cached_module"]).startswith("_haptic_study_loop_kernel_")
    assert list((tmp_path / "cache" / "kernels").glob("loop_kernel_*.py"))
    # the trained GRU runs from gru.npz in the numba kernel: PyTorch is never loaded
    assert first["torch"] is False and second["torch"] is False
    # the cached kernel computes what the in-process closure computes, bit for bit
    np.testing.assert_array_equal(np.load(tmp_path / "first.npy"), np.load(tmp_path / "second.npy"))


def test_the_cached_kernel_equals_the_closure_compiled_in_process(tmp_path: Path) -> None:
    env = tube_with_wall(friction_n_per_m=8.0)
    cached = TeleopLoop(environment=env, seed=5).run(4.0, SimulatedOperator()).samples
    assert kernel.kernel_for(env.fn).__module__.startswith("_haptic_study_loop_kernel_")
    closure = kernel._make(env.fn)
    kernel._KERNELS[env.fn] = closure
    try:
        again = TeleopLoop(environment=env, seed=5).run(4.0, SimulatedOperator()).samples
    finally:
        kernel._KERNELS.pop(env.fn)
    np.testing.assert_array_equal(cached, again)


def test_an_environment_defined_in_a_function_still_runs(tmp_path: Path) -> None:
    import numba

    @numba.njit
    def wall(state, params, insertion_m, speed_m_s, rotation_rad, dt_s, out):  # type: ignore[no-untyped-def]
        out[:] = 0.0
        out[kernel.E_PROXIMAL] = 10.0 * max(insertion_m - 0.05, 0.0)
        out[kernel.E_TIP_X] = insertion_m

    assert kernel._cached_kernel(wall) is None  # not importable by name: compiled here
    base = tube_with_wall(friction_n_per_m=8.0)
    from teleop_core.loop.environments import Environment

    run = TeleopLoop(environment=Environment(wall, base.params), seed=5).run(
        2.0, SimulatedOperator()
    )
    assert run.samples.shape[0] > 0
