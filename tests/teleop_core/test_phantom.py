"""The LCCA phantom against hand-computed geometry and the capstan and buckling laws."""

from __future__ import annotations

import math

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.loop.layout import E_BRANCH, E_DISTAL, E_PROXIMAL, E_SUCCESS, ENV_OUT
from teleop_core.phantom.anatomy import G_THETA, ArchAnatomy
from teleop_core.phantom.lcca import (
    CATCH_DEPTH_M,
    STATE_SIZE,
    GuidewireParams,
    LccaPhantom,
    lcca_phantom,
)
from teleop_core.phantom.regions import REGIONS


class Wire:
    """Drives the phantom function directly, one 1 ms step at a time."""

    def __init__(self, phantom: LccaPhantom) -> None:
        self.params = phantom.params()
        self.state = np.zeros(STATE_SIZE)
        self.out = np.zeros(ENV_OUT)

    def move(self, insertion_m: float, speed_m_s: float, rotation_rad: float) -> np.ndarray:
        lcca_phantom(self.state, self.params, insertion_m, speed_m_s, rotation_rad, 1e-3, self.out)
        return self.out.copy()

    def push(self, to_m: float, rotation_rad: float, speed_m_s: float = 0.01) -> np.ndarray:
        start = self.state[2]
        for x in np.arange(start, to_m, speed_m_s * 1e-3):
            out = self.move(float(x), speed_m_s, rotation_rad)
        return out


def region(out: np.ndarray) -> str:
    return REGIONS[int(out[E_BRANCH])]


def test_the_arch_turns_half_a_circle_and_the_lcca_lies_between_its_neighbours() -> None:
    phantom = LccaPhantom()
    main = phantom.geometry[0]
    assert main[-1, G_THETA] == pytest.approx(math.pi, abs=0.02)
    ostia = [phantom.ostium_m(b.name) for b in phantom.anatomy.branches]
    assert ostia == sorted(ostia)
    # ostium arc length = descending run + R * arch angle
    a = phantom.anatomy
    assert phantom.ostium_m("left common carotid") == pytest.approx(
        a.descending_length_m + a.arch_radius_m * 0.45 * math.pi
    )


def test_straight_run_friction_grows_with_inserted_length() -> None:
    wire = Wire(LccaPhantom())
    out = wire.push(0.10, 0.0, speed_m_s=0.01)
    w = GuidewireParams()
    # no curvature, no turning: F = f_len L tanh(v / v_s) + c_v L v
    expected = (
        w.friction_n_per_m * 0.10 * math.tanh(0.01 / w.smoothing_speed_m_s)
        + w.viscous_n_s_per_m2 * 0.10 * 0.01
    )
    assert out[E_PROXIMAL] == pytest.approx(expected, rel=1e-2)
    assert out[E_DISTAL] == 0.0


def test_pointing_at_the_lcca_enters_it_and_reaches_success() -> None:
    phantom = LccaPhantom()
    wire = Wire(phantom)
    target = phantom.ostium_m("left common carotid") + phantom.anatomy.target_depth_m
    out = wire.push(target + 0.002, rotation_rad=0.0)
    assert region(out) == "left common carotid"
    assert out[E_SUCCESS] == 1.0


@pytest.mark.parametrize(
    "rotation, depth, expected",
    [
        (1.2, 0.30, "left subclavian"),
        (-1.0, 0.30, "brachiocephalic"),
        (math.pi, 0.34, "ascending aorta"),  # the arch ends at 0.20 + pi 0.035 = 0.31 m
    ],
)
def test_the_tip_orientation_chooses_the_branch(
    rotation: float, depth: float, expected: str
) -> None:
    wire = Wire(LccaPhantom())
    out = wire.push(depth, rotation_rad=rotation)
    assert region(out) == expected
    assert out[E_SUCCESS] == 0.0


def test_pointing_just_off_the_ostium_catches_its_edge() -> None:
    phantom = LccaPhantom()
    lcca = next(b for b in phantom.anatomy.branches if b.name == "left common carotid")
    wire = Wire(phantom)
    ostium = phantom.ostium_m(lcca.name)
    out = wire.push(ostium + CATCH_DEPTH_M + 0.005, rotation_rad=1.5 * lcca.half_width_rad)
    # blocked 2 mm past the ostium: wall force k * (push beyond it)
    w = GuidewireParams()
    assert out[E_DISTAL] >= w.wall_stiffness_n_per_m * 0.004
    assert region(out) == "aortic arch"


def test_a_blocked_tip_prolapses_at_the_critical_load_and_capstan_amplifies_it() -> None:
    phantom = LccaPhantom()
    wire = Wire(phantom)
    end = phantom.meta[0]["end"]  # the valve at the end of the ascending aorta
    w = GuidewireParams()
    wire.push(end + 0.03, rotation_rad=math.pi)
    out = wire.move(end + 0.03, 0.0, math.pi)  # hold still: no sliding friction
    assert out[E_DISTAL] == pytest.approx(w.buckling_load_n, abs=0.02)
    slack = wire.state[1]
    assert slack == pytest.approx(0.03 - w.buckling_load_n / w.wall_stiffness_n_per_m, abs=2e-4)
    # T_proximal = T_distal e^(mu Theta) with Theta = pi at the valve
    theta = phantom.geometry[0, -1, G_THETA]
    expected = w.buckling_load_n * math.exp(w.friction_coefficient * theta)
    assert out[E_PROXIMAL] == pytest.approx(expected, rel=0.02)
    # pulling back takes the loop out first: the tip stays pressed
    out = wire.move(end + 0.03 - slack / 2, -0.01, math.pi)
    assert wire.state[1] == pytest.approx(slack / 2, abs=1e-6)
    assert out[E_DISTAL] == pytest.approx(w.buckling_load_n, abs=0.02)


def test_a_target_that_is_not_a_branch_is_refused() -> None:
    with pytest.raises(TeleopInputError, match="target branch"):
        LccaPhantom(anatomy=ArchAnatomy(target="renal"))
