"""Memory features: values against closed forms, the causal path, the folder."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.estimation.gru import GruConfig
from teleop_core.estimation.memory import MemorySpec, ema_residuals, memory_inputs
from teleop_core.estimation.training import train_estimator
from teleop_core.follower.recording import FollowerRecording

SHIPPED = Path(__file__).resolve().parents[2] / "study" / "models" / "follower_estimator"


def test_a_step_decays_as_the_discrete_exponential() -> None:
    # x = 0 for k < s, 1 from k = s; with e_k = e_{k-1} + (1 - exp(-dt/tau)) (x_k - e_{k-1})
    # and e_0 = x_0 = 0: x_k - e_k = (exp(-dt/tau))^(k - s + 1) = exp(-(k - s + 1) dt / tau)
    dt, s, n = 0.005, 40, 400
    t = np.arange(n) * dt
    base = np.zeros((n, 3))
    base[s:, 0] = 1.0  # I_q steps
    base[s:, 1] = -2.0  # theta_d steps the other way, twice as far
    spec = MemorySpec((0.1, 1.0))
    got = ema_residuals(t, base, spec)
    k = np.arange(n)
    for j, (scale, tau) in enumerate([(1.0, 0.1), (1.0, 1.0), (-2.0, 0.1), (-2.0, 1.0)]):
        expected = np.where(k >= s, scale * np.exp(-(k - s + 1) * dt / tau), 0.0)
        np.testing.assert_allclose(got[:, j], expected, rtol=1e-12, atol=1e-15)
    assert spec.feature_names == (
        "iq",
        "omega",
        "alpha",
        "iq-ema0.1s",
        "iq-ema1s",
        "omega-ema0.1s",
        "omega-ema1s",
    )


def test_irregular_steps_use_each_samples_own_time_step() -> None:
    # by hand: x = 0, 1, 1 at t = 0, 0.1, 0.3 with tau = 0.2:
    # e1 = 0 + (1 - e^-0.5) (1 - 0) -> x1 - e1 = e^-0.5; e2 = e1 + (1 - e^-1) (1 - e1)
    # -> x2 - e2 = (1 - e1) e^-1 = e^-0.5 e^-1 = e^-1.5
    t = np.array([0.0, 0.1, 0.3])
    base = np.column_stack([[0.0, 1.0, 1.0], np.zeros(3), np.zeros(3)])
    got = ema_residuals(t, base, MemorySpec((0.2,), ("iq",)))
    np.testing.assert_allclose(got[:, 0], [0.0, math.exp(-0.5), math.exp(-1.5)], rtol=1e-14)


def test_no_memory_is_the_plain_window() -> None:
    base = np.arange(12.0).reshape(4, 3)
    assert memory_inputs(np.arange(4.0), base, MemorySpec.none()).shape == (4, 3)
    assert memory_inputs(np.arange(4.0), base, MemorySpec()).shape == (4, 11)
    assert MemorySpec.from_dict(None) == MemorySpec.none()
    assert MemorySpec.parse("none") == MemorySpec.none()
    assert MemorySpec.parse("ema") == MemorySpec()
    assert MemorySpec.parse("0.5,2").time_constants_s == (0.5, 2.0)
    for bad in ("fast", "0,1", "-1"):
        with pytest.raises(TeleopInputError):
            MemorySpec.parse(bad)


SMALL = GruConfig(window=6, hidden_size=6, max_epochs=2, memory=MemorySpec((0.2, 2.0)))


@pytest.fixture(scope="module")
def trained(short_recording: FollowerRecording) -> tuple[ForceEstimator, dict]:
    estimator, summary = train_estimator(short_recording.slice(0, 3000), SMALL, seed=2)
    return estimator, summary.to_dict()


def test_the_causal_stream_builds_the_same_memory_features(
    trained, short_recording: FollowerRecording
) -> None:
    estimator, _ = trained
    rec = short_recording.slice(0, 700)
    stream = estimator.stream()
    for t, iq, w in zip(rec.t, rec.iq, rec.omega, strict=True):
        stream.push(t, iq, w)
    # the window's last rows, standardised, against the batch inputs of the same samples
    batch = estimator.gru.standardisation.features(
        estimator.gru.inputs(rec.t, np.column_stack([rec.iq, rec.omega, rec.alpha]))
    )
    np.testing.assert_allclose(stream.buffer[:, 3:], batch[-6:, 3:], rtol=0, atol=1e-12)
    # and the estimates of a fresh stream are the batch's
    fresh = estimator.stream()
    got = [fresh.update(t, i, w) for t, i, w in zip(rec.t, rec.iq, rec.omega, strict=True)]
    hybrid = np.array([o[1] for o in got[5:]])
    np.testing.assert_allclose(hybrid, estimator.predict(rec).f_hybrid, rtol=0, atol=1e-12)


def test_the_memory_choice_is_saved_and_loaded(
    tmp_path: Path, trained, short_recording: FollowerRecording
) -> None:
    estimator, summary = trained
    estimator.save(tmp_path / "m", summary)
    meta = json.loads((tmp_path / "m" / "standardisation.json").read_text())
    assert meta["memory"] == {
        "kind": "ema_residual",
        "columns": ["iq", "omega"],
        "time_constants_s": [0.2, 2.0],
    }
    loaded = ForceEstimator.load(tmp_path / "m")
    assert loaded.gru.memory == SMALL.memory
    rec = short_recording.slice(3000, 3600)
    np.testing.assert_array_equal(loaded.predict(rec).f_final, estimator.predict(rec).f_final)
    # without the metadata the folder would read as the plain window: refused, saying why
    del meta["memory"]
    (tmp_path / "m" / "standardisation.json").write_text(json.dumps(meta))
    with pytest.raises(TeleopInputError, match=r"m: its network takes 7 inputs per step"):
        ForceEstimator.load(tmp_path / "m")


def test_a_folder_saved_before_memory_features_loads_as_the_plain_window(
    short_recording: FollowerRecording,
) -> None:
    meta = json.loads((SHIPPED / "standardisation.json").read_text())
    assert "memory" not in meta  # the shipped model predates memory features
    shipped = ForceEstimator.load(SHIPPED)
    assert shipped.gru.memory == MemorySpec.none()
    assert shipped.gru.weights.n_inputs == 3
    rec = short_recording.slice(0, 500)
    result = shipped.predict(rec)
    stream = shipped.stream()
    causal = [stream.update(t, i, w) for t, i, w in zip(rec.t, rec.iq, rec.omega, strict=True)]
    hybrid = np.array([o[1] for o in causal[shipped.window - 1 :]])
    np.testing.assert_allclose(hybrid, result.f_hybrid, rtol=0, atol=1e-12)
