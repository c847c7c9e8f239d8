"""`study bench master`: the paper's master-side experiments ([endovascular], IV-D, Figs. 10-11).

- Calibration (Fig. 10(b)): the dial presses its lever on the force gauge while the
  current command sweeps up and down the calibrated range; quadratics refitted to the
  loading and unloading halves (numpy.polyfit) are compared with eqs. 14-15.
- Frequency response (Figs. 10(c), 11): sinusoidal current commands from 1 to 12 Hz;
  the gauge force's amplitude at the command frequency (least-squares sine fit) relative
  to 1 Hz, and the -2 dB bandwidth interpolated between the tested frequencies. The
  simulated bench's roll-off comes from the current loop and the lever-and-gauge chain
  (`DialParams.gauge_time_constant_s`, set to the paper's figure): the bench checks the
  measurement procedure and the model's consistency, it cannot discover the 8 Hz.
- End-to-end force latency: a step in the force the follower publishes, through the link
  and the master controller, to the torque the dial's motor renders, over links of
  increasing delay. Latency is the time until the torque has made half of its step; the
  onset (10 %, when anything can first be felt) is reported beside it.
- The closed loop's speed: dial + follower + estimator + link with a simulated operator,
  headless, against real time.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from study.analysis.figures import label_source
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.loop.config import LoopConfig
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import (
    GRIP_DAMPING_N_M_S_PER_RAD,
    Driver,
    HandAction,
    OperatorView,
    SimulatedOperator,
)
from teleop_core.loop.environments import free_space, tube_with_wall
from teleop_core.loop.link import LinkParams
from teleop_core.master.dial import gauge_force
from teleop_core.master.params import DialParams
from teleop_core.progress import Progress, no_progress

FREQUENCIES_HZ = tuple(float(f) for f in range(1, 13))
FIG11_FREQUENCIES_HZ = (1.0, 4.0, 8.0, 12.0)
SIMULATED_NOTE = (
    "SIMULATED: the dial model on its simulated lever and gauge, and the simulated "
    "teleoperation loop; no measured data"
)
"""Written above every figure of this bench (`figures.label_source`) and in its JSON."""


@dataclass(frozen=True)
class MasterBenchConfig:
    calibration_cycles: int = 3
    calibration_period_s: float = 20.0
    sine_offset_ma: float = 2.0
    sine_amplitude_ma: float = 1.5
    sine_seconds: float = 4.0
    latency_delays_ms: tuple[float, ...] = (0.0, 2.0, 5.0, 10.0, 20.0)
    latency_repeats: int = 20
    loop_seconds: float = 60.0
    loop_repeats: int = 3
    seed: int = 0

    @classmethod
    def quick(cls) -> MasterBenchConfig:
        return cls(
            calibration_cycles=1,
            calibration_period_s=4.0,
            sine_seconds=2.0,
            latency_delays_ms=(0.0, 5.0),
            latency_repeats=3,
            loop_seconds=5.0,
            loop_repeats=1,
        )


def _gauge(params: DialParams, current_a: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Gauge force (N) at 1 kHz for a current command at 1 kHz, dial clamped on the lever."""
    return gauge_force(params, current_a, 1e-3, rng)


def calibration(config: MasterBenchConfig, rng: np.random.Generator) -> tuple[dict, plt.Figure]:
    params = DialParams()
    poly = params.polynomials
    n = round(config.calibration_period_s * 1000)
    up = np.linspace(0.0, poly.max_current_ma, n // 2, endpoint=False)
    cycle_ma = np.concatenate([up, poly.max_current_ma - up])
    current_ma = np.tile(cycle_ma, config.calibration_cycles)
    force = _gauge(params, current_ma / 1000.0, rng)
    # the gauge is read at 100 Hz; loading where the command rises
    idx = np.arange(9, len(current_ma), 10)
    i, f = current_ma[idx], force[idx]
    rising = np.gradient(current_ma)[idx] > 0
    fig, ax = plt.subplots(figsize=(3.5, 2.8), layout="constrained")
    ax.plot(i[rising], f[rising], ".", ms=1.5, color="C0", alpha=0.4, label="loading (measured)")
    ax.plot(i[~rising], f[~rising], ".", ms=1.5, color="C3", alpha=0.4, label="unloading")
    grid = np.linspace(0.0, poly.max_current_ma, 200)
    out: dict[str, Any] = {}
    for name, mask, color in (("loading", rising, "C0"), ("unloading", ~rising, "C3")):
        fitted = np.polyfit(i[mask], f[mask], 2)
        paper = np.array(getattr(poly, name))
        diff = np.polyval(fitted, grid) - np.polyval(paper, grid)
        out[name] = {
            "fitted": fitted.tolist(),
            "paper": paper.tolist(),
            "max_abs_difference_n": float(np.max(np.abs(diff))),
            "rms_difference_n": float(np.sqrt(np.mean(diff**2))),
        }
        ax.plot(grid, np.polyval(fitted, grid), color=color, lw=1.2, label=f"{name} refit")
        ax.plot(grid, np.polyval(paper, grid), color="k", lw=0.8, ls="--")
    ax.plot([], [], color="k", lw=0.8, ls="--", label="eqs. 14-15")
    ax.set_xlabel("current (mA)")
    ax.set_ylabel("gauge force (N)")
    ax.legend(fontsize=6)
    return out, fig


def _sine_amplitude(t: np.ndarray, y: np.ndarray, f_hz: float) -> tuple[float, float]:
    """Amplitude and phase (rad) of the f_hz component by least squares with an offset."""
    w = 2 * math.pi * f_hz
    basis = np.column_stack([np.ones_like(t), np.sin(w * t), np.cos(w * t)])
    (_, a, b), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return math.hypot(a, b), math.atan2(b, a)


def bandwidth_at(freqs: np.ndarray, gain_db: np.ndarray, level_db: float = -2.0) -> float:
    """First frequency where the gain falls to `level_db`, interpolated; nan if never."""
    below = np.nonzero(gain_db <= level_db)[0]
    if len(below) == 0 or below[0] == 0:
        return math.nan
    k = below[0]
    f0, f1, g0, g1 = freqs[k - 1], freqs[k], gain_db[k - 1], gain_db[k]
    return float(f0 + (level_db - g0) * (f1 - f0) / (g1 - g0))


def frequency_response(
    config: MasterBenchConfig, rng: np.random.Generator
) -> tuple[dict, plt.Figure, plt.Figure]:
    params = DialParams()
    amps, phases, traces = [], [], {}
    for f_hz in FREQUENCIES_HZ:
        t = np.arange(round(config.sine_seconds * 1000)) * 1e-3
        i_ma = config.sine_offset_ma + config.sine_amplitude_ma * np.sin(2 * math.pi * f_hz * t)
        force = _gauge(params, i_ma / 1000.0, rng)
        keep = t >= 1.0  # after the start-up transient
        amp, phase = _sine_amplitude(t[keep], force[keep], f_hz)
        amps.append(amp)
        phases.append(phase)
        if f_hz in FIG11_FREQUENCIES_HZ:
            traces[f_hz] = (t, i_ma, force)
    freqs = np.array(FREQUENCIES_HZ)
    gain_db = 20 * np.log10(np.array(amps) / amps[0])
    phase_deg = np.degrees(np.unwrap(np.array(phases)) - phases[0])
    bw = bandwidth_at(freqs, gain_db)
    fig, (a, b) = plt.subplots(2, 1, figsize=(3.5, 3.6), sharex=True, layout="constrained")
    a.plot(freqs, gain_db, "o-", color="C0")
    a.axhline(-2.0, color="0.5", ls="--", lw=0.8)
    if math.isfinite(bw):
        a.axvline(bw, color="C3", lw=0.8)
        a.annotate(
            f"-2 dB at {bw:.1f} Hz",
            (bw, -2.0),
            fontsize=7,
            xytext=(4, 6),
            textcoords="offset points",
        )
    a.set_ylabel("gain (dB, re 1 Hz)")
    b.plot(freqs, phase_deg, "o-", color="C1")
    b.set_ylabel("phase (deg)")
    b.set_xlabel("frequency (Hz)")
    fig11, axes = plt.subplots(
        len(traces), 1, figsize=(3.5, 4.2), sharex=True, layout="constrained"
    )
    slope = np.polyval(np.polyder(np.array(params.polynomials.loading)), config.sine_offset_ma)
    for ax, (f_hz, (t, i_ma, force)) in zip(axes, traces.items(), strict=True):
        span = (t >= 1.0) & (t < 2.0)
        nominal = np.polyval(params.polynomials.loading, config.sine_offset_ma) + slope * (
            i_ma - config.sine_offset_ma
        )
        ax.plot(t[span] - 1.0, nominal[span], color="0.4", lw=0.8, ls="--", label="nominal")
        ax.plot(t[span] - 1.0, force[span], color="C0", lw=0.8, label="gauge")
        ax.set_ylabel(f"{f_hz:.0f} Hz\nN", fontsize=7)
    axes[0].legend(fontsize=6, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    table = {
        "frequencies_hz": freqs.tolist(),
        "gain_db": gain_db.tolist(),
        "phase_deg": phase_deg.tolist(),
        "bandwidth_minus_2db_hz": bw,
        "offset_ma": config.sine_offset_ma,
        "amplitude_ma": config.sine_amplitude_ma,
    }
    return table, fig, fig11


class HoldDial(Driver):
    """A hand holding the dial firmly at centre (the latency bench's operator)."""

    def act(self, view: OperatorView) -> HandAction:
        return HandAction(0.0, 2.0, 10 * GRIP_DAMPING_N_M_S_PER_RAD)


def _step_latency(delay_ms: float, step_s: float, seed: int) -> tuple[float, float, np.ndarray]:
    """(onset to 10 %, latency to 50 %) in ms for one force step, and the tick log."""
    cfg = LoopConfig(to_master=LinkParams(delay_s=delay_ms / 1000.0))
    published: list[float] = []

    def force(t_s: float) -> float:
        if t_s >= step_s and not published:
            published.append(t_s)  # the instant the follower publishes the step
        return 1.0 if t_s >= step_s else 0.0

    loop = TeleopLoop(cfg, free_space(), seed=seed, force_override=force, keep_ticks=True)
    ticks = loop.run(step_s + 0.2, HoldDial()).ticks_frame()
    t0 = published[0]
    tau = ticks["dial_torque_n_m"].to_numpy()
    t = ticks["t_s"].to_numpy()
    before = np.mean(tau[(t > t0 - 0.05) & (t <= t0)])
    after = np.mean(tau[t > t0 + 0.08])
    change = (tau - before) / (after - before)
    later = t > t0
    t10 = t[later][np.argmax(change[later] >= 0.1)]
    t50 = t[later][np.argmax(change[later] >= 0.5)]
    return (t10 - t0) * 1000.0, (t50 - t0) * 1000.0, np.column_stack([t - t0, change])


def latency(config: MasterBenchConfig, rng: np.random.Generator) -> tuple[dict, plt.Figure]:
    rows = []
    fig, ax = plt.subplots(figsize=(3.5, 2.6), layout="constrained")
    for k, delay_ms in enumerate(config.latency_delays_ms):
        onsets, latencies = [], []
        for _ in range(config.latency_repeats):
            step_s = 0.4 + rng.uniform(0.0, 0.1)
            a, b, trace = _step_latency(delay_ms, step_s, int(rng.integers(2**31)))
            onsets.append(a)
            latencies.append(b)
        rows.append(
            {
                "link_delay_ms": delay_ms,
                "latency_ms_mean": float(np.mean(latencies)),
                "latency_ms_max": float(np.max(latencies)),
                "onset_10_ms_mean": float(np.mean(onsets)),
            }
        )
        span = (trace[:, 0] > -0.005) & (trace[:, 0] < 0.06)
        ax.plot(
            trace[span, 0] * 1000,
            trace[span, 1],
            color=f"C{k}",
            lw=1,
            label=f"link {delay_ms:g} ms",
        )
    base = rows[0]["latency_ms_mean"]
    for row in rows:
        row["increase_ms"] = row["latency_ms_mean"] - base
    ax.axhline(0.5, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("time after the force step is published (ms)")
    ax.set_ylabel("torque change / step")
    ax.legend(fontsize=6)
    return {"threshold": "50 % of the torque step", "rows": rows}, fig


LINKS = {
    "wired": LinkParams(),
    "2 ms delay, 1 ms jitter, 1 % loss": LinkParams(delay_s=0.002, jitter_s=0.001, loss=0.01),
}
"""The links the loop is timed over: the paper's wired Ethernet (zero delay, IV-A) and a
degraded network."""


def closed_loop_speed(
    config: MasterBenchConfig, estimator: ForceEstimator, progress: Progress
) -> dict[str, Any]:
    """Real-time factor of the headless loop over each link in LINKS; the top-level
    figures are the wired link's."""
    out: dict[str, Any] = {"simulated_s": config.loop_seconds, "links": {}}
    for name, link in LINKS.items():
        cfg = LoopConfig(to_follower=link, to_master=link)
        warm = TeleopLoop(cfg, tube_with_wall(), estimator=estimator)
        warm.run(1.0, SimulatedOperator())  # compile outside the timing
        factors = []
        for k in range(config.loop_repeats):
            progress(f"closed loop, {name} link: run {k + 1}/{config.loop_repeats}")
            loop = TeleopLoop(
                cfg,
                tube_with_wall(wall_depth_m=10.0, target_depth_m=10.0),
                estimator=estimator,
                seed=k,
            )
            operator = SimulatedOperator(target_depth_m=10.0)
            start = time.perf_counter()
            loop.run(config.loop_seconds, operator)
            factors.append(loop.t_s / (time.perf_counter() - start))
        out["links"][name] = {
            "realtime_factors": factors,
            "realtime_factor_median": float(np.median(factors)),
            "counters": asdict(loop.counters),
        }
    out["realtime_factor_median"] = out["links"]["wired"]["realtime_factor_median"]
    out["realtime_factors"] = out["links"]["wired"]["realtime_factors"]
    return out


def markdown(report: dict[str, Any]) -> str:
    cal, fr, lat, cl = (
        report[k] for k in ("calibration", "frequency_response", "latency", "closed_loop")
    )
    lines = [
        "# Master bench (simulated dial)",
        "",
        "## Calibration (Fig. 10(b))",
        "",
        "| branch | refit a, b, c | eqs. 14-15 | max abs difference (N) |",
        "|---|---|---|---|",
    ]
    for name in ("loading", "unloading"):
        row = cal[name]
        fit = ", ".join(f"{v:.6f}" for v in row["fitted"])
        paper = ", ".join(f"{v:.6f}" for v in row["paper"])
        lines.append(f"| {name} | {fit} | {paper} | {row['max_abs_difference_n']:.4f} |")
    lines += [
        "",
        "## Frequency response (Figs. 10(c), 11)",
        "",
        "| f (Hz) | gain (dB) | phase (deg) |",
        "|---|---|---|",
    ]
    for f, g, p in zip(fr["frequencies_hz"], fr["gain_db"], fr["phase_deg"], strict=True):
        lines.append(f"| {f:g} | {g:.2f} | {p:.1f} |")
    lines += [
        "",
        f"-2 dB bandwidth: {fr['bandwidth_minus_2db_hz']:.2f} Hz (paper: about 8 Hz)",
        "",
        "## End-to-end force latency",
        "",
        f"Latency = time until the rendered torque has moved {lat['threshold']}.",
        "",
        "| link delay (ms) | latency mean (ms) | max (ms) | increase (ms) | onset, 10 % (ms) |",
        "|---|---|---|---|---|",
    ]
    for row in lat["rows"]:
        lines.append(
            f"| {row['link_delay_ms']:g} | {row['latency_ms_mean']:.2f} "
            f"| {row['latency_ms_max']:.2f} | {row['increase_ms']:.2f} "
            f"| {row['onset_10_ms_mean']:.2f} |"
        )
    lines += [
        "",
        "## Closed loop",
        "",
        *[
            f"Headless loop over a {name} link, {cl['simulated_s']:g} s simulated: "
            f"{row['realtime_factor_median']:.0f}x real time (median of "
            f"{len(row['realtime_factors'])})."
            for name, row in cl["links"].items()
        ],
        "",
    ]
    return "\n".join(lines)


def run_master_bench(
    config: MasterBenchConfig,
    out_dir: Path,
    estimator: ForceEstimator,
    progress: Progress = no_progress,
) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(config.seed)
    report: dict[str, Any] = {"data": SIMULATED_NOTE, "config": asdict(config)}
    progress("calibration")
    report["calibration"], fig = calibration(config, rng)
    label_source(fig, SIMULATED_NOTE).savefig(out_dir / "fig10b_calibration.png", dpi=200)
    plt.close(fig)
    progress("frequency response")
    report["frequency_response"], fig, fig11 = frequency_response(config, rng)
    label_source(fig, SIMULATED_NOTE).savefig(out_dir / "fig10c_frequency_response.png", dpi=200)
    label_source(fig11, SIMULATED_NOTE).savefig(out_dir / "fig11_time_responses.png", dpi=200)
    plt.close(fig)
    plt.close(fig11)
    progress("latency")
    report["latency"], fig = latency(config, rng)
    label_source(fig, SIMULATED_NOTE).savefig(out_dir / "latency.png", dpi=200)
    plt.close(fig)
    report["closed_loop"] = closed_loop_speed(config, estimator, progress)
    (out_dir / "master_bench.md").write_text(markdown(report))
    (out_dir / "master_bench.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
