"""The probes' line in `study participants fit`: who lacks which probe, grouped by what
they lack and with runs of consecutive codes as ranges, so a study that ran the probes
for one person reads as one short line rather than one entry per participant."""

from __future__ import annotations

import numpy as np

from study.probes.measure import code_runs, probe_summary

TRAITS = ("reaction_s", "haptic_threshold_n_m", "visual_stall_s")


def test_consecutive_codes_under_one_prefix_and_width_become_ranges() -> None:
    assert code_runs(["P002", "P003", "P004", "P009"]) == "P002-P004, P009"
    assert code_runs(["P001"]) == "P001"
    # another prefix or width breaks a run; a code without a number stands alone
    assert code_runs(["A1", "A2", "B3", "B4", "P09", "P010", "X"]) == "A1-A2, B3-B4, P09, P010, X"


def test_the_line_groups_the_participants_by_what_they_lack() -> None:
    nan = np.nan
    est = np.array(
        [
            [[0.3, 0.01], [0.004, 1e-4], [0.5, 0.05]],  # P001: every probe
            [[nan, nan], [nan, nan], [nan, nan]],  # P002: none
            [[nan, nan], [nan, nan], [nan, nan]],  # P003: none
            [[0.3, 0.01], [nan, nan], [0.5, 0.05]],  # P004: no threshold
            [[nan, nan], [nan, nan], [nan, nan]],  # P005: none
        ]
    )
    out = probe_summary(
        {"novice": est}, {"novice": ["P001", "P002", "P003", "P004", "P005"]}, TRAITS
    )
    assert out["missing"]["P004"] == ["haptic_threshold_n_m"]
    assert out["missing"]["P005"] == list(TRAITS)
    assert out["line"] == (
        "probes: 3 traits measured; 4 of 5 participants fitted without some: "
        "P002-P003, P005 (3) lack every probe; P004 lacks haptic_threshold_n_m"
    )
