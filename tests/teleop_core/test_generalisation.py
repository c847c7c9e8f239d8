"""The estimator on a time block it never saw.

Each recording carries one seeded effect eq. 1 lacks, at the JND's size
(`calibration.synthetic.follower_recording`): the estimator is trained on the first
60 % and run on the last 40 %, as the generalisation bench does at full size
(`study bench follower --only generalisation`), here short and with a fast learning
rate so each training takes seconds. The references are the physics stage's own error
on the held-out block and the issue's targets.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import pytest

from teleop_core.calibration.synthetic import JND_N, follower_recording
from teleop_core.estimation.gru import GruConfig
from teleop_core.estimation.metrics import rmse
from teleop_core.estimation.training import train_estimator

FAST = GruConfig(window=10, hidden_size=16, learning_rate=3e-3, max_epochs=10, patience=4)
"""Small and quick; the defaults are measured by the bench."""


@cache
def held_out(effect: str, seed: int, effects: bool = False) -> dict[str, Any]:
    """Train on the first 60 % of 60 s at 100 Hz carrying `effect`, run on the rest:
    RMSE (N) of each stage over the held-out block, and eq. 1's on the validation blocks
    of training (`validation_physics`); with `effects`, training first looks for the
    effects eq. 1 lacks (`found`). Cached: the tests below share the trainings."""
    rec, _ = follower_recording(60.0, [effect] if effect else [], seed=seed, size_n=JND_N)
    cut = int(0.6 * len(rec))
    estimator, summary = train_estimator(rec.slice(0, cut), FAST, seed=seed, effects=effects)
    result = estimator.predict(rec.slice(cut, len(rec)))
    out: dict[str, Any] = {
        s: rmse(getattr(result, f"f_{s}"), result.f_ref) for s in ("physics", "hybrid", "final")
    }
    out["validation_physics"] = summary.validation_rmse_n["physics"]
    out["found"] = estimator.extension.families if estimator.extension else []
    return out


@pytest.mark.parametrize("effect", ["stribeck", "hysteresis", "direction_asymmetry", "drift"])
def test_the_filter_never_makes_the_held_out_estimate_worse(effect: str) -> None:
    """The issue's second target: final within 2 % of physics+GRU on data never seen."""
    e = held_out(effect, seed=0)
    assert e["final"] <= 1.02 * e["hybrid"], e


def test_a_direction_dependent_load_is_learned_and_carries_over() -> None:
    """A load gain that only acts backwards: a function of the inputs, which the GRU
    learns on the first block and applies on the second (the issue's first target)."""
    e = held_out("direction_asymmetry", seed=0)
    assert e["hybrid"] <= 0.7 * e["physics"], e


def test_a_stribeck_dip_is_partly_learned_on_a_short_recording() -> None:
    """The dip lives at low speed, a small part of the samples: ten quick epochs on 36 s
    learn some of it (the full-size default run learns most: see the README)."""
    e = held_out("stribeck", seed=0)
    assert e["hybrid"] < 0.97 * e["physics"], e


def test_drift_goes_on_after_training_and_no_input_tells_it() -> None:
    """A winding heating over minutes: the gain keeps changing in the held-out block,
    where eq. 1's error grows, and nothing in [I_q, theta_d, theta_dd] tells the time,
    so the GRU cannot take it out (the README's limit); it must not add to it much."""
    e = held_out("drift", seed=0)
    assert e["physics"] > 1.2 * e["validation_physics"], e
    assert e["hybrid"] <= 1.1 * e["physics"], e


@pytest.mark.parametrize("effect", ["stribeck", "hysteresis", "direction_asymmetry", "drift"])
def test_with_the_effect_search_every_effect_carries_past_the_training_block(
    effect: str,
) -> None:
    """The default training (`--effects auto`) looks for what eq. 1 lacks before the
    GRU: the effect found is a physical term with its parameter fitted, so it holds on
    the held-out block, drift included, which no window of inputs tells (the issue's
    targets: physics+GRU <= 0.7 x physics, final within 2 % of it)."""
    e = held_out(effect, seed=1, effects=True)
    assert effect in e["found"], e
    assert e["hybrid"] <= 0.7 * e["physics"], e
    assert e["final"] <= 1.02 * e["hybrid"], e


def test_the_effect_search_adds_nothing_to_a_recording_eq1_explains() -> None:
    """No effect injected: eq. 1 is the true model, and the search must not find one."""
    e = held_out("", seed=2, effects=True)
    assert e["found"] == [], e
