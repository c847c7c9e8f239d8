"""The calibration loop: fit, test the held-out residual, add the effect that helps most.

    1. fit the base model on the training block (the first part of the recording);
    2. compute the residual on the held-out block (the end of the recording: a
       chronological split, never a random one, so that slow effects and correlated
       noise cannot leak from training into the test);
    3. for every candidate family not yet in the model, search its nonlinear
       parameter on the training block, refit base + effects + candidate, and measure
       the held-out RMSE;
    4. add the best candidate if its gain is significant: held-out RMSE lower by at
       least `min_gain`, the one-sided Diebold-Mariano test (HAC variance) below
       `alpha`, and a lower BIC on training. The three guard each other: on long
       recordings tiny gains are significant (the minimum gain stops them), on short
       ones a gain made in a few bursts is not (the test stops it), and the BIC charges
       for the parameters. `alpha` is per candidate, not divided among them: an effect
       must pass all three, and on clean recordings the minimum gain is what rejects;
    5. search the searched value of every effect added before again, the others in
       the model (`_backfit`: each was searched against a residual that still held
       the effects found after it);
    6. repeat until no candidate passes or `max_effects` are in.

A winner that another passing family explains as well on the held-out block (the
winner's errors not significantly smaller, `_look_alikes`) is kept in the model, since
it predicts as well either way, but the report lists it under `ambiguous_effects` with
its alternatives instead of naming it. A `delay` that wins is also checked against
what the library has no family for, a first-order lag of the whole force
(`_lag_alike`, `first_order_lag`): a pure delay and a lag of a few tens of ms shift
the force alike at the speeds a recording holds, and the recording names the delay
only where the lag, both with the regressors' noise filtered without a shift, predicts
the held-out block significantly worse or fits the training block decisively worse.

A winner that a second term
of a family already in the model replaces as well (`_refinement_alike`) is reported
ambiguous with that family: it may be no effect of its own but a correction of the
first one's shape.

The residual tests (`residual.py`) are reported before and after; they describe the
residual, while the decision rests on held-out prediction, which they cannot game.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import Any

import numpy as np
from scipy import signal
from statsmodels.stats.stattools import durbin_watson

from teleop_core._typing import Float1D, Float2D, Rows
from teleop_core.blas import one_blas_thread
from teleop_core.calibration.candidates import (
    OPEN,
    REPEATABLE,
    UNLOCATED_AT,
    Candidate,
    ChainFit,
    Found,
    _best,
    _candidate_dict,
    _remaining,
    _search_edge,
    _verdict,
)
from teleop_core.calibration.effects import EFFECTS, MAX_LAG_S, Effect
from teleop_core.calibration.fitting import (
    CalibratedModel,
    Chain,
    best_training_fit,
    confidence,
    design,
    search,
    solve,
    train_sse,
)
from teleop_core.calibration.library import OPEN_TERMS, OpenTerm, term_report
from teleop_core.calibration.models import BaseModel, CalibrationData
from teleop_core.calibration.plausibility import effect_coefficients, implausible
from teleop_core.calibration.residual import diebold_mariano, residual_tests
from teleop_core.calibration.tell_apart import tell_apart
from teleop_core.calibration.validation import Validation, validate
from teleop_core.calibration.verdict import fit_percent, unexplained, verdict
from teleop_core.errors import TeleopInputError
from teleop_core.progress import Progress, no_progress

LAG_ALTERNATIVE = "first_order_lag"
"""The name a first-order lag of the whole force takes among a delay's alternatives."""
SATURATION_ALTERNATIVE = "force_saturation"
"""The name a saturation of the whole force (a slip, a force limit) takes among a
current nonlinearity's alternatives."""
SATURATION_QUANTILES = np.linspace(0.2, 0.99, 20)
"""Saturation levels tried, as quantiles of the model's |force| on the training block."""
LAG_GRID = 24
"""Time constants tried for that lag, log-spaced from one sample period to 0.2 s."""
ZERO_PHASE_CUTOFFS = (0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.25)
"""Cutoffs of the zero-phase noise filter in the delay-or-lag comparison, as fractions
of the sampling rate (up to half the Nyquist frequency)."""
BIC_DECISIVE = 10.0
"""Training-BIC difference that decides between two candidates (Kass and Raftery
1995: above 10 is "very strong" evidence): a look-alike further behind is no
alternative, whatever the held-out block says."""


@dataclass(frozen=True)
class _Round:
    """One round of the forward selection: the chain so far and how it does."""

    number: int
    chain: Chain
    pred: Float1D
    rmse: float
    bic: float


@dataclass
class Calibrator:
    """Greedy forward selection of effects on a base model, judged on a held-out block.

    Parameters
    ----------
    model : BaseModel
        Base model (`models.py`).
    families : Sequence of str or None, optional
        Candidate families to try; default: all that apply to the model's signals.
    held_out_fraction : float, optional
        Share of the recording, at its end, held out for testing.
    alpha : float, optional
        Level of each candidate's Diebold-Mariano test.
    min_gain : float, optional
        Smallest relative cut in held-out RMSE worth an effect (default 5 %): above
        the cut that the imperfect fit of an effect already in the model can leave for
        a wrong family to take on simulated recordings.
    max_effects : int, optional
        Most effects added.
    max_lag : int, optional
        Lags, samples, of the residual tests.

    Raises
    ------
    TeleopInputError
        `held_out_fraction` lies outside 0.05 to 0.5, or `families` names an unknown
        effect family.
    """

    model: BaseModel
    families: Sequence[str] | None = None
    held_out_fraction: float = 0.25
    alpha: float = 0.01
    min_gain: float = 0.05
    max_effects: int = 4
    max_lag: int = 25
    candidates_: list[Candidate] = field(default_factory=list, init=False)
    """Every candidate of every round, in order (`fit`)."""
    # what `fit` sets (scikit-learn's manner: the names end in `_`, absent before it)
    train_: Rows = field(init=False, repr=False)
    """The training rows."""
    test_: Rows = field(init=False, repr=False)
    """The held-out rows."""
    base_: BaseModel = field(init=False, repr=False)
    """The base model with its own assumptions fitted on the training rows."""
    base_prediction_: Float1D = field(init=False, repr=False)
    """The base model's prediction over every sample."""
    base_model_: CalibratedModel = field(init=False, repr=False)
    """The base model alone, fitted on the training rows."""
    rmse_before_: float = field(init=False, repr=False)
    """Held-out RMSE of the base model alone."""
    step_rmse_: list[float] = field(init=False, repr=False)
    """Held-out RMSE after each round."""
    ambiguous_: list[list[str]] = field(init=False, repr=False)
    """Per round, the families the recording does not tell apart from its winner."""
    rmse_after_: float = field(init=False, repr=False)
    """Held-out RMSE of the calibrated model."""
    model_: CalibratedModel = field(init=False, repr=False)
    """The calibrated model: the base and the effects added."""
    prediction_: Float1D = field(init=False, repr=False)
    """The calibrated model's prediction over every sample."""
    chain_: Chain = field(init=False, repr=False)
    """The effects added, with their searched values."""
    tests_before_: dict[str, Any] = field(init=False, repr=False)
    """The residual tests of the base model on the held-out block."""
    tests_after_: dict[str, Any] = field(init=False, repr=False)
    """The residual tests of the calibrated model on the held-out block."""
    unexplained_: dict[str, Any] = field(init=False, repr=False)
    """Where the calibrated model's held-out error is left (`verdict.unexplained`)."""
    verdict_: str = field(init=False, repr=False)
    """The verdict on the held-out error (`verdict.verdict`)."""
    fit_percent_: tuple[float, float] = field(init=False, repr=False)
    """Held-out fit percentages of the base and of the calibrated model."""
    base_params_: dict[str, float] = field(init=False, repr=False)
    """The base model's physical parameters (`fitting.confidence`)."""
    base_ci_: dict[str, list[float] | None] = field(init=False, repr=False)
    """Their 95 % intervals (None where the fit does not determine one)."""
    effect_params_: list[dict[str, Any]] = field(init=False, repr=False)
    """Each effect's parameters and intervals, in chain order."""
    data_: CalibrationData = field(init=False, repr=False)
    """The recording fitted."""
    validation_: list[Validation] = field(init=False, repr=False)
    """One `Validation` per recording given to `fit` as `validation`."""

    def __post_init__(self) -> None:
        if not 0.05 <= self.held_out_fraction <= 0.5:
            raise TeleopInputError(
                f"held_out_fraction = {self.held_out_fraction!r}; expected 0.05 to 0.5"
            )
        unknown = [f for f in self.families or () if f not in EFFECTS]
        if unknown:
            raise TeleopInputError(
                f"unknown effect family {unknown[0]!r}; expected one of {', '.join(EFFECTS)}"
            )

    def _split(self, n: int, blocks: int) -> tuple[Rows, Rows]:
        """Training and held-out rows: the end of the recording, or with `blocks` > 1 the
        end of each of `blocks` equal segments (blocked hold-out, still chronological
        within each block: no sample is held out apart from its neighbours)."""
        if blocks == 1:
            cut = round(n * (1.0 - self.held_out_fraction))
            return slice(0, cut), slice(cut, n)
        edges = np.linspace(0, n, blocks + 1).round().astype(int)
        held = np.zeros(n, dtype=bool)
        for start, stop in itertools.pairwise(edges):
            held[stop - round((stop - start) * self.held_out_fraction) : stop] = True
        return np.flatnonzero(~held), np.flatnonzero(held)

    def _fit_chain(self, data: CalibrationData, chain: Chain) -> ChainFit:
        """Coefficients on the training block, predictions everywhere, parameter count."""
        X, _ = design(self.base_, data.signals, chain)
        coef = solve(X[self.train_], data.y[self.train_])
        searched = sum(e.searched is not None for e, _ in chain)
        return ChainFit(coef, X @ coef, X.shape[1] + searched)

    def _bic(self, data: CalibrationData, fit: ChainFit) -> float:
        e = data.y[self.train_] - fit.pred[self.train_]
        n = len(e)
        return float(n * np.log(np.mean(e * e)) + fit.n_params * np.log(n))

    def _reason(self, cand: Candidate, effect: Effect, coef: Float1D, data: CalibrationData) -> str:
        """Why a candidate is refused ("" when it passes): the held-out rules, then
        plausibility, then an unlocated search."""
        reason = _verdict(cand, self.min_gain, self.alpha)
        if not reason:
            own = effect_coefficients(coef, effect, data.signals, cand.searched_value)
            reason = (
                implausible(
                    effect,
                    own,
                    cand.searched_value,
                    self.base_.out,
                    self.base_.unit,
                    data.signals,
                    self.base_.passive_loop_sign,
                )
                or ""
            )
        edge = _search_edge(effect, cand.searched_value, data.signals)
        if not reason and edge and UNLOCATED_AT.get(cand.family) == edge[0]:
            reason = f"not located: {edge[1]}"
        return reason

    def _look_alikes(self, best: Found, passing: list[Found], y_test: Float1D) -> list[str]:
        """The other passing candidates of the round that neither block tells apart
        from its winner: on the held-out block the winner's errors are not
        significantly smaller than theirs (one-sided Diebold-Mariano at `alpha`), and
        on the training block their BIC is within `BIC_DECISIVE` of the winner's.
        An open term that is no look-alike of the winner's family (`OpenTerm.look_alike`:
        the gain step is one of a drift's only) is no alternative. Empty when the
        winner is identified. Look-alikes this catches: a drift and a gain step early
        in the recording, a direction asymmetry and a velocity nonlinearity on a recording
        with few speeds in one direction, pre-sliding memory and a direction
        asymmetry or a Stribeck dip on one with few reversals."""
        out = []
        winner = best.candidate
        e_best = y_test - best.fit.pred[self.test_]
        for other in passing:
            cand = other.candidate
            if cand is winner or cand.bic_change - winner.bic_change > BIC_DECISIVE:
                continue
            alike_of = getattr(other.effect, "look_alike", True)
            if alike_of is False or (alike_of is not True and best.effect.family not in alike_of):
                continue
            if diebold_mariano(y_test - other.fit.pred[self.test_], e_best) >= self.alpha:
                out.append(cand.family)
        return out

    def _alternatives(
        self, data: CalibrationData, chain: Chain, pred: Float1D, best: Found, passing: list[Found]
    ) -> list[str]:
        """What the recording does not tell apart from the round's winner `best`: the
        passing look-alikes, and for a `delay` a first-order lag, for a
        `current_nonlinearity` a saturation of the whole force (`pred`: the model's
        force before the round)."""
        y_test = data.y[self.test_]
        alike = self._look_alikes(best, passing, y_test)
        winner = (best.effect, best.candidate.searched_value)
        if best.effect.family == "delay":
            alike += self._lag_alike(data, chain, [*chain, winner])
        elif any(LAG_ALTERNATIVE in a for a in self.ambiguous_):
            # a delay that a lag explains as well is in the model: a later winner may be
            # no effect of its own but what the delay leaves of the lag
            undelayed = [(e, v) for e, v in chain if e.family != "delay"]
            extra = best.fit.n_params - self._fit_chain(data, chain).n_params
            alike += self._lag_alike(data, undelayed, [*chain, winner], extra)
        if best.effect.family == "current_nonlinearity":
            alike += self._saturation_alike(data, chain, pred, data.y - best.fit.pred)
        return alike + self._refinement_alike(data, chain, best)

    def _refinement_alike(self, data: CalibrationData, chain: Chain, best: Found) -> list[str]:
        """The families already in `chain` whose second term (the same family at another
        searched value, on top of the chain) predicts the held-out block about as well
        as the round's winner `best`: its held-out RMSE within `min_gain` of the
        winner's (or below), the winner's errors not significantly smaller (one-sided
        Diebold-Mariano at `alpha`), and its training BIC not `BIC_DECISIVE` behind.

        A large effect that the model holds only as well as the recorded channels allow
        (a wide Stribeck dip on a noisy speed, whose mean shape is not the dip's) leaves
        a residual shaped like it, which a look-alike family then takes: a viscous
        nonlinearity after a Stribeck dip. Where the first family's own second term does
        as well, the recording does not say that the winner is another effect rather
        than a correction of the first, and the winner is reported ambiguous with it."""
        out: list[str] = []
        y_test = data.y[self.test_]
        e_best = y_test - best.fit.pred[self.test_]
        rmse_best = _rmse(e_best)
        bic_best = self._bic(data, best.fit)
        for effect, _ in chain:
            if effect.searched is None or effect.family in REPEATABLE or effect.family in out:
                continue
            if type(effect).transform is not Effect.transform:
                continue
            value = search(self.base_, data, self.train_, chain, effect)
            refined = self._fit_chain(data, [*chain, (effect, value)])
            e = y_test - refined.pred[self.test_]
            if _rmse(e) * (1.0 - self.min_gain) > rmse_best:
                continue
            if self._bic(data, refined) - bic_best > BIC_DECISIVE:
                continue
            if diebold_mariano(e, e_best) >= self.alpha:
                out.append(effect.family)
        return out

    def _lag_alike(
        self, data: CalibrationData, chain: Chain, delayed: Chain, extra: int = 0
    ) -> list[str]:
        """[`first_order_lag`] when a first-order lag of the whole force after base +
        `chain`, in place of the `delay` in `delayed` (`chain` with the delay that won,
        or the chain with its delay and a later winner), predicts the held-out block
        about as well.

        The lag acts on the model's force as on the recording's: every column of the
        design of base + `chain` (the effects without the delay) through
        y_k = a y_{k-1} + (1 - a) x_k, a = exp(-dt / tau), tau searched on the training
        block. Filtering the columns also filters the current's noise, which alone cuts
        the error of any recording, so both are judged with the same kind of noise
        filter after them: a zero-phase low-pass (`_zero_phase`), which cuts the
        regressors' noise without shifting them. A causal filter there would add a lag
        of its own to the delay, and a lag of a few tens of ms then beat a 15 ms delay
        by filtering the noise. The lag is an alternative when its held-out RMSE is
        within `min_gain` of the delay's (or below), the delay's errors are not
        significantly smaller (one-sided Diebold-Mariano at `alpha`), and its training
        BIC is not `BIC_DECISIVE` behind the delay's (`extra`: the parameters `delayed`
        holds beyond the delay, charged to it).

        With a later winner in `delayed` the question is whether that winner is an
        effect of its own or what the delay leaves of a lag: a 55 ms lag held by a
        delay left, after each reversal, a shape a wide backlash took."""
        sse_lag, lag = self._filtered_errors(data, chain, lagged=True)
        sse_delay, e_delay = self._filtered_errors(data, delayed, lagged=False)
        # a delay has one searched value and the filter's cutoff, as the lag has
        n = len(data.y[self.train_])
        behind = n * np.log(sse_lag / sse_delay) - extra * np.log(n) > BIC_DECISIVE
        near = _rmse(lag) * (1.0 - self.min_gain) <= _rmse(e_delay)
        alike = near and diebold_mariano(lag, e_delay) >= self.alpha and not behind
        return [LAG_ALTERNATIVE] if alike else []

    def _saturation_alike(
        self, data: CalibrationData, chain: Chain, pred: Float1D, e_best: Float1D
    ) -> list[str]:
        """[`force_saturation`] when a saturation of the whole force, in place of the
        `current_nonlinearity` that won (`e_best`: its errors), is not worse on both
        blocks.

        A current nonlinearity bends the force of the current alone; a slip or a force
        limit clips the whole force (friction and inertia with it). Where the current's
        force is most of the force the two bend alike. The saturation is the column
        -sgn(f) max(|f| - L, 0) of the model's force f before the round (base +
        `chain`), L searched over quantiles of |f| on the training block, fitted with
        base + `chain`. It is an alternative when its held-out RMSE is within
        `min_gain` of the winner's (or below) and the winner's errors are not
        significantly smaller (one-sided Diebold-Mariano at `alpha`), or when it fits
        the training block decisively better (BIC lower by `BIC_DECISIVE`; both have
        one coefficient and one searched value): the blocks then disagree, and the
        recording names neither."""
        X, _ = design(self.base_, data.signals, chain)
        y = data.y
        size = np.abs(pred)
        sse_sat, fit_sat = best_training_fit(
            (
                np.column_stack([X, -np.sign(pred) * np.maximum(size - level, 0.0)])
                for level in np.quantile(size[self.train_], SATURATION_QUANTILES)
            ),
            y,
            self.train_,
        )
        e_sat = y[self.test_] - fit_sat[self.test_]
        e_win = e_best[self.test_]
        near = _rmse(e_sat) * (1.0 - self.min_gain) <= _rmse(e_win)
        tied = near and diebold_mariano(e_sat, e_win) >= self.alpha
        train = e_best[self.train_]
        better = len(train) * np.log(sse_sat / float(train @ train)) < -BIC_DECISIVE
        return [SATURATION_ALTERNATIVE] if tied or better else []

    def _filtered_errors(
        self, data: CalibrationData, chain: Chain, lagged: bool
    ) -> tuple[float, Float1D]:
        """Training SSE and held-out errors of base + `chain` with every column through
        the zero-phase low-pass of `ZERO_PHASE_CUTOFFS` (and, `lagged`, the first-order
        lag of `LAG_GRID`) that fits the training block best."""
        X, _ = design(self.base_, data.signals, chain)
        dt = float(np.median(np.diff(data.signals["t"])))
        smoothed = [_zero_phase(X, f) for f in ZERO_PHASE_CUTOFFS]
        taus = np.geomspace(dt, 2 * MAX_LAG_S, LAG_GRID) if lagged else np.empty(0)
        poles = [float(np.exp(-dt / tau)) for tau in taus]
        designs = (
            (signal.lfilter([1.0 - a], [1.0, -a], Z, axis=0, zi=a * Z[:1])[0] for a in poles)
            if lagged
            else iter([Z])
            for Z in smoothed
        )
        sse, fit = best_training_fit(itertools.chain.from_iterable(designs), data.y, self.train_)
        return sse, data.y[self.test_] - fit[self.test_]

    @one_blas_thread
    def fit(
        self,
        data: CalibrationData,
        progress: Progress = no_progress,
        validation: Sequence[tuple[str, CalibrationData]] = (),
    ) -> Calibrator:
        """Run the loop on `data`; fitted attributes end in `_`.

        Parameters
        ----------
        data : CalibrationData
            The recording as the base model reads it (`BaseModel.read` or `.data`).
        progress : Progress, optional
            Told each candidate of each round (``"round 2: stribeck"``, k of n) and
            each round's end.
        validation : sequence of (str, CalibrationData), optional
            Other recordings of the same machine, each with its name in the report,
            read as `data` was (`BaseModel.reader_for`): the fitted model predicts each
            in full (`validate`; `validation_`, the report's `validation`).

        Returns
        -------
        Calibrator
            Itself, fitted: `model_` (the calibrated model), `base_model_` (the base
            model alone, fitted on the training block), `chain_` (the effects added),
            `candidates_`, `rmse_before_` / `rmse_after_` on the held-out block, the
            residual tests, the verdict and `validation_` (one `Validation` per
            recording of `validation`).

        Raises
        ------
        TeleopInputError
            The recording has fewer than 200 samples.
        """
        if len(data) < 200:
            raise TeleopInputError(
                f"recording {data.name} has {len(data)} samples; expected at least 200 "
                "for a training and a held-out block"
            )
        families = list(self.families or self.model.families)
        families = [f for f in families if all(k in data.signals for k in EFFECTS[f].needs)]
        open_terms = (
            []
            if self.families
            else [f for f, e in OPEN_TERMS.items() if all(k in data.signals for k in e.needs)]
        )
        self.train_, self.test_ = self._split(len(data), data.held_out_blocks)
        # the base model's own assumptions (eq. 1's sign width) fitted on training only
        self.base_ = self.model.fitted_to(data, self.train_)
        y_test = data.y[self.test_]
        chain: Chain = []
        fit = self._fit_chain(data, chain)
        self.base_prediction_ = fit.pred
        self.base_model_ = CalibratedModel(self.base_, [], fit.coef, _settings(self.base_))
        rmse = _rmse(y_test - fit.pred[self.test_])
        self.rmse_before_ = rmse
        self.step_rmse_ = []
        self.candidates_ = []
        self.ambiguous_ = []
        round_ = 0
        while len(chain) < self.max_effects:
            remaining = _remaining(families, chain, marker=bool(open_terms))
            if not remaining:
                break
            step = _Round(round_ + 1, chain, fit.pred, rmse, self._bic(data, fit))
            found = self._candidates(data, step, remaining, open_terms, progress)
            passing = [f for f in found if not f.candidate.reason]
            self.candidates_.extend(f.candidate for f in found)
            progress(f"round {round_ + 1} done", len(remaining), len(remaining))
            if not passing:
                break
            best = _best(passing, self.min_gain)
            best.candidate.accepted = True
            self.ambiguous_.append(self._alternatives(data, chain, fit.pred, best, passing))
            for other in passing:
                if other is not best:
                    other.candidate.reason = (
                        f"passed, but {best.candidate.family} cut the error more"
                    )
            chain.append((best.effect, best.candidate.searched_value))
            fit = best.fit
            rmse = best.candidate.rmse_held_out_n
            backfitted = self._backfit(data, chain)
            if backfitted != chain:
                chain[:] = backfitted
                fit = self._fit_chain(data, chain)
                rmse = _rmse(y_test - fit.pred[self.test_])
            refitted = self.model.fitted_to(data, self.train_, chain)
            if refitted != self.base_:
                # the base model's own assumptions again, now that the effect no longer
                # fills the training error: what they got wrong before would otherwise
                # be left for a wrong family to take in the next round
                self.base_ = refitted
                fit = self._fit_chain(data, chain)
                rmse = _rmse(y_test - fit.pred[self.test_])
            self.step_rmse_.append(rmse)
            round_ += 1
        self.rmse_after_ = rmse
        self.model_ = CalibratedModel(self.base_, chain, fit.coef, _settings(self.base_))
        self.prediction_ = fit.pred
        self.chain_ = chain
        self._diagnose(data, fit.pred)
        self.validation_ = self._validations(validation)
        return self

    def _validations(self, recordings: Sequence[tuple[str, CalibrationData]]) -> list[Validation]:
        """`validate` on each (name, recording) of `recordings`."""
        return [self.validate(data, name) for name, data in recordings]

    def validate(self, data: CalibrationData, recording: str) -> Validation:
        """The fitted base and calibrated models over every sample of another recording
        (`validation.validate`); `data` read as the training recording was
        (`BaseModel.reader_for`)."""
        return validate(self.base_model_, self.model_, data, recording)

    def _backfit(self, data: CalibrationData, chain: Chain) -> Chain:
        """`chain` with each earlier effect's searched value searched again on the
        training block, every other effect of the chain in the model (one pass, in the
        order added; a value is replaced only where the training fit improves).

        An effect's value is searched in the round it enters, against a residual that
        still holds the effects found after it: a hysteresis loop searched beside an
        unmodelled gain step widens to take part of the step, a Stribeck speed beside
        a missing ripple shifts. Left frozen, the biased value leaves structure for a
        wrong family to take and keeps the right one from passing."""
        current = list(chain)
        sse = train_sse(self.base_, data, self.train_, current)
        for i, (effect, _) in enumerate(chain[:-1]):
            if effect.searched is None:
                continue
            others = [*current[:i], *current[i + 1 :]]
            value = search(self.base_, data, self.train_, others, effect)
            trial = [*current[:i], (effect, value), *current[i + 1 :]]
            trial_sse = train_sse(self.base_, data, self.train_, trial)
            if trial_sse < sse:
                current, sse = trial, trial_sse
        return current

    def _candidates(
        self,
        data: CalibrationData,
        step: _Round,
        remaining: list[str],
        open_terms: list[str],
        progress: Progress,
    ) -> list[Found]:
        """Each remaining family (the open terms in place of their marker) searched,
        fitted after `step.chain` and judged on the held-out block."""
        y_test = data.y[self.test_]
        found: list[Found] = []
        for i, family in enumerate(remaining):
            if family == OPEN:
                remaining.extend(_remaining(open_terms, step.chain, marker=False))
                continue
            progress(f"round {step.number}: {family}", i, len(remaining))
            effect = self.base_.effect(family)
            value = search(self.base_, data, self.train_, step.chain, effect)
            c_fit = self._fit_chain(data, [*step.chain, (effect, value)])
            c_rmse = _rmse(y_test - c_fit.pred[self.test_])
            p = diebold_mariano(y_test - step.pred[self.test_], y_test - c_fit.pred[self.test_])
            cand = Candidate(
                family,
                step.number,
                value,
                c_rmse,
                1.0 - c_rmse / step.rmse,
                p,
                self._bic(data, c_fit) - step.bic,
            )
            found.append(Found(cand, effect, c_fit))
            cand.reason = self._reason(cand, effect, c_fit.coef, data)
        return found

    def _diagnose(self, data: CalibrationData, pred: Float1D) -> None:
        """The residual tests, the verdict, the fit percentages and the confidence
        intervals of the fitted model on the held-out block."""
        y_test = data.y[self.test_]
        inputs = {k: v[self.test_] for k, v in data.signals.items() if k != "t"}
        self.tests_before_ = residual_tests(
            y_test - self.base_prediction_[self.test_], inputs, self.max_lag
        )
        self.tests_after_ = residual_tests(y_test - pred[self.test_], inputs, self.max_lag)
        held_out = {k: v[self.test_] for k, v in data.signals.items()}
        self.unexplained_ = unexplained(y_test - pred[self.test_], held_out, pred[self.test_])
        self.verdict_ = verdict(y_test - pred[self.test_], self.unexplained_)
        self.unexplained_["durbin_watson"] = float(durbin_watson(y_test - pred[self.test_]))
        self.fit_percent_ = (
            fit_percent(y_test, self.base_prediction_[self.test_]),
            fit_percent(y_test, pred[self.test_]),
        )
        self.base_params_, self.base_ci_, self.effect_params_ = confidence(
            self.model_, data, self.train_
        )
        self.data_ = data

    def report(self) -> dict[str, Any]:
        """The JSON report of a fitted loop (`study calibrate`'s REPORT.json).

        Returns
        -------
        dict
            The contract keys first (``rmse_before``, ``rmse_after``,
            ``effects_added``, ``candidates_rejected``), then context: the base
            model's parameters with intervals, the residual tests before and after, the
            verdict, the look-alikes.
        """
        added, discovered, ambiguous = [], [], []
        mse = [self.rmse_before_**2] + [r**2 for r in self.step_rmse_]
        explained = mse[0] - mse[-1]
        for i, ((e, _), p, r, alike) in enumerate(
            zip(self.chain_, self.effect_params_, self.step_rmse_, self.ambiguous_, strict=True)
        ):
            share = (mse[i] - mse[i + 1]) / explained if explained > 0 else 0.0
            if alike:
                ambiguous.append(
                    {
                        "families": [e.family, *alike],
                        "params": p["params"],
                        "ci": p["ci"],
                        "rmse_after_step": r,
                        "share_of_explained_variance": share,
                    }
                )
            elif isinstance(e, OpenTerm):
                discovered.append(
                    {**term_report(e, p["params"], p["ci"], share), "rmse_after_step": r}
                )
            else:
                added.append(
                    {
                        "family": e.family,
                        "params": p["params"],
                        "ci": p["ci"],
                        "rmse_after_step": r,
                        "share_of_explained_variance": share,
                    }
                )
        in_model = {e.family for e, _ in self.chain_}
        last: dict[str, Candidate] = {}
        for c in self.candidates_:
            if c.family not in in_model:
                last[c.family] = c
        rejected = [_candidate_dict(c) for c in last.values()]
        t = self.data_.signals["t"]
        return {
            "rmse_before": self.rmse_before_,
            "rmse_after": self.rmse_after_,
            "effects_added": added,
            "discovered_terms": discovered,
            "ambiguous_effects": ambiguous,
            "candidates_rejected": rejected,
            "residual_tests_before": self.tests_before_,
            "residual_tests_after": self.tests_after_,
            "verdict": self.verdict_,
            "unexplained": self.unexplained_ if self.verdict_ == "structure_remains" else None,
            "to_tell_apart": tell_apart(
                [a["families"] for a in ambiguous], self.verdict_, self.unexplained_
            ),
            "fit_percent_before": self.fit_percent_[0],
            "fit_percent_after": self.fit_percent_[1],
            "model": self.model.name,
            "units": self.model.units(),
            "recording": self.data_.name,
            "base_params": {"params": self.base_params_, "ci": self.base_ci_},
            "preparation": {**(self.data_.preparation or {}), **_fitted_settings(self)} or None,
            "held_out": {
                "blocks": self.data_.held_out_blocks,
                "start_s": float(t[self.test_][0]),
                "end_s": float(t[-1]),
                "samples": len(t[self.test_]),
                "training_samples": len(t[self.train_]),
            },
            "settings": {
                "held_out_fraction": self.held_out_fraction,
                "alpha": self.alpha,
                "min_gain": self.min_gain,
                "max_effects": self.max_effects,
                "ci_level": 0.95,
            },
            "validation": [v.to_dict() for v in self.validation_],
            "warnings": self.warnings(),
            "candidates": [_candidate_dict(c) for c in self.candidates_],
            "calibrated_model": self.model_.to_dict(),
        }

    def warnings(self) -> list[str]:
        """Searched values that ended at an end of their search range, and parameters
        without an interval.

        At an edge the effect may stand in for something else (a long lag for a slow
        dynamic). A parameter the linearised fit does not determine (`confidence`) has
        the interval None.

        Returns
        -------
        list of str
            One line per selected effect whose fitted value lies at an edge of its
            search range, naming the family, and one per parameter without an
            interval, naming the model or family and the parameter; empty when none.
        """
        notes = []
        for effect, value in self.chain_:
            edge = _search_edge(effect, value, self.data_.signals)
            if edge is not None:
                notes.append(f"{effect.family}: {edge[1]}")
        named = [(self.model.name, self.base_ci_)]
        named += [
            (e.family, p["ci"]) for (e, _), p in zip(self.chain_, self.effect_params_, strict=True)
        ]
        for name, ci in named:
            for param in (k for k, v in ci.items() if v is None):
                notes.append(
                    f"{name}: {param} has no interval: the linearised fit does not determine "
                    "it (a step's time between two samples, or a term that is a sum of others)"
                )
        return notes


def _zero_phase(X: Float2D, cutoff_fraction: float) -> Float2D:
    """The columns of X through a 2nd-order Butterworth low-pass at `cutoff_fraction` of
    the sampling rate, run forwards and backwards (`scipy.signal.filtfilt`: no
    phase shift, so no lag)."""
    b, a = signal.butter(2, 2.0 * cutoff_fraction)
    return signal.filtfilt(b, a, X, axis=0)


def _rmse(e: Float1D) -> float:
    return float(np.sqrt(np.mean(e * e)))


def _fitted_settings(cal: Calibrator) -> dict[str, Any]:
    """The base model's settings that the loop fitted (given as None, fitted here)."""
    given, fitted = _settings(cal.model), _settings(cal.base_)
    return {k: v for k, v in fitted.items() if given.get(k) is None and v is not None}


def _settings(model: BaseModel) -> dict[str, Any]:
    return asdict(model) if is_dataclass(model) and not isinstance(model, type) else {}
