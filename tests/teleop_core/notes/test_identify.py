"""Characterisation of the simulated NOTES device: ramps, compensation, grey-box round trip."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from teleop_core.notes.compensation import KarnoppCompensator
from teleop_core.notes.identify import GreyBoxFit, measure_frf, ramp_measures
from teleop_core.notes.params import MSD_FIELDS, RotationParams, TranslationParams
from teleop_core.notes.recording import NotesRecording, NotesRecordingError
from teleop_core.notes.simulate import (
    BOUNDARIES,
    ramp_command,
    simulate_recording,
    simulate_response,
)


@pytest.fixture(scope="module")
def rotation_ramp() -> NotesRecording:
    return NotesRecording.from_frame(simulate_recording(RotationParams(), "ramp", "clamped"))


def test_translation_ramp_tops_out_at_the_continuous_limit() -> None:
    p = TranslationParams()
    m = ramp_measures(NotesRecording.from_frame(simulate_recording(p, "ramp", "clamped")))
    assert m.max_continuous == pytest.approx(5.62, rel=0.005)
    # loading g u - F_c, unloading g u + F_c: the gap between branches is 2 F_c
    assert m.hysteresis == pytest.approx(2 * p.coulomb_friction_n, rel=0.05)
    # the -4 N end: -4 + F_c on the loading branch
    assert m.min_output == pytest.approx(-4.0 + p.coulomb_friction_n, abs=0.01)


def test_rotation_ramp_shows_the_ccw_loss(rotation_ramp: NotesRecording) -> None:
    p = RotationParams()
    m = ramp_measures(rotation_ramp)
    assert m.gain_positive == pytest.approx(p.cw_transmission, rel=0.01)
    assert m.gain_negative == pytest.approx(p.ccw_transmission, rel=0.01)
    assert m.max_continuous == pytest.approx(0.19005, rel=0.005)
    # CCW end: 0.8 * -0.190 + T_c
    assert m.min_output == pytest.approx(-0.190 * 0.8 + p.coulomb_friction_n_m, abs=5e-4)


def test_compensation_shrinks_hysteresis_and_asymmetry(rotation_ramp: NotesRecording) -> None:
    comp = KarnoppCompensator().fit(rotation_ramp)
    t, u = ramp_command("rotation")
    after = ramp_measures(
        NotesRecording(
            t, u, simulate_response(RotationParams(), t, u, "clamped", compensator=comp), "clamped"
        )
    )
    before = ramp_measures(rotation_ramp)
    assert after.hysteresis < 0.1 * before.hysteresis
    assert abs(after.asymmetry) < 0.01 < before.asymmetry


def test_grey_box_round_trip_within_5_percent() -> None:
    # one seeded draw moved up to 30 % from the defaults, 2 % sensor noise
    base = TranslationParams()
    rng = np.random.default_rng(42)
    truth = base.linear.scaled({n: float(rng.uniform(0.7, 1.3)) for n in MSD_FIELDS})
    device = base.with_linear(truth)
    frfs = [
        measure_frf(
            NotesRecording.from_frame(
                simulate_recording(device, "chirp", b, nonlinear=False, noise=0.02, seed=i)
            )
        )
        for i, b in enumerate(BOUNDARIES)
    ]
    fit = GreyBoxFit(base.linear).fit(frfs)
    err = np.array(fit.params_.as_tuple()) / np.array(truth.as_tuple()) - 1
    assert np.all(np.abs(err) < 0.05), dict(zip(MSD_FIELDS, err, strict=True))
    assert min(fit.fit_percent_.values()) > 80


def test_clamped_chirp_alone_fits_only_the_ratios() -> None:
    base = TranslationParams()
    truth = base.linear.scaled({"k_s": 1.2, "b_m": 0.8})
    rec = NotesRecording.from_frame(
        simulate_recording(base.with_linear(truth), "chirp", "clamped", nonlinear=False)
    )
    fit = GreyBoxFit(base.linear).fit([measure_frf(rec)])
    assert fit.free_ == ("k_s", "b_m", "b_s")
    assert fit.params_.m_m == base.linear.m_m
    assert fit.params_.k_s == pytest.approx(truth.k_s, rel=0.02)
    assert fit.params_.b_m == pytest.approx(truth.b_m, rel=0.02)


def _frame(n: int = 300) -> pd.DataFrame:
    t = np.arange(n) * 1e-3
    return pd.DataFrame({"t": t, "f_des": np.sin(t), "f_ee": np.sin(t)})


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.drop(columns="f_des"), "column 'f_des' missing"),
        (lambda f: f.assign(x=0.0), "both x and f_ee"),
        (
            lambda f: f.astype(object).assign(f_ee=["1"] * 9 + ["oops"] + ["1"] * 290),
            "row 11, column 'f_ee'",
        ),
        (lambda f: f.assign(t=np.r_[f.t[:5], f.t[4], f.t[6:]]), "row 7, column 't'"),
        (lambda f: f.iloc[:50], "50 data rows"),
    ],
)
def test_bad_recordings_are_refused_with_row_and_column(edit, message: str) -> None:
    with pytest.raises(NotesRecordingError, match=message):
        NotesRecording.from_frame(edit(_frame()), "recording r.csv")


def test_experiment_is_told_from_the_command() -> None:
    ramp = NotesRecording.from_frame(simulate_recording(TranslationParams(), "ramp", "clamped"))
    assert ramp.experiment == "ramp"
    assert ramp_command("translation")[1].max() == 6.0
