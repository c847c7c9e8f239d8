"""What another recording would need to settle what this one leaves open.

A recording cannot tell look-alike effects apart (the loop reports them as
`ambiguous_effects`), nor explain structure that no family takes (`structure_remains`).
Another recording can, if it holds the right channel or the right excitation: a pure
delay and a first-order lag differ only above 1 / (2 pi tau), a wheel that slips and a
torque per amp that bends differ only where the load's own position is recorded. Each
open question gets one entry of the report's `to_tell_apart`:

- `effects`: the candidates (the ambiguous families, or the effects that leave
  residual structure along the quantity the verdict named);
- `channel`: what to record besides the recording's own channels;
- `excitation`: what motion or force to run, and what each candidate would show.

The table is written from the effects' definitions (`effects.py`, `library.py`), not
fitted: it says what distinguishes the shapes, which holds whatever the recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from teleop_core.calibration.verdict import SHARE_STRUCTURE


@dataclass(frozen=True)
class Tell:
    """A channel to record and an excitation to run that tell `effects` apart."""

    effects: tuple[str, ...]
    channel: str
    excitation: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "effects": list(self.effects),
            "channel": self.channel,
            "excitation": self.excitation,
        }


LAG = Tell(
    ("delay", "first_order_lag"),
    "the force sensor's output at its own, higher rate, with the drive's command "
    "timestamped on the same clock",
    "force steps or a chirp up to 1 / (2 pi tau) Hz and beyond: a delay shifts a step "
    "unchanged and keeps the amplitude at every frequency, a lag rounds the step and "
    "attenuates the fast part",
)
SLIP = Tell(
    ("current_nonlinearity", "force_saturation", "slip"),
    "the load side's own position (a second encoder on the instrument or the load), "
    "which stands while the wheel slips",
    "a hold against a stiff stop at a slowly rising current: a slip flattens the force "
    "at one level while the wheel turns on, a torque per amp that bends with the "
    "current bends at rest too",
)
LOAD_FRICTION = Tell(
    ("load_friction", "current_nonlinearity", "force_saturation"),
    "the normal force across the friction contact (a load cell on the clamp or the instrument)",
    "the same current at rest and in motion, and the same motion at two or more "
    "loads: friction that grows with the load acts only in motion, a bend of the "
    "torque per amp acts at rest too",
)
THERMAL = Tell(
    ("drift", "gain_change"),
    "the winding or housing temperature",
    "the same trajectory repeated at the start and at the end of a long session: a "
    "thermal drift follows the temperature, a step change does not",
)
GAP = Tell(
    ("backlash", "presliding_memory", "hysteresis"),
    "the load side's own position (an encoder after the transmission)",
    "slow reversals of growing amplitude, from well below the gap to several times "
    "it: a gap shows as travel without load motion, a pre-sliding memory as a smooth "
    "approach with the load moving",
)
FRICTION = Tell(
    ("stribeck", "viscous_nonlinear", "direction_asymmetry", "load_friction"),
    "the normal force across the friction contact (a load cell)",
    "constant-speed runs in both directions at speeds from well below to well above "
    "the Stribeck speed, at two loads: a Stribeck dip lies at low speed, a nonlinear "
    "drag at high speed, a direction asymmetry in one direction only, load friction "
    "scales with the load",
)
RIPPLE = Tell(
    ("position_periodic", "backlash"),
    "the angle at a higher resolution",
    "slow constant-speed turns over several revolutions in both directions: a ripple "
    "repeats with the angle, a gap with the reversals",
)
DYNAMICS = Tell(
    ("first_order_lag", "delay", "sensor dynamics"),
    "the force sensor's output at its own, higher rate",
    "a force chirp up to the sensor's bandwidth, or steps: residual structure smooth "
    "in time with no channel behind it is a dynamic the model lacks",
)
OTHER = Tell(
    (),
    "a channel of the quantity the residual follows",
    "a second recording with another pattern of speeds, loads and reversals, "
    "validated against this calibration (`--validate`)",
)

PAIRS: tuple[Tell, ...] = (LAG, SLIP, LOAD_FRICTION, THERMAL, GAP, FRICTION, RIPPLE)
"""Rules for ambiguous families, in order: the first sharing two families applies."""
BY_QUANTITY: dict[str, Tell] = {
    "distance since reversal": GAP,
    "speed band": FRICTION,
    "speed": FRICTION,
    "direction": FRICTION,
    "drive": LOAD_FRICTION,
    "load": SLIP,
    "time window": THERMAL,
    "angle": RIPPLE,
    "accel": DYNAMICS,
}
"""Rules for the quantity along which structure remains (`verdict.unexplained`)."""


def _for_ambiguous(families: list[str]) -> Tell:
    for rule in PAIRS:
        if len(set(rule.effects) & set(families)) >= 2:
            return Tell(tuple(families), rule.channel, rule.excitation)
    return Tell(tuple(families), OTHER.channel, OTHER.excitation)


def tell_apart(
    ambiguous: list[list[str]], verdict: str, unexplained: dict[str, Any] | None
) -> list[dict[str, Any]]:
    """One entry (`Tell.to_dict`) per ambiguous group of families, and one for the
    structure that remains (`verdict` `structure_remains`): by the quantity
    `unexplained` names where it explains the residual beyond chance, else as a
    dynamic the model lacks (smooth in time, no channel behind it)."""
    out = [_for_ambiguous(families).to_dict() for families in ambiguous if families]
    if verdict == "structure_remains":
        where = unexplained or {}
        beyond = where.get("share_beyond_chance", 0.0) >= SHARE_STRUCTURE
        named = where.get("quantity") if beyond else None
        rule = BY_QUANTITY.get(named, OTHER) if named else DYNAMICS
        out.append({**rule.to_dict(), "along": named or "time (smooth residual)"})
    return out
