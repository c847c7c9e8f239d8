"""Imported only by the fork server of `test_kill_points.py`: compiles the closed loop's
numba kernel once (8 s of CPU), so that the forked sessions start at once.

Only numba runs here, no torch operation: a forked child of a process that ran
OpenMP-parallel torch code can hang in its first parallel region.
"""

from study.protocol.default_estimator import load_estimator
from study.protocol.session import participant_traits
from study.tasks.lcca.simulated_participant import SimulatedParticipant
from study.tasks.lcca.trial import lcca_loop
from teleop_core.phantom.lcca import LccaPhantom

_phantom = LccaPhantom()
for _condition in ("VO", "HV"):
    _loop = lcca_loop(_condition, 0, load_estimator(), phantom=_phantom)
    _loop.start(SimulatedParticipant(participant_traits(3, "P001", "novice"), _phantom, 180.0))
    _loop.advance(0.1)
