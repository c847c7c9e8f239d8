"""The fitted group means' 95 % intervals (`estimate.expanded_interval`): Hesterberg's
expanded percentile interval, checked against hand-computed values and by its coverage
of a normal mean over 8 people, where the plain percentile interval falls short."""

from __future__ import annotations

import numpy as np
import pytest

from study.analysis.participant_fit.estimate import expanded_interval


def test_the_percentile_interval_widened_about_the_median_by_the_t_factor() -> None:
    boots = np.arange(1001) / 1000.0  # percentiles 0.025, 0.5, 0.975
    # sqrt(8 / 7) * t(0.975, 7) / z(0.975) = 1.0690450 * 2.3646243 / 1.9599640
    widen = 1.0690450 * 2.3646243 / 1.9599640
    low, high = expanded_interval(boots, 8)
    assert low == pytest.approx(0.5 - widen * 0.475, abs=1e-6)
    assert high == pytest.approx(0.5 + widen * 0.475, abs=1e-6)
    # many people: the factor tends to 1 and the interval to the percentile one
    low, high = expanded_interval(boots, 10_000)
    assert (low, high) == pytest.approx((0.025, 0.975), abs=2e-4)


def test_it_holds_a_normal_mean_over_8_people_about_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(4)
    studies, n, b = 600, 8, 400
    plain = expanded = 0
    for _ in range(studies):
        people = rng.normal(1.0, 0.3, n)
        boots = people[rng.integers(0, n, (b, n))].mean(axis=1)
        lo, hi = np.percentile(boots, [2.5, 97.5])
        plain += lo <= 1.0 <= hi
        lo, hi = expanded_interval(boots, n)
        expanded += lo <= 1.0 <= hi
    # the plain percentile interval of a mean of 8 holds it about 89 % of the time
    # (sqrt(7 / 8) z in place of t(7)); the expanded one about 95 %
    assert plain / studies < 0.92
    assert 0.93 <= expanded / studies <= 0.97
