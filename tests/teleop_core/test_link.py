"""The link: delay, jitter, loss, and the newest-wins receiver."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.loop.link import Link, LinkParams


def test_a_packet_arrives_after_exactly_the_delay() -> None:
    link: Link[float] = Link(LinkParams(delay_s=0.005))
    link.send(1.0, 3.0)
    assert link.receive(1.0049) is None
    assert link.receive(1.005) == 3.0
    assert link.value_sent_at_s == 1.0


def test_losses_follow_the_configured_probability() -> None:
    link: Link[int] = Link(LinkParams(loss=0.3), np.random.default_rng(1))
    for k in range(10_000):
        link.send(k * 0.01, k)
        link.receive(k * 0.01)
    # binomial(10000, 0.3): sd = 45.8; 5 sd either way
    assert abs(link.lost - 3000) < 230
    assert link.delivered == 10_000 - link.lost


def test_jitter_stays_in_range_and_late_packets_never_overwrite_newer_ones() -> None:
    link: Link[int] = Link(LinkParams(delay_s=0.002, jitter_s=0.02), np.random.default_rng(2))
    seen = []
    for k in range(2000):
        t = k * 0.001
        link.send(t, k)
        value = link.receive(t)
        if value is not None:
            seen.append(value)
            assert t - link.value_sent_at_s >= 0.002 - 1e-12
    assert np.all(np.diff(seen) >= 0)
    assert link.discarded_late > 0  # 20 ms of jitter at 1 kHz reorders packets


@pytest.mark.parametrize("kwargs", [{"delay_s": -1.0}, {"jitter_s": float("nan")}, {"loss": 1.5}])
def test_bad_link_parameters_are_refused(kwargs: dict[str, float]) -> None:
    with pytest.raises(TeleopInputError, match="link"):
        LinkParams(**kwargs)
