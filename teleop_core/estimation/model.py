"""The force estimator end to end (`estimator.py` re-exports it; the streaming kernels are
in `stream.py`): physics (eq. 1) -> GRU residual (eqs. 3-4) -> EKF.

`ForceEstimator.predict` runs over a whole recording; `ForceEstimator.stream()` gives a
`CausalEstimator` that takes one new sample at a time, as the 50 Hz pipeline does, and
produces the same numbers (a test holds them to 1e-12 N). `training.train_estimator`
fits all three stages to one bench recording; `save`/`load` keep them in a model folder:

| file | what |
|---|---|
| `physics.json` | fitted eq. 1 parameters (SI) |
| `gru.npz` | GRU weights as plain float64 arrays: what inference reads (no PyTorch) |
| `gru.pt` | the same weights as a PyTorch state dict for `GruNet` (for further training;
  read only where a folder older than `gru.npz` has no `gru.npz`) |
| `trees.npz` | in place of the two above, for a model whose residual stage is the
  boosted trees (`trees.py`; `standardisation.json`'s `residual` is `trees`) |
| `standardisation.json` | window, hidden size, input names, means/SDs, target scale,
  the memory features (`memory`, `memory.py`; absent: none), the inputs' training range
  (`input_range`, `ranges.py`) |
| `ekf.json` | EKF noise covariances, and whether it passes the hybrid estimate through |
| `summary.json` | train/validation RMSE of each stage and per regime, epochs, sample
  rate, data digest |
| `calibration.json` | only for a calibrated model: eq. 1 plus the effects of a
  `study calibrate` report, the physics stage in place of eq. 1, or the effects
  training found itself, before the GRU (`stage`, `extended.py`) |
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.ekf import EKF_STATE_SIZE, EkfSettings, filter_forces, settings_vector
from teleop_core.estimation.extended import ExtendedPhysics, physics_force
from teleop_core.estimation.gru import GruModel, GruWeights, Standardisation
from teleop_core.estimation.memory import MemorySpec
from teleop_core.estimation.ranges import InputRange
from teleop_core.estimation.stream import (
    EST_FINAL,
    EST_HYBRID,
    EST_PHYSICS,
    ESTIMATE_OUT,
    N_FEATURES,
    STREAM_STATE_SIZE,
    stream_estimate,
    stream_push,
)
from teleop_core.estimation.trees import TreesModel
from teleop_core.follower.params import FollowerSensorParams
from teleop_core.follower.physics import PhysicsParams
from teleop_core.follower.recording import FollowerRecording

MODEL_FILES = ("physics.json", "standardisation.json", "ekf.json", "summary.json")
"""Besides one of `gru.npz` (read), `gru.pt` (a folder older than `gru.npz`) or
`trees.npz` (a trees residual stage)."""
RESIDUAL_KINDS = ("gru", "trees")
"""The residual stages a model can hold (`ForceEstimator.residual`)."""
RATE_TOLERANCE = 0.02
"""A recording whose rate differs from the model's by more than this is resampled."""


def features_of(recording: FollowerRecording) -> Float2D:
    """Per-sample GRU inputs [I_q, theta_d, theta_dd].

    Parameters
    ----------
    recording : FollowerRecording
        A follower recording of n samples.

    Returns
    -------
    Float2D
        Shape (n, 3): motor current I_q (A), velocity theta_d (rad/s) and
        acceleration theta_dd (rad/s^2).
    """
    return np.column_stack([recording.iq, recording.omega, recording.alpha])


def inputs_of(recording: FollowerRecording, gru: GruModel | TreesModel) -> Float2D:
    """Per-sample inputs of a residual stage: [I_q, theta_d, theta_dd] and its memory
    features.

    Parameters
    ----------
    recording : FollowerRecording
        A follower recording of n samples.
    gru : GruModel or TreesModel
        The residual stage whose memory features (if any) are added.

    Returns
    -------
    Float2D
        Shape (n, 3 + number of memory features), unstandardised.
    """
    return gru.inputs(recording.t, features_of(recording))


@dataclass
class EstimateResult:
    """Estimates for every sample with a full window; arrays of shape (n - T + 1,)."""

    t: Float1D
    """Sample times, s."""
    f_ref: Float1D
    """The reference force of the recording, N."""
    f_physics: Float1D
    """The physics stage's force (eq. 1, or the calibrated physics stage replacing it), N."""
    f_hybrid: Float1D
    """Physics + the residual stage's correction (``F*_GRU``), N."""
    f_final: Float1D
    """The EKF's fused estimate (``F*_Final``), N."""
    in_range: np.ndarray | None = None
    """Whether each sample's inputs lie inside the training range (None: range unknown)."""
    f_effects: Float1D | None = None
    """Eq. 1 with the effects training found, before the GRU (None: none were found)."""

    @property
    def f_model(self) -> Float1D:
        """What the GRU corrects and the EKF fuses: eq. 1, with any effects."""
        return self.f_physics if self.f_effects is None else self.f_effects

    def to_frame(self) -> pd.DataFrame:
        """The estimates as a frame.

        Returns
        -------
        pandas.DataFrame
            Columns t (s), f_ref, f_physics, f_hybrid, f_final (N) and, when known,
            in_range (0/1) and f_effects (eq. 1 with the effects training found, N).
        """
        optional = ("in_range", "f_effects")
        frame = pd.DataFrame({k: v for k, v in asdict(self).items() if k not in optional})
        if self.in_range is not None:
            frame["in_range"] = self.in_range.astype(int)
        if self.f_effects is not None:
            frame["f_effects"] = self.f_effects
        return frame


@dataclass
class ForceEstimator:
    """The follower's force estimator: eq. 1, the GRU's residual and the EKF [endovascular].

    Trained by `study estimator train` (`teleop_core.estimation.training`), kept as a
    folder (`save`, `load`), run over a recording (`predict`) or one sample at a time
    in the control loop (`stream`).

    Attributes
    ----------
    physics : PhysicsParams
        Eq. 1's parameters (torque constant, friction, wheel radius).
    gru : GruModel or TreesModel
        The residual compensator (numba inference; PyTorch only to train it).
    ekf : EkfSettings
        The EKF's noise settings and whether it is used.
    sample_rate_hz : float
        The rate the model was trained at, Hz.
    pipeline_rate_hz : float
        The rate the estimation pipeline runs at in the loop, Hz.
    """

    physics: PhysicsParams
    gru: GruModel | TreesModel
    """The residual stage: the GRU, or the boosted trees (`trees.py`) in its place."""
    ekf: EkfSettings
    sample_rate_hz: float
    pipeline_rate_hz: float = FollowerSensorParams.estimation_rate_hz
    extension: ExtendedPhysics | None = None
    """The calibrated physics stage replacing eq. 1, if any."""
    input_range: InputRange | None = None
    """The inputs' range over the training samples (None for models saved before it)."""

    @property
    def window(self) -> int:
        """The residual stage's window, samples (T): estimates start at the T-th sample."""
        return self.gru.window

    @property
    def residual(self) -> str:
        """Which residual stage the model holds: `gru` or `trees`."""
        return "trees" if isinstance(self.gru, TreesModel) else "gru"

    @property
    def dt_s(self) -> float:
        """The sample period at the model's rate, s."""
        return 1.0 / self.sample_rate_hz

    def conform(self, recording: FollowerRecording) -> FollowerRecording:
        """The recording at the model's sample rate.

        Parameters
        ----------
        recording : FollowerRecording
            A follower recording at any rate.

        Returns
        -------
        FollowerRecording
            `recording` itself when its rate is within `RATE_TOLERANCE` of the model's,
            else a copy resampled to `sample_rate_hz`.
        """
        rate = recording.sample_rate_hz
        if abs(rate / self.sample_rate_hz - 1.0) > RATE_TOLERANCE:
            return recording.resampled(self.sample_rate_hz)
        return recording

    def predict(self, recording: FollowerRecording) -> EstimateResult:
        """Estimate the force over a recording.

        Parameters
        ----------
        recording : FollowerRecording
            A follower recording at the model's rate (`conform` resamples one that
            is not).

        Returns
        -------
        EstimateResult
            For every sample with a full window: the reference, eq. 1's force,
            physics + GRU, the final (EKF) estimate, and whether the inputs were inside
            the training range.

        Raises
        ------
        TeleopInputError
            The recording is shorter than the GRU's window.
        """
        T = self.window
        if len(recording) < T:
            raise TeleopInputError(
                f"recording {recording.name} has {len(recording)} samples; expected at least "
                f"the estimator's window of {T}"
            )
        # what the GRU corrects: eq. 1, or eq. 1 with the effects of a calibration
        f_model = physics_force(self.physics, self.extension, recording)[T - 1 :]
        delta = self.gru.predict(inputs_of(recording, self.gru))
        f_physics, f_effects = f_model, None
        if self.extension is not None and self.extension.stage == "hybrid":
            # effects found in training are part of the correction: F_physics is eq. 1
            f_physics, f_effects = physics_force(self.physics, None, recording)[T - 1 :], f_model
        f_hybrid = f_model + delta  # F*_GRU = F_physics + dF_resistance   (eq. 4)
        f_final = filter_forces(
            self.ekf, self.physics, self.dt_s, f_model, f_hybrid, recording.omega[T - 1 :]
        )
        in_range = None
        if self.input_range is not None:
            in_range = self.input_range.contains(features_of(recording)[T - 1 :])
        return EstimateResult(
            recording.t[T - 1 :],
            recording.f_ref[T - 1 :],
            f_physics,
            f_hybrid,
            f_final,
            in_range,
            f_effects,
        )

    def stream(self) -> CausalEstimator:
        """The estimator fed one sample at a time, as the control loop runs it.

        Returns
        -------
        CausalEstimator
            A fresh streaming estimator with empty state.

        Raises
        ------
        TeleopInputError
            The model cannot stream (see `check_streams`).
        """
        self.check_streams()
        return CausalEstimator(self)

    def check_streams(self) -> None:
        """Check that the model can run one sample at a time, as the loop does.

        A model whose physics stage or correction holds calibrated effects cannot, nor
        one whose residual stage is the trees (the loop's kernel runs the GRU).

        Raises
        ------
        TeleopInputError
            The model cannot stream; one line saying why and how to train one that can.
        """
        if isinstance(self.gru, TreesModel):
            raise TeleopInputError(
                "this estimator's residual stage is the boosted trees, which run with "
                "predict(), not one sample at a time; for the loop, train with "
                "`--residual gru`"
            )
        if self.extension is not None:
            effects = ", ".join(self.extension.families)
            raise TeleopInputError(
                f"this estimator is calibrated ({effects}): eq. 1 with effects that need the "
                "whole recording, so it runs with predict(), not one sample at a time; for "
                "the loop, train with `--effects none`"
            )

    def save(self, folder: Path, summary: dict[str, Any]) -> None:
        """Write the model folder, all or nothing (through a temporary sibling folder).

        Parameters
        ----------
        folder : Path
            The model folder to write; one already there is replaced.
        summary : dict of str to Any
            What training reports, written as `summary.json`.

        Raises
        ------
        TeleopInputError
            The folder's parent does not exist.
        """
        folder = Path(folder)
        if not folder.parent.is_dir():
            raise TeleopInputError(f"folder {folder.parent} for the model does not exist")
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
        try:
            _write_json(tmp / "physics.json", self.physics.to_dict())
            if isinstance(self.gru, TreesModel):
                self.gru.save_npz(tmp / "trees.npz")
                stage: dict[str, Any] = {"residual": "trees"}
            else:
                self.gru.weights.save_npz(tmp / "gru.npz")
                try:  # gru.pt, for training on from these weights, where PyTorch is installed
                    from teleop_core.estimation.gru_torch import save_torch_weights
                except TeleopInputError:
                    pass
                else:
                    save_torch_weights(self.gru.weights, tmp / "gru.pt")
                stage = {"hidden_size": int(self.gru.weights.w_hh.shape[1])}
            _write_json(
                tmp / "standardisation.json",
                {
                    "window": self.window,
                    **stage,
                    "target": self.gru.target,
                    "sample_rate_hz": self.sample_rate_hz,
                    "pipeline_rate_hz": self.pipeline_rate_hz,
                    "features": list(self.gru.memory.feature_names),
                    "memory": self.gru.memory.to_dict(),
                    **self.gru.standardisation.to_dict(),
                    **(
                        {"input_range": self.input_range.to_dict()}
                        if self.input_range is not None
                        else {}
                    ),
                },
            )
            _write_json(tmp / "ekf.json", self.ekf.to_dict())
            _write_json(tmp / "summary.json", summary)
            if self.extension is not None:
                _write_json(tmp / "calibration.json", self.extension.to_dict())
            if folder.exists():
                shutil.rmtree(folder)
            tmp.rename(folder)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

    @classmethod
    def load(cls, folder: Path) -> ForceEstimator:
        """Read a model folder written by `save` (`study estimator train --out`).

        Parameters
        ----------
        folder : Path
            The model folder.

        Returns
        -------
        ForceEstimator
            The model.

        Raises
        ------
        TeleopInputError
            The folder does not exist, lacks one of `MODEL_FILES`, or holds a file that
            cannot be read; one line naming it.
        """
        folder = Path(folder)
        if not folder.is_dir():
            raise TeleopInputError(
                f"model folder {folder} does not exist; "
                "expected the --out of `study estimator train`"
            )
        missing = [f for f in MODEL_FILES if not (folder / f).is_file()]
        if not any((folder / f).is_file() for f in ("gru.npz", "gru.pt", "trees.npz")):
            missing.append("gru.npz")
        if missing:
            raise TeleopInputError(
                f"model folder {folder} has no {missing[0]}; expected a folder written by "
                "`study estimator train`"
            )
        try:
            physics = PhysicsParams(**_read_json(folder / "physics.json"))
            meta = _read_json(folder / "standardisation.json")
            std = Standardisation(
                tuple(meta["feature_mean"]),
                tuple(meta["feature_std"]),
                float(meta["target_mean"]),
                float(meta["target_std"]),
            )
            # A folder saved before memory features has no `memory`: the plain window.
            memory = MemorySpec.from_dict(meta.get("memory"))
            names = list(meta.get("features", memory.feature_names))
            kind = meta.get("residual", "gru")
            if kind not in RESIDUAL_KINDS:
                raise TeleopInputError(
                    f"model folder {folder}: residual stage {kind!r}; expected one of "
                    + ", ".join(RESIDUAL_KINDS)
                )
            if kind == "trees":
                if not (folder / "trees.npz").is_file():
                    raise TeleopInputError(
                        f"model folder {folder} has no trees.npz; expected a folder written "
                        "by `study estimator train --residual trees`"
                    )
                n_inputs = len(memory.feature_names)
            else:
                weights = _load_gru_weights(folder)
                n_inputs = weights.n_inputs
            if (
                names != list(memory.feature_names)
                or n_inputs != len(names)
                or len(std.feature_mean) != len(names)
            ):
                raise TeleopInputError(
                    f"model folder {folder}: its network takes {n_inputs} inputs per "
                    f"step, its standardisation {len(std.feature_mean)} ({', '.join(names)}), "
                    f"its memory features ({memory.to_dict()['kind']}) give "
                    f"{len(memory.feature_names)}; expected them to agree, as "
                    "`study estimator train` writes them"
                )
            gru: GruModel | TreesModel
            if kind == "trees":
                trees = TreesModel.load_trees(folder / "trees.npz")
                gru = TreesModel(trees, std, int(meta["window"]), meta["target"], memory)
            else:
                gru = GruModel(weights, std, int(meta["window"]), meta["target"], memory)
            ekf = EkfSettings(**_read_json(folder / "ekf.json"))
            extension = None
            if (folder / "calibration.json").is_file():
                extension = ExtendedPhysics.from_dict(_read_json(folder / "calibration.json"))
            input_range = None
            if "input_range" in meta:
                input_range = InputRange.from_dict(meta["input_range"])
            return cls(
                physics,
                gru,
                ekf,
                float(meta["sample_rate_hz"]),
                float(meta["pipeline_rate_hz"]),
                extension,
                input_range,
            )
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            if isinstance(exc, TeleopInputError):
                raise
            raise TeleopInputError(f"model folder {folder} is damaged: {exc}") from None


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise TeleopInputError(f"{path} is not valid JSON: {exc}") from None


class CausalEstimator:
    """The estimator fed one sample at a time; `update` returns None until a window is full.

    Its state lives in arrays and its steps are numba functions (`stream_push`,
    `stream_estimate`), so that the closed loop's compiled kernel can run the same
    estimator between its events; `kernel_arrays()` hands them over.

    Parameters
    ----------
    estimator : ForceEstimator
        A model that can stream (`ForceEstimator.check_streams`).

    Raises
    ------
    TeleopInputError
        The model cannot stream.
    """

    def __init__(self, estimator: ForceEstimator) -> None:
        self.est = estimator
        if not isinstance(estimator.gru, GruModel):
            estimator.check_streams()  # raises: a trees model does not stream
        assert isinstance(estimator.gru, GruModel)
        std = estimator.gru.standardisation
        w = estimator.gru.weights
        self.mem = estimator.gru.memory.kernel_table()
        self.buffer = np.zeros((estimator.window, N_FEATURES + len(self.mem)))
        self.state = np.zeros(STREAM_STATE_SIZE + len(self.mem))
        self.ekf_state = np.zeros(EKF_STATE_SIZE)
        self.mean = np.asarray(std.feature_mean, dtype=np.float64)
        self.std = np.asarray(std.feature_std, dtype=np.float64)
        self.physics = estimator.physics.vector()
        self.ekf_settings = settings_vector(estimator.ekf)
        self.weights = w.kernel_weights()
        self.target = np.array([std.target_std, std.target_mean], dtype=np.float64)
        self.dt_s = estimator.dt_s
        self._out = np.zeros(ESTIMATE_OUT)

    def kernel_arrays(self) -> tuple:
        """The estimator's state and settings for the loop's compiled kernel.

        Returns
        -------
        tuple
            The arrays in the order the loop's kernel unpacks them
            (`stream.NO_STREAM_ARRAYS` has dummies of the same types); the kernel
            updates the state arrays in place.
        """
        return (
            self.buffer,
            self.state,
            self.mean,
            self.std,
            self.mem,
            self.physics,
            *self.weights,
            self.target,
            self.ekf_state,
            self.ekf_settings,
        )

    def push(self, t: float, iq: float, omega: float, alpha: float | None = None) -> None:
        """Add a sample to the window without estimating.

        The 50 Hz pipeline sees every 100 Hz sample but estimates on every other one.

        Parameters
        ----------
        t : float
            The sample's time, s.
        iq : float
            Motor current I_q, A.
        omega : float
            Velocity theta_d, rad/s.
        alpha : float or None, optional
            Acceleration theta_dd, rad/s^2; None: the backward difference of `omega`
            (0 for the first sample), as `FollowerRecording` derives it.
        """
        given = alpha is not None
        stream_push(
            self.state,
            self.buffer,
            self.mean,
            self.std,
            self.mem,
            t,
            iq,
            omega,
            alpha if given else 0.0,
            given,
        )

    def estimate(self) -> tuple[float, float, float] | None:
        """Estimate the force from the samples pushed so far.

        Returns
        -------
        tuple of (float, float, float) or None
            ``(F_physics, F*_GRU, F*_Final)``, N; None while the window fills.
        """
        ok = stream_estimate(
            self.state,
            self.buffer,
            self.physics,
            *self.weights,
            self.target,
            self.ekf_state,
            self.ekf_settings,
            self.dt_s,
            self._out,
        )
        if not ok:
            return None
        out = self._out
        return float(out[EST_PHYSICS]), float(out[EST_HYBRID]), float(out[EST_FINAL])

    def update(
        self, t: float, iq: float, omega: float, alpha: float | None = None
    ) -> tuple[float, float, float] | None:
        """Add a sample and estimate.

        Parameters
        ----------
        t : float
            The sample's time, s.
        iq : float
            Motor current I_q, A.
        omega : float
            Velocity theta_d, rad/s.
        alpha : float or None, optional
            Acceleration theta_dd, rad/s^2; None: derived as in `push`.

        Returns
        -------
        tuple of (float, float, float) or None
            ``(F_physics, F*_GRU, F*_Final)``, N; None while the window fills.
        """
        self.push(t, iq, omega, alpha)
        return self.estimate()


def _load_gru_weights(folder: Path) -> GruWeights:
    """`gru.npz` without PyTorch; a folder written before it existed has only `gru.pt`."""
    if (folder / "gru.npz").is_file():
        return GruWeights.load_npz(folder / "gru.npz")
    # lazy: teleop_core.estimation.gru_torch (with torch) costs 1.2 s at start-up
    from teleop_core.estimation.gru_torch import load_torch_weights

    return load_torch_weights(folder / "gru.pt")
