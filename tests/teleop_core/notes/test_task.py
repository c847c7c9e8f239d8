"""The NOTES abdomen against the paper's benchmarks, and the loop under any driver."""

from __future__ import annotations

import math

import pytest

from teleop_core.loop.drivers import KeyboardDriver
from teleop_core.notes import task


def test_tissue_reaches_the_papers_benchmarks() -> None:
    a = task.NotesAbdomen()
    a.breached = True  # through the fornix
    fast = 100 * task.FRICTION_SPEED_M_S  # tanh(100) = 1
    # pull at the target depth: the canal's full friction, 4.5 N against the motion
    assert a.forces(task.TARGET_M, -fast, 0.0).force_n == pytest.approx(-4.5)
    roll = 100 * task.FRICTION_SPEED_RAD_S
    assert a.forces(task.TARGET_M, 0.0, roll).torque_n_m == pytest.approx(0.0767)
    assert a.forces(task.TARGET_M, 0.0, -roll).torque_n_m == pytest.approx(-0.085)


def test_fornix_gives_way_at_the_mean_max_push() -> None:
    a = task.NotesAbdomen()
    depth = task.FORNIX_M
    push = 0.0
    while not a.breached:
        depth += 1e-5
        push = a.forces(depth, 1.0, 0.0).force_n
    assert push == pytest.approx(task.PUSH_BENCHMARK_N, abs=0.01)
    assert a.forces(depth + 1e-3, 1.0, 0.0).tip_force_n == 0.0


@pytest.mark.parametrize("haptics", [False, True])
def test_keyboard_driver_moves_the_scope(haptics: bool) -> None:
    now = [0.0]
    keys = KeyboardDriver(clock=lambda: now[0])
    loop = task.NotesLoop(haptics=haptics, seed=1)
    loop.start(keys)
    for _ in range(4):
        keys.press("advance")
    samples = loop.advance(2.0)
    depth = samples[:, task.SAMPLE_COLUMNS.index("insertion_m")]
    assert samples.shape == (200, len(task.SAMPLE_COLUMNS))
    # aim 0.4 rad x 0.05 m/s per rad = 20 mm/s, reached within a fraction of a second
    assert depth[-1] == pytest.approx(0.02 * 2.0, rel=0.15)
    rendered = samples[:, task.SAMPLE_COLUMNS.index("proximal_force_est_n")]
    # canal friction is rendered only in HV
    assert bool(abs(rendered[-1]) > 0.1) is haptics
    keys.press("stop")
    loop.advance(0.1)
    assert loop.done and not loop.success and math.isfinite(loop.t_s)
