"""A fresh process: no PyTorch to run a trained estimator, no compilation of the loop
kernel and no numba after the first process. Each check runs in its own
interpreter, since what is imported or compiled is a property of a process."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from teleop_core.loop import kernel, layout
from teleop_core.loop.aot import SUFFIX
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import SimulatedOperator
from teleop_core.loop.environments import Environment, tube_with_wall

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
    "numba": "numba" in sys.modules,
    "ahead_of_time": getattr(k, "ahead_of_time", False),
}))
"""


def _process(tmp_path: Path, code: str, *argv: str) -> dict[str, object]:
    """The JSON last printed by `code` run in a fresh interpreter on the kernel cache
    in `tmp_path` (a crash, a signal's negative return code, fails the test)."""
    env = {**os.environ, "HAPTIC_STUDY_CACHE": str(tmp_path / "cache")}
    done = subprocess.run(
        [sys.executable, "-c", code, *argv],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    result: dict[str, object] = json.loads(done.stdout.splitlines()[-1])
    return result


def _trial_process(tmp_path: Path, name: str) -> dict[str, object]:
    return _process(tmp_path, TRIAL, str(tmp_path / name))


def test_a_second_process_loads_the_loop_kernel_and_never_imports_numba_or_torch(
    tmp_path: Path,
) -> None:
    first = _trial_process(tmp_path, "first.npy")
    second = _trial_process(tmp_path, "second.npy")
    # the first process compiles the kernel ahead of time into the cache (numba runs
    # there), the second imports the extension module and never numba
    folder = tmp_path / "cache" / "kernels"
    assert list(folder.glob(f"_haptic_study_loop_aot_*{SUFFIX}")), list(folder.iterdir())
    assert first["numba"] is True
    assert second["numba"] is False
    assert first["ahead_of_time"] is True
    assert second["ahead_of_time"] is True
    # the trained GRU runs from gru.npz in the compiled kernel: PyTorch is never loaded
    assert first["torch"] is False
    assert second["torch"] is False
    np.testing.assert_array_equal(np.load(tmp_path / "first.npy"), np.load(tmp_path / "second.npy"))
    # the extension (compiled for this CPU) and numba's JIT kernel of the same source,
    # on the same trial: equal samples, not close ones
    env = tube_with_wall(friction_n_per_m=8.0)
    from study.protocol.default_estimator import load_estimator

    kernel._KERNELS[env.fn] = kernel._make(env.fn)
    try:
        run = TeleopLoop(environment=env, estimator=load_estimator(), seed=5).run(
            3.0, SimulatedOperator()
        )
    finally:
        kernel._KERNELS.pop(env.fn)
    np.testing.assert_array_equal(np.load(tmp_path / "second.npy"), run.samples)


BAD_ARRAYS = """
import json, sys
import numpy as np
from teleop_core.loop import kernel
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import SimulatedOperator
from teleop_core.loop.environments import tube_with_wall

env = tube_with_wall(friction_n_per_m=8.0)
k = kernel.kernel_for(env.fn)


def trial(change):
    loop = TeleopLoop(environment=env, seed=5)
    loop._est_arrays = change(loop._est_arrays)
    try:
        loop.run(0.05, SimulatedOperator())
    except ValueError as exc:
        return str(exc)
    return "ran"


print(json.dumps({
    "ahead_of_time": getattr(k, "ahead_of_time", False),
    "short": trial(lambda a: a[:-1]),
    "long": trial(lambda a: (*a, np.zeros(1))),
    # the stream state in float32: the JIT kernel compiles for it
    "float32": trial(lambda a: (a[0], a[1].astype(np.float32), *a[2:])),
}))
"""


def test_the_compiled_kernel_refuses_estimator_arrays_it_would_misread(tmp_path: Path) -> None:
    """The extension's own wrapper reads whatever tuple and arrays it is given as its
    signature's (a tuple one short crashed the process): a tuple of another length is a
    ValueError naming both lengths, an array of another dtype runs the JIT kernel. In a
    process of its own, so that a crash fails this test rather than ending the run."""
    result = _process(tmp_path, BAD_ARRAYS)
    assert result["ahead_of_time"] is True
    assert re.fullmatch(r".*estimator arrays.*: expected 15, got 14", str(result["short"]))
    assert re.fullmatch(r".*estimator arrays.*: expected 15, got 16", str(result["long"]))
    assert result["float32"] == "ran"


def test_without_a_compiler_the_kernel_runs_through_numbas_cache(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A machine where the extension cannot be built (here: no C compiler on PATH)
    says so once in a marker file and runs the JIT kernel from numba's cache."""
    monkeypatch.setenv("HAPTIC_STUDY_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setenv("CC", str(tmp_path / "empty" / "cc"))
    env = tube_with_wall(friction_n_per_m=8.0)
    k = kernel._cached_kernel(env.fn)
    assert k is not None
    assert not getattr(k, "ahead_of_time", False)
    folder = tmp_path / "cache" / "kernels"
    assert list(folder.glob("_haptic_study_loop_aot_*.failed"))
    assert not list(folder.glob(f"_haptic_study_loop_aot_*{SUFFIX}"))


def test_the_cached_kernel_equals_the_closure_compiled_in_process(tmp_path: Path) -> None:
    env = tube_with_wall(friction_n_per_m=8.0)
    module, name, key = kernel._kernel_module(env.fn)  # type: ignore[misc]
    cached_jit, _ = kernel._jit_kernel(kernel._cache_dir(), module, name, key)
    assert cached_jit.__module__.startswith("_haptic_study_loop_kernel_")
    kernel._KERNELS[env.fn] = cached_jit
    try:
        cached = TeleopLoop(environment=env, seed=5).run(4.0, SimulatedOperator()).samples
    finally:
        kernel._KERNELS.pop(env.fn)
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
        out[layout.E_PROXIMAL] = 10.0 * max(insertion_m - 0.05, 0.0)
        out[layout.E_TIP_X] = insertion_m

    assert kernel._cached_kernel(wall) is None  # not importable by name: compiled here
    base = tube_with_wall(friction_n_per_m=8.0)
    run = TeleopLoop(environment=Environment(wall, base.params), seed=5).run(
        2.0, SimulatedOperator()
    )
    assert run.samples.shape[0] > 0


def test_importing_the_loop_and_estimator_modules_imports_no_numba() -> None:
    """Every module with kernel functions decorates them with `teleop_core._jit.njit`,
    which imports numba on first use only."""
    code = (
        "import sys\n"
        "import teleop_core.loop.core, teleop_core.estimation.estimator\n"
        "import teleop_core.phantom.lcca, teleop_core.notes.simulate\n"
        "import teleop_core.calibration.effects\n"
        "print('numba' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    )
    assert done.stdout.strip() == "False", done.stderr


def test_a_lazy_function_is_compiled_when_called_and_from_compiled_code() -> None:
    """Called from Python it runs numba's dispatcher; called from another numba
    function it is typed as that dispatcher (the typeof hook); it pickles by name."""
    import pickle

    import numba

    from teleop_core._jit import LazyJit
    from teleop_core.master.haptics import haptic_torque, rate_command

    assert isinstance(rate_command, LazyJit)
    # eq. 5: v = k_v theta
    assert rate_command(0.5, 0.004) == 0.5 * 0.004
    assert rate_command.signatures  # compiled by numba, not run as Python

    @numba.njit
    def twice(force_n: float) -> float:
        return 2.0 * haptic_torque(force_n, 0.01, 0.0, 1.0)

    assert twice(3.0) == 2.0 * haptic_torque.py_func(3.0, 0.01, 0.0, 1.0)
    assert pickle.loads(pickle.dumps(rate_command)) is rate_command


def test_the_first_demo_after_install_says_it_compiles_the_loop_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`study demo` (and `study run --all`) compile the loop's kernel in the parent before
    the workers start, saying so, where it is not compiled yet; a second run loads it."""
    env = {**os.environ, "HAPTIC_STUDY_CACHE": str(tmp_path / "cache")}

    def demo(out: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            [sys.executable, "-m", "study.cli", "demo", "--quick", "--out", str(tmp_path / out)],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
        assert done.returncode == 0, done.stderr
        return done

    first, second = demo("first"), demo("second")
    notice = "study demo: compiling the simulation loop (once after install"
    assert notice in first.stderr
    assert notice not in second.stderr
    # and how long it took (a whole number of seconds)
    assert re.search(r"study demo: compiled the simulation loop in \d+ s", first.stderr)
    assert "compiled the simulation loop" not in second.stderr
    folder = tmp_path / "cache" / "kernels"
    assert len(list(folder.glob(f"_haptic_study_loop_aot_*{SUFFIX}"))) == 1
    from teleop_core.phantom.lcca import lcca_phantom

    monkeypatch.setenv("HAPTIC_STUDY_CACHE", str(tmp_path / "cache"))
    assert kernel.is_compiled(lcca_phantom)
    assert not kernel.needs_compiling(lcca_phantom)
    monkeypatch.setenv("HAPTIC_STUDY_CACHE", str(tmp_path / "empty"))
    assert not kernel.is_compiled(lcca_phantom)
    assert kernel.needs_compiling(lcca_phantom)
    # a machine where building failed once (no C compiler) is not told it compiles
    # every run: the JIT kernel from numba's cache runs there
    key = kernel._kernel_module(lcca_phantom)[2]  # type: ignore[index]
    (tmp_path / "empty" / "kernels").mkdir(parents=True)
    (tmp_path / "empty" / "kernels" / f"_haptic_study_loop_aot_{key}.failed").write_text("x")
    assert not kernel.needs_compiling(lcca_phantom)
