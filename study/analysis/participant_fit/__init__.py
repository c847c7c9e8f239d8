"""Simulated participants fitted to a study's trials: `study participants fit`.

- `observed.py`: the task's trials from the database, their sample features (the task's
  `fit_features`, e.g. `study.tasks.lcca.features`), each person's moments.
- `simulate.py`: trait settings through the task's own trials, in parallel.
- `emulator.py`: the moments as a response surface of the traits.
- `estimate.py`: which traits the moments identify; each group's trait distribution by
  a hierarchical model (each person's traits, then the group's) fitted by EM, the
  weakly told traits' group means under their profile's prior.
- `validate.py`: how well one person's trials tell their traits, on held-out settings.
- `checks.py`: what the model cannot explain (trends, condition order, outliers,
  group means).
- `fit.py`: the whole fit, MODEL.json's content; `summaries.py`: its observed vs simulated
  summaries and the effects `study power` takes; `figure.py`: observed vs simulated.
"""

WEAK_TRAITS = ("prior", "shrink")
"""What `--weak-traits` may be (`fit.FitSettings.weak_traits`); here, so that the commands
offer the choices without importing the fit."""
