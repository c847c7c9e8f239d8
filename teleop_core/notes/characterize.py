"""The characterisation of one NOTES axis end to end ([notes], III): ramps, chirps, fit.

Owns the sequence the paper runs on its bench, on the simulated device or on recorded
files: a clamped static ramp (continuous limit, hysteresis, direction gains), the same
ramp with the fitted Karnopp/direction compensator in the loop (before/after), open and
clamped 1-30 Hz chirps, their grey-box fit, and the force bandwidth and settling time
of the fitted F(s). The numbers come back as `AxisCharacterisation`, whose
`to_dict()` is one axis of the `study characterize notes` JSON.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleop_core.notes.compensation import KarnoppCompensator
from teleop_core.notes.identify import Frf, GreyBoxFit, RampMeasures, measure_frf, ramp_measures
from teleop_core.notes.params import MSD_FIELDS, AxisParams, MsdParams
from teleop_core.notes.recording import NotesRecording
from teleop_core.notes.simulate import BOUNDARIES, ramp_command, simulate_recording
from teleop_core.notes.simulate import simulate_response as _simulate_response
from teleop_core.notes.transfer import force_bandwidth_hz, settling_time_s


@dataclass(frozen=True)
class AxisCharacterisation:
    """Everything measured on one axis."""

    dof: str
    """"translation" or "rotation"."""
    ramp: NotesRecording
    """The clamped static ramp without compensation."""
    ramp_compensated: NotesRecording | None
    """The same ramp with the fitted compensator in the loop (simulated device only)."""
    before: RampMeasures
    """Ramp measures without compensation."""
    after: RampMeasures | None
    """Ramp measures with compensation."""
    compensator: KarnoppCompensator
    """Fitted from the uncompensated ramp."""
    frfs: list[Frf]
    """Measured V and F responses."""
    fit: GreyBoxFit
    """Grey-box fit to `frfs`."""
    truth: MsdParams | None
    """The simulated device's true parameters, when simulated."""

    @property
    def bandwidth_hz(self) -> float:
        return force_bandwidth_hz(self.fit.params_)

    @property
    def settling_time_s(self) -> float:
        return settling_time_s(self.fit.params_)

    def to_dict(self) -> dict[str, object]:
        """One axis of the characterisation JSON (SI units; rotation in N m, rad)."""
        out: dict[str, object] = {
            "bandwidth_hz": self.bandwidth_hz,
            "settling_time_s": self.settling_time_s,
            "max_continuous": self.before.max_continuous,
            "parameters": dict(zip(MSD_FIELDS, self.fit.params_.as_tuple(), strict=True)),
            "fit_quality": {f"fit_percent_{k}": v for k, v in self.fit.fit_percent_.items()},
            "ramp": self.before.to_dict(),
        }
        if self.truth is not None:
            out["true_parameters"] = dict(zip(MSD_FIELDS, self.truth.as_tuple(), strict=True))
            out["true_bandwidth_hz"] = force_bandwidth_hz(self.truth)
            out["true_settling_time_s"] = settling_time_s(self.truth)
        if self.after is not None:
            out["compensation"] = {
                "compensator": self.compensator.to_dict(),
                "before": self.before.to_dict(),
                "after": self.after.to_dict(),
            }
        return out


def characterize_simulated(
    params: AxisParams, noise: float = 0.0, seed: int = 0
) -> AxisCharacterisation:
    """Run the paper's experiments on the simulated device `params` (friction on)."""
    ramp = NotesRecording.from_frame(
        simulate_recording(params, "ramp", "clamped", noise=noise, seed=seed)
    )
    compensator = KarnoppCompensator().fit(ramp)
    t, u = ramp_command(params.dof)
    y = _simulate_response(params, t, u, "clamped", compensator=compensator)
    ramp_comp = NotesRecording(t, u, y, "clamped")
    chirps = [
        NotesRecording.from_frame(
            simulate_recording(params, "chirp", b, noise=noise, seed=seed + 1 + i)
        )
        for i, b in enumerate(BOUNDARIES)
    ]
    frfs = [measure_frf(c) for c in chirps]
    fit = GreyBoxFit(params.linear).fit(frfs)
    return AxisCharacterisation(
        params.dof,
        ramp,
        ramp_comp,
        ramp_measures(ramp),
        ramp_measures(ramp_comp),
        compensator,
        frfs,
        fit,
        params.linear,
    )


@dataclass(frozen=True)
class ChirpFit:
    """A grey-box fit to recorded chirp responses (what `bode` draws)."""

    dof: str
    frfs: list[Frf]
    fit: GreyBoxFit

    @property
    def bandwidth_hz(self) -> float:
        return force_bandwidth_hz(self.fit.params_)


def identify_recording(
    recording: NotesRecording, start: MsdParams, dof: str = "translation"
) -> tuple[dict[str, object], ChirpFit | None]:
    """What one recorded file tells: a chirp's grey-box fit or a ramp's measures.

    A chirp (the command reverses often) is fitted from `start`: all five parameters
    from an open-ended run, the three that F(s) fixes from a clamped one (M_m and M_s
    held at `start`). A clamped ramp gives the limit, hysteresis, direction gains and
    the fitted compensator. Keys: `experiment`, `boundary` and either `parameters`,
    `free_parameters`, `fit_quality`, `bandwidth_hz`, `settling_time_s` or `ramp`,
    `compensator`; and the `ChirpFit` of a chirp (None for a ramp).
    """
    out: dict[str, object] = {
        "experiment": recording.experiment,
        "boundary": recording.boundary,
        "rows": len(recording.t),
    }
    if recording.experiment == "ramp":
        ramp = ramp_measures(recording).to_dict()
        out["ramp"] = ramp
        out["max_continuous"] = ramp["max_continuous"]
        out["compensator"] = KarnoppCompensator().fit(recording).to_dict()
        return out, None
    frfs = [measure_frf(recording)]
    fit = GreyBoxFit(start).fit(frfs)
    out["parameters"] = dict(zip(MSD_FIELDS, fit.params_.as_tuple(), strict=True))
    out["free_parameters"] = list(fit.free_)
    out["fit_quality"] = {f"fit_percent_{k}": v for k, v in fit.fit_percent_.items()}
    out["bandwidth_hz"] = force_bandwidth_hz(fit.params_)
    out["settling_time_s"] = settling_time_s(fit.params_)
    return out, ChirpFit(dof, frfs, fit)
