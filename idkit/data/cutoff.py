"""The low-pass cut-off chosen from the training data: cross-validation of a quick least-squares fit.

Why: the cut-off trades two errors that no single number balances on every robot. Too low, and the
filter removes part of the motion (the model is fitted to, and predicts, a flattened trajectory);
too high, and the twice-differentiated position noise enters the accelerations (the fit is biased
and its predictions are noisy). Which one dominates depends on the sampling rate, the sensors and the
trajectory, all of which the training recording shows. :func:`choose_cutoff` asks it:

1. every candidate of :data:`CANDIDATES_HZ` below a quarter of the (decimated) sampling rate
   preprocesses every training recording (the other :class:`PreprocessOptions` as given); one that
   cannot (its trim leaves a short recording no samples) is left out, and the reason says so;
2. only the samples every candidate keeps are used (the lowest cut-off trims the most), so all
   candidates are scored on the same samples;
3. each recording's span is cut into ``folds`` contiguous blocks of equal duration; fold ``k`` is
   block ``k`` of every recording. Contiguous, not shuffled: neighbouring samples are correlated, and
   a fit that has seen a block's neighbours would look better than it generalises;
4. for each fold, least squares on the robot's base regressor over the other folds (states *and*
   torques filtered at the candidate, as the fit will see them) predicts the fold's torques from its
   states at the candidate;
5. the out-of-fold error ``measured − predicted`` is scored as held-out validation scores a file
   (:mod:`idkit.studies.validation`): measured torques resampled but not filtered, the error and the
   torques both band-limited at the same fixed scoring ``band`` (:func:`band_limit`) whatever the
   candidate, and summed over the folds: ``‖band(E)‖ / ‖band(T)‖``;
6. the candidate with the smallest error wins.

A linear fit is enough to judge the filter and costs one Gram matrix per block (the regressor is
evaluated once per candidate). The chosen cut-off is then used for every file, the held-out ones too.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from torch import Tensor

from idkit.data.preprocess import GapWarning, PreprocessOptions, band_limit, preprocess_recording
from idkit.data.raw import Recording
from idkit.problem import SAMPLE_ARRAYS, Samples

#: Cut-offs tried (Hz), log-spaced: identification motion lives below ~2 Hz, and a cut-off above
#: ~25 Hz only lets noise into the accelerations. Those at or above a quarter of the sampling rate are
#: left out (a Butterworth filter that close to the Nyquist frequency barely filters).
CANDIDATES_HZ = (2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0)
#: Contiguous blocks per recording (module doc, step 3).
FOLDS = 5
#: The cross-validation evaluates every ``stride``-th sample, keeping this many samples per second per
#: Hz of the highest candidate cut-off (``_cross_validated``).
RATE_PER_CUTOFF = 4.0

#: ``regressor(samples) -> W[N, n, B]``: the robot's base regressor at the samples' states.
Regressor = Callable[[Samples], Tensor]


@dataclass(frozen=True)
class CutoffChoice:
    """What :func:`choose_cutoff` chose and why.

    Attributes:
        cutoff: the chosen cut-off (Hz).
        reason: one line saying how it was chosen (starts with ``"auto: "``).
        scores: cross-validated ``‖band(E)‖ / ‖band(T)‖`` per candidate (keys: the cut-off in Hz).
        band: the scoring band (Hz).
        folds: the number of contiguous blocks per recording.
    """

    cutoff: float
    reason: str
    scores: dict[float, float]
    band: float
    folds: int

    def line(self) -> str:
        """``cut-off 6 Hz (auto: …)``."""
        return f"cut-off {self.cutoff:g} Hz ({self.reason})"

    def to_dict(self) -> dict[str, Any]:
        """For ``result.json``: the choice, its reason and every candidate's score."""
        return {
            "cutoff": self.cutoff,
            "reason": self.reason,
            "band_hz": self.band,
            "folds": self.folds,
            "scores": {f"{c:g}": s for c, s in self.scores.items()},
        }


def lowest_rate(recordings: Sequence[Recording], options: PreprocessOptions) -> float:
    """The lowest sampling rate (Hz) the recordings will have after preprocessing (resampled at
    ``options.rate`` or their median rate, then decimated)."""
    rates = [
        float(options.rate) if options.rate is not None else 1.0 / float(np.median(np.diff(r.t)))
        for r in recordings
    ]
    return min(rates) / max(options.decimate, 1)


def candidates(recordings: Sequence[Recording], options: PreprocessOptions) -> list[float]:
    """The cut-offs of :data:`CANDIDATES_HZ` below a quarter of every recording's (decimated) rate."""
    return [c for c in CANDIDATES_HZ if c < lowest_rate(recordings, options) / 4]


def choose_cutoff(
    recordings: Sequence[Recording],
    regressor: Regressor,
    options: PreprocessOptions,
    band: float,
    folds: int = FOLDS,
) -> CutoffChoice:
    """The cut-off whose least-squares fit predicts held-out blocks of the training data best (module doc).

    Args:
        recordings: the raw training recordings (``t, q, tau``; each preprocessed on its own).
        regressor: the robot's base regressor ``W[N, n, B]`` of a ``Samples``.
        options: every other preprocessing option (``cutoff`` is ignored).
        band: the fixed scoring band (Hz) of the held-out error.
        folds: contiguous blocks per recording (>= 2).

    A candidate whose preprocessing fails (a low cut-off trims too much of a short recording) is left
    out of the choice, and the reason names it and why.

    Raises:
        ValueError: no candidate below a quarter of the sampling rate, or none that leaves samples
            (naming the recording and why).
    """
    if folds < 2:
        raise ValueError(f"choose_cutoff: folds must be >= 2, got {folds}")
    tried = candidates(recordings, options)
    if not tried:
        rates = [lowest_rate([r], options) for r in recordings]
        slowest = recordings[int(np.argmin(rates))]
        kept = (
            f" keeping every preprocess.decimate={options.decimate}-th sample" if options.decimate > 1 else ""
        )
        raise ValueError(
            f"cutoff=auto: no candidate cut-off ({', '.join(f'{c:g}' for c in CANDIDATES_HZ)} Hz) is below "
            f"a quarter of the {min(rates):.3g} Hz sampling rate of {slowest.source}{kept}; give "
            "preprocess.cutoff in Hz"
        )
    runs: dict[float, list[Any]] = {}
    left_out: dict[float, str] = {}
    for cutoff in tried:
        try:
            with warnings.catch_warnings():  # gaps are said once, by the preprocessing that is kept
                warnings.simplefilter("ignore", GapWarning)
                runs[cutoff] = [
                    preprocess_recording(r, replace(options, cutoff=cutoff, min_speed=0.0))
                    for r in recordings
                ]
        except ValueError as exc:  # a low cut-off trims too much of a short recording
            left_out[cutoff] = str(exc)
    if not runs:
        raise ValueError(f"cutoff=auto: {list(left_out.values())[-1]}")
    scores = _cross_validated(runs, regressor, band, folds)
    best = min(scores, key=lambda c: scores[c])
    lowest, highest = min(scores), max(scores)
    reason = (
        f"auto: lowest {folds}-fold cross-validated torque error of a least-squares fit on the training "
        f"data, {100 * scores[best]:.3g} % in the {band:g} Hz scoring band, among {len(scores)} cut-offs "
        f"{lowest:g}–{highest:g} Hz"
    )
    if left_out:  # the choice was made without them: say so, and why
        first = next(iter(left_out))
        reason += f"; {', '.join(f'{c:g}' for c in left_out)} Hz left out ({first:g} Hz: {left_out[first]})"
    return CutoffChoice(best, reason, scores, band, folds)


def _cross_validated(
    runs: dict[float, list[Any]], regressor: Regressor, band: float, folds: int
) -> dict[float, float]:
    """Step 2-5 of the module doc for every candidate: ``{cutoff: ‖band(E)‖ / ‖band(T)‖}``.

    The fits and predictions use every ``stride``-th scored sample, ``stride`` keeping at least
    :data:`RATE_PER_CUTOFF` × the highest candidate (100 Hz of 200 Hz data, a tenth of 1 kHz data):
    the states are band-limited below it, and the regressor, the bulk of the cost, is evaluated on
    fewer samples. The measured torques are band-limited at their full rate first (thinning them
    would fold their noise into the band); ``band(E) = band(T) − band(prediction)`` (linear)."""
    most_trimmed = runs[min(runs)]
    reference = []  # per recording: (scored times, band-limited measured torques, stride)
    for run, first in zip(runs[max(runs)], most_trimmed, strict=True):
        rows = _common(run.times, first.times)
        step = float(np.median(np.diff(run.times)))
        stride = max(1, int(1.0 / (step * RATE_PER_CUTOFF * max(runs))))
        reference.append((run.times[rows], band_limit(run.times[rows], run.raw_tau[rows], band), stride))
    total = sum(float(np.sum(measured[::stride] ** 2)) for _, measured, stride in reference)
    scores = {}
    for cutoff, done in runs.items():
        blocks = []
        for (times, _, stride), run in zip(reference, done, strict=True):
            rows = np.flatnonzero(_common(run.times, times))[::stride]
            thinned = Samples(*(getattr(run.samples, k)[rows] for k in SAMPLE_ARRAYS))
            W = regressor(thinned).detach().cpu().double().numpy()
            edges = np.linspace(times[0], times[-1], folds + 1)[1:-1]
            fold = np.searchsorted(edges, run.times[rows], side="right")
            blocks.append((W, run.samples.tau.numpy()[rows], fold))
        predicted = _out_of_fold(blocks, folds)
        error = 0.0
        for (times, measured, stride), guess in zip(reference, predicted, strict=True):
            error += float(np.sum((measured[::stride] - band_limit(times[::stride], guess, band)) ** 2))
        scores[cutoff] = float(np.sqrt(error / total)) if total > 0 else float("inf")
    return scores


def _common(times: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Mask of ``times`` that are also in ``kept`` (both on one uniform grid; trims differ)."""
    step = float(np.median(np.diff(times))) if times.size > 1 else 1.0
    return np.isin(np.round(times / step), np.round(kept / step))


def _out_of_fold(blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]], folds: int) -> list[np.ndarray]:
    """Per recording, each sample's torques ``[N, n]`` predicted by the least-squares fit on the folds
    that do not hold it. ``blocks``: per recording ``(W[N, n, B], tau[N, n], fold[N])``.

    Normal equations of the column-equilibrated regressor, one Gram matrix per fold, each fit the
    total minus its fold's: a fraction of a QR's cost for the tens of thousands of rows of a recording,
    and accurate enough to rank filters (directions below ``1e-12`` of the largest eigenvalue, those
    a fold leaves unexcited, get the minimum-norm zero)."""
    B = blocks[0][0].shape[-1]
    scale = np.sqrt(sum(np.sum(W**2, axis=(0, 1)) for W, _, _ in blocks))
    scale[scale == 0] = 1.0
    gram = np.zeros((folds, B, B))
    moment = np.zeros((folds, B))
    for W, tau, fold in blocks:
        for k in range(folds):
            rows = (W[fold == k] / scale).reshape(-1, B)
            gram[k] += rows.T @ rows
            moment[k] += rows.T @ tau[fold == k].reshape(-1)
    predicted = [np.empty_like(tau) for _, tau, _ in blocks]
    for k in range(folds):
        values, vectors = np.linalg.eigh(gram.sum(0) - gram[k])
        kept = values > 1e-12 * values[-1]
        alpha = vectors[:, kept] @ ((vectors[:, kept].T @ (moment.sum(0) - moment[k])) / values[kept])
        for (W, _, fold), out in zip(blocks, predicted, strict=True):
            out[fold == k] = W[fold == k] @ (alpha / scale)
    return predicted
