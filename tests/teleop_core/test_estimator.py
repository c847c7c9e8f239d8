"""The estimator end to end: causal equals batch, and a saved model predicts the same."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.estimator import MODEL_FILES, ForceEstimator
from teleop_core.estimation.gru import GruConfig
from teleop_core.estimation.training import train_estimator
from teleop_core.follower.recording import FollowerRecording

SMALL = GruConfig(window=8, hidden_size=8, learning_rate=3e-3, max_epochs=3)


@pytest.fixture(scope="module")
def trained(short_recording: FollowerRecording) -> tuple[ForceEstimator, dict]:
    estimator, summary = train_estimator(short_recording, SMALL, seed=1)
    return estimator, summary.to_dict()


def test_causal_updates_reproduce_the_batch_estimates(
    trained, short_recording: FollowerRecording
) -> None:
    estimator, _ = trained
    rec = short_recording.slice(0, 1500)
    batch = estimator.predict(rec)
    stream = estimator.stream()
    causal = [stream.update(t, i, w) for t, i, w in zip(rec.t, rec.iq, rec.omega, strict=True)]
    assert causal[: SMALL.window - 1] == [None] * (SMALL.window - 1)
    got = np.array(causal[SMALL.window - 1 :])
    for k, column in enumerate(("f_physics", "f_hybrid", "f_final")):
        np.testing.assert_allclose(got[:, k], getattr(batch, column), rtol=0, atol=1e-12)


def test_saved_model_predicts_the_same(
    tmp_path: Path, trained, short_recording: FollowerRecording
) -> None:
    estimator, summary = trained
    estimator.save(tmp_path / "model", summary)
    assert sorted(p.name for p in (tmp_path / "model").iterdir()) == sorted(
        [*MODEL_FILES, "gru.npz", "gru.pt"]
    )
    loaded = ForceEstimator.load(tmp_path / "model")
    a = estimator.predict(short_recording.slice(0, 800))
    b = loaded.predict(short_recording.slice(0, 800))
    np.testing.assert_array_equal(a.f_final, b.f_final)
    # a folder written before gru.npz existed has only PyTorch's gru.pt: the same numbers
    (tmp_path / "model" / "gru.npz").unlink()
    old = ForceEstimator.load(tmp_path / "model")
    np.testing.assert_array_equal(a.f_final, old.predict(short_recording.slice(0, 800)).f_final)


def test_damaged_gru_weights_are_refused_with_the_file_named(tmp_path: Path, trained) -> None:
    estimator, summary = trained
    estimator.save(tmp_path / "model", summary)
    (tmp_path / "model" / "gru.npz").write_bytes(b"not an npz")
    with pytest.raises(TeleopInputError, match=r"gru\.npz: .*expected the GRU weights"):
        ForceEstimator.load(tmp_path / "model")
    hidden = estimator.gru.weights.w_hh.shape[1]
    weights = estimator.gru.weights
    np.savez(
        tmp_path / "model" / "gru.npz",
        w_ih=weights.w_ih,
        w_hh=weights.w_hh[:-1],
        b_ih=weights.b_ih,
        b_hh=weights.b_hh,
        w_out=weights.w_out,
        b_out=weights.b_out,
    )
    with pytest.raises(TeleopInputError, match=rf"w_hh has shape .*expected \({3 * hidden}"):
        ForceEstimator.load(tmp_path / "model")


def test_summary_reports_each_stage_on_both_splits(trained) -> None:
    _, summary = trained
    for split in ("train_rmse_n", "validation_rmse_n"):
        assert set(summary[split]) == {"physics", "hybrid", "final"}
    assert 1 <= summary["best_epoch"] <= summary["epochs_run"] == 3
    assert summary["ekf_lag_s"] <= 1 / 50  # within one pipeline period


def test_process_noise_can_be_set_instead_of_tuned(short_recording: FollowerRecording) -> None:
    estimator, _ = train_estimator(short_recording.slice(0, 3000), SMALL, seed=1, ekf_q_n2=2.5e-4)
    assert estimator.ekf.q_physics_n2 == estimator.ekf.q_hybrid_n2 == 2.5e-4


def test_damaged_model_folder_is_refused(tmp_path: Path, trained) -> None:
    estimator, summary = trained
    estimator.save(tmp_path / "model", summary)
    (tmp_path / "model" / "ekf.json").unlink()
    with pytest.raises(TeleopInputError, match=r"has no ekf\.json"):
        ForceEstimator.load(tmp_path / "model")
    with pytest.raises(TeleopInputError, match="does not exist"):
        ForceEstimator.load(tmp_path / "nowhere")


def test_a_recording_at_another_rate_is_resampled_to_the_models(trained, short_recording) -> None:
    estimator, _ = trained
    rec = short_recording.slice(0, 1000)
    fast = rec.resampled(200.0)
    assert estimator.conform(fast).sample_rate_hz == pytest.approx(100.0, rel=1e-6)
    assert estimator.conform(rec) is rec


def test_a_filter_that_hurts_on_validation_passes_the_hybrid_estimate_through(
    tmp_path: Path, short_recording: FollowerRecording
) -> None:
    """A process noise far too small freezes the filter on its first
    state, which the validation blocks see as a large error; the model then passes the
    hybrid estimate through, in the batch path, the causal path and once saved."""
    rec = short_recording.slice(0, 3000)
    estimator, summary = train_estimator(rec, SMALL, seed=1, ekf_q_n2=1e-12)
    check = summary.ekf_check
    assert check["validation_rmse_filtered_n"] > check["validation_rmse_hybrid_n"]
    assert check["passthrough"]
    assert estimator.ekf.passthrough
    assert any("passes the hybrid" in note for note in summary.notes)
    v = summary.validation_rmse_n
    assert v["final"] == v["hybrid"]
    batch = estimator.predict(rec)
    np.testing.assert_array_equal(batch.f_final, batch.f_hybrid)
    stream = estimator.stream()
    causal = [stream.update(t, i, w) for t, i, w in zip(rec.t, rec.iq, rec.omega, strict=True)]
    got = np.array(causal[SMALL.window - 1 :])
    np.testing.assert_array_equal(got[:, 2], got[:, 1])
    estimator.save(tmp_path / "model", summary.to_dict())
    assert ForceEstimator.load(tmp_path / "model").ekf.passthrough


def test_a_filter_that_helps_on_validation_is_kept(trained) -> None:
    estimator, summary = trained
    check = summary["ekf_check"]
    assert check["validation_rmse_filtered_n"] < check["validation_rmse_hybrid_n"]
    assert not check["passthrough"]
    assert not estimator.ekf.passthrough
