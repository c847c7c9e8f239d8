"""Simulated participants fitted to a study's trials (issue 24): `study participants fit`.

- `observed.py`: the task's trials from the database, each person's moments.
- `simulate.py`: trait settings through the task's own trials, in parallel.
- `emulator.py`: the moments as a response surface of the traits.
- `estimate.py`: which traits the moments identify; each group's trait distribution by
  the method of simulated moments on the emulator.
- `checks.py`: what the model cannot explain (trends, condition order, outliers).
- `fit.py`: the whole fit, MODEL.json's content; `figure.py`: observed vs simulated.
"""
