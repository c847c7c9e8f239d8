"""The names of the participant fit's features of an LCCA trial, in a module of their
own: the task's declaration lists them without loading the numerics that compute them
(`study.tasks.lcca.features`), and those import them from here."""

FIT_FEATURES = (
    "advance_speed_m_s",
    "approach_m",
    "approaches",
    "target_speed_ratio",
    "aim_error_rad",
    "turn_peak_s",
    "turn_swing_s",
    "stall_s",
    "stall_backoffs",
    "peak_felt_rise_n_m",
)
"""The participant fit's features of a trial (`study.tasks.lcca.features.lcca_features`)."""
