"""Effects the loop used to miss on recordings drawn as the generalisation bench draws
them: a short pure delay (below one JND), a gain that differs with the direction of
motion, a backlash wider than the bench's range.

Each recording is a clean simulated follower recording (`synthetic.follower_recording`)
whose true, noise-free force gets a planted deviation in closed form, the sensors'
noise on top; the reference is the oracle, eq. 1 plus the exact deviation as one more
column fitted on the training block (`general.oracle_rmse`'s rule).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from teleop_core.calibration import Calibrator, FollowerBase
from teleop_core.calibration.effects import play_operator
from teleop_core.calibration.models import CalibrationData
from teleop_core.calibration.synthetic import JND_N, follower_recording

Shape = Callable[[dict[str, np.ndarray]], np.ndarray]


def planted(
    deviation: Shape,
    seed: int,
    size_jnd: float | None = None,
    seconds: float = 60.0,
    rate_hz: float = 200.0,
) -> tuple[CalibrationData, float]:
    """A clean recording whose true force gets `deviation(true)` (scaled to `size_jnd`
    JND RMS, or as it is), and the oracle's held-out RMSE."""
    true: dict = {}
    rec, _ = follower_recording(seconds, (), rate_hz=rate_hz, seed=seed, noise_free=true)
    data = FollowerBase().data(rec)
    d = deviation(true)
    if size_jnd is not None:
        d = size_jnd * JND_N * d / np.sqrt(np.mean(d**2))
    y = data.y + d
    X = np.column_stack([FollowerBase().columns(data.signals), d])
    cut = round(0.75 * len(y))
    coef, *_ = np.linalg.lstsq(X[:cut], y[:cut], rcond=None)
    oracle = float(np.sqrt(np.mean((y[cut:] - X[cut:] @ coef) ** 2)))
    return CalibrationData(data.signals, y, f"planted (seed {seed}, simulated)"), oracle


def names(report: dict) -> list[str]:
    return [e["family"] for e in report["effects_added"]] + [
        t["term"] for t in report["discovered_terms"]
    ]


def delayed(lag_s: float) -> Shape:
    """The whole true force taken lag_s earlier, minus the force: a pure delay."""
    return lambda s: np.interp(s["t"] - lag_s, s["t"], s["force"]) - s["force"]


@pytest.mark.parametrize("seed", [1, 2])
def test_a_15_ms_delay_below_one_jnd_is_named_delay(seed: int) -> None:
    data, oracle = planted(delayed(0.015), seed)
    report = Calibrator(FollowerBase()).fit(data).report()
    assert names(report) == ["delay"]
    assert report["ambiguous_effects"] == []
    (delay,) = report["effects_added"]
    assert delay["params"]["lag_s"] == pytest.approx(0.015, abs=1e-9)
    assert report["rmse_after"] <= 1.05 * oracle


def reverse_gain(s: dict[str, np.ndarray]) -> np.ndarray:
    """A torque per amp that differs by direction: the current's force in reverse only."""
    return s["drive"] * (s["speed"] < 0)


@pytest.mark.parametrize("seed", [1, 3])
def test_a_gain_that_differs_by_direction_is_named_direction_asymmetry(seed: int) -> None:
    # it used to leave its shape (a force proportional to the current, in reverse
    # only) to the speed families, at twice the oracle's error or more
    data, oracle = planted(reverse_gain, seed, size_jnd=1.5)
    report = Calibrator(FollowerBase()).fit(data).report()
    assert names(report) == ["direction_asymmetry"]
    assert report["ambiguous_effects"] == []
    (effect,) = report["effects_added"]
    # the planted force per amp in reverse, in N m per A through the wheel's radius
    scale = 1.5 * JND_N / np.sqrt(np.mean(reverse_gain(_true(seed)) ** 2))
    r = FollowerBase().wheel_radius_m
    gain = effect["params"]["extra_gain_reverse_n_m_per_drive_unit"]
    assert gain == pytest.approx(scale * r, rel=0.15)
    assert report["rmse_after"] <= 1.5 * oracle


def _true(seed: int, seconds: float = 60.0, rate_hz: float = 200.0) -> dict:
    true: dict = {}
    follower_recording(seconds, (), rate_hz=rate_hz, seed=seed, noise_free=true)
    return true


def test_a_direction_asymmetry_saved_without_its_reverse_gain_still_loads() -> None:
    # a model saved before the follower's direction asymmetry had its third column: two
    # coefficients for it, read back as the two-column form, predicting as it was fitted
    from teleop_core.calibration.effects import DirectionAsymmetry
    from teleop_core.calibration.fitting import CalibratedModel, design

    data, _ = planted(reverse_gain, 1, size_jnd=1.5, seconds=10.0)
    model = FollowerBase(sign_speed_rad_s=0.3)
    chain = [(DirectionAsymmetry(), float("nan"))]
    X, _ = design(model, data.signals, chain)
    coef = np.linalg.lstsq(X, data.y, rcond=None)[0]
    saved = CalibratedModel(model, chain, coef, {"sign_speed_rad_s": 0.3}).to_dict()
    assert "reverse_gain" not in saved["effects"][0]
    loaded = CalibratedModel.from_dict(saved)
    np.testing.assert_allclose(loaded.predict(data), X @ coef, rtol=1e-12)
    # and one saved now keeps its three columns
    now = [(model.effect("direction_asymmetry"), float("nan"))]
    X3, _ = design(model, data.signals, now)
    assert X3.shape[1] == 5 + 3
    fitted = CalibratedModel(model, now, np.linalg.lstsq(X3, data.y, rcond=None)[0])
    again = CalibratedModel.from_dict(fitted.to_dict())
    np.testing.assert_allclose(again.predict(data), X3 @ fitted.coef, rtol=1e-12)


def gap_losing_the_drive(half_gap_rad: float) -> Shape:
    """A gap in the drive that passes none of the current's force at a turn and all of
    it once crossed: the current's force times (|h| - 1), h the play operator of the
    true angle (+-1 once the gap is crossed)."""
    return lambda s: (np.abs(play_operator(s["angle"], half_gap_rad)) - 1.0) * s["drive"]


@pytest.mark.parametrize(("half_gap_rad", "seed"), [(0.3, 1), (0.05, 2)])
def test_a_gap_that_loses_the_drives_force_is_named_backlash(
    half_gap_rad: float, seed: int
) -> None:
    # the backlash term held only a force across the gap; a gap that loses the drive's
    # force while it is open (six times the bench's widest, and one inside it) ended at
    # ten times the oracle's error with nothing named
    data, oracle = planted(gap_losing_the_drive(half_gap_rad), seed, size_jnd=1.5)
    report = Calibrator(FollowerBase()).fit(data).report()
    assert names(report) == ["backlash"]
    (term,) = report["discovered_terms"]
    assert term["params"]["half_gap"] == pytest.approx(half_gap_rad, rel=0.2)
    assert report["rmse_after"] <= 1.3 * oracle


def test_a_clean_recording_stays_white_with_nothing_added() -> None:
    data, _ = planted(lambda s: np.zeros_like(s["t"]), 4)
    report = Calibrator(FollowerBase()).fit(data).report()
    assert names(report) == []
    assert report["ambiguous_effects"] == []
    assert report["verdict"] == "white"


def test_a_slip_is_reported_with_the_channel_and_excitation_that_would_tell() -> None:
    # the whole force saturated (a wheel that slips past a traction limit): no family
    # has its shape; the report names the look-alikes and what would tell them apart,
    # the load side's own position under a slowly rising current against a stop
    def slip(s: dict[str, np.ndarray]) -> np.ndarray:
        level = np.quantile(np.abs(s["force"]), 0.8)
        return np.clip(s["force"], -level, level) - s["force"]

    data, _ = planted(slip, 3)
    report = Calibrator(FollowerBase()).fit(data).report()
    told = report["to_tell_apart"]
    assert told, report["verdict"]
    slip_rule = [t for t in told if "force_saturation" in t["effects"]]
    assert slip_rule
    assert "load side's own position" in slip_rule[0]["channel"]
    assert "rising current" in slip_rule[0]["excitation"]


def test_what_would_tell_follows_the_ambiguity_and_the_remaining_structure() -> None:
    from teleop_core.calibration.tell_apart import DYNAMICS, GAP, LAG, OTHER, tell_apart

    where = {"quantity": "distance since reversal", "share_beyond_chance": 0.1}
    (lag, gap) = tell_apart([["delay", "first_order_lag"]], "structure_remains", where)
    assert (lag["effects"], lag["channel"]) == (["delay", "first_order_lag"], LAG.channel)
    assert (gap["channel"], gap["along"]) == (GAP.channel, "distance since reversal")
    # structure smooth in time that no quantity explains beyond chance: a dynamic
    weak = {"quantity": "angle", "share_beyond_chance": 0.001}
    (dynamic,) = tell_apart([], "structure_remains", weak)
    assert dynamic["channel"] == DYNAMICS.channel
    # a white verdict with nothing ambiguous leaves no question open
    assert tell_apart([], "white", None) == []
    (other,) = tell_apart([["stribeck", "gain_change"]], "white", None)
    assert other["channel"] == OTHER.channel


def test_the_reverse_gains_switch_is_three_noise_sds_of_the_speed_wide() -> None:
    from teleop_core.calibration.effects import reverse_gain_sign_width

    rng = np.random.default_rng(0)
    t = np.arange(20_000) * 0.005
    speed = 2.0 * np.sin(0.5 * t)
    noisy = speed + rng.normal(0.0, 0.02, len(t))
    assert reverse_gain_sign_width(noisy) == pytest.approx(3 * 0.02, rel=0.05)
    # a noise-free ramp (its steps all equal: no noise): a thousandth of the speed's
    # range (its 99th percentile of |w|)
    ramp = np.linspace(-2.0, 2.0, 1001)
    assert reverse_gain_sign_width(ramp) == pytest.approx(1e-3 * 1.98, rel=1e-6)


def test_what_a_delay_leaves_of_a_long_lag_is_not_named_backlash() -> None:
    # a 55 ms first-order lag of the whole force (the generalisation bench's recording
    # of seed 10103): the delay that holds most of it is ambiguous with the lag, and
    # the backlash that took what it left after each reversal is ambiguous with the
    # lag too, not named
    from teleop_core.calibration.general import general_recording

    drawn = general_recording(("lag",), 10103, 240.0, 200.0)
    assert drawn.truth[0]["params"]["time_constant_s"] == pytest.approx(0.0547, abs=1e-4)
    report = Calibrator(FollowerBase()).fit(drawn.data).report()
    assert names(report) == []
    assert [a["families"][-1] for a in report["ambiguous_effects"]] == ["first_order_lag"] * len(
        report["ambiguous_effects"]
    )
    assert report["verdict"] == "structure_remains"
    assert report["to_tell_apart"][0]["effects"][-1] == "first_order_lag"
