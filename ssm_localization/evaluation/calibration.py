"""
Calibration of the confidence: fitting ``P(right | evidence)`` and measuring its reliability.

``fit_confidence`` is the logistic regression and isotonic map of ``scripts/learn_confidence.py``;
``reliability`` bins answers by their reported confidence and compares each bin's mean
confidence with the fraction of its answers that were right (a reliability diagram, drawn by
``plotting.plot_reliability``).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
from scipy.optimize import minimize

from ..config.confidence import ConfidenceModel, REFUSED_REASONS

#: reliability bins: [0, 0.1), ..., [0.9, 0.99), [0.99, 1.0]
BIN_EDGES = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1.0)


def fit_logistic(x: np.ndarray, y: np.ndarray, weight: np.ndarray | None = None,
                 l2: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """
    Return ``(mean, scale, weights, intercept)`` of an L2-regularised logistic regression.

    The features are standardised (``mean``, ``scale``) and ``l2`` penalises the standardised
    weights, not the intercept; ``weight`` weighs the samples.
    """
    y = np.asarray(y, dtype=float)
    if len(y) == 0 or y.min() == y.max():
        raise ValueError('calibration needs right and wrong answers')
    sw = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=float)
    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale[scale <= 0.0] = 1.0
    z1 = np.column_stack((np.ones(len(y)), (x - mean) / scale))

    def loss(w):
        z = z1 @ w
        p = 1.0 / (1.0 + np.exp(-z))
        grad = z1.T @ (sw * (p - y))
        grad[1:] += l2 * w[1:]
        return (float(np.sum(sw * (np.logaddexp(0.0, z) - y * z)) + 0.5 * l2 * w[1:] @ w[1:]),
                grad)

    w = minimize(loss, np.zeros(z1.shape[1]), jac=True, method='L-BFGS-B').x
    return mean, scale, w[1:], float(w[0])


def isotonic_knots(z: np.ndarray, y: np.ndarray, weight: np.ndarray | None = None,
                   min_weight: float = 25.0) -> tuple[tuple[float, float], ...]:
    """
    Return ``(z, probability)`` knots of the isotonic regression of the labels ``y`` on ``z``.

    Pool-adjacent-violators on the weighted labels; blocks lighter than ``min_weight`` are merged
    into a neighbour (no knot rests on a handful of answers); each block's probability is
    ``(right + 0.5) / (weight + 1)`` (kept non-decreasing), so no knot says 0 or 1; its ``z`` is
    the block's mean.
    """
    order = np.argsort(z, kind='stable')
    zs = np.asarray(z, float)[order]
    ys = np.asarray(y, float)[order]
    ws = (np.ones(len(ys)) if weight is None else np.asarray(weight, float)[order])
    # blocks as [weight, weighted right, weighted z]
    blocks: list[list[float]] = []
    for zi, yi, wi in zip(zs, ys, ws):
        blocks.append([wi, wi * yi, wi * zi])
        while len(blocks) > 1 and (blocks[-2][1] / blocks[-2][0]
                                   >= blocks[-1][1] / blocks[-1][0]):
            last = blocks.pop()
            blocks[-1] = [a + b for a, b in zip(blocks[-1], last)]
    k = 0
    while len(blocks) > 1 and k < len(blocks):
        if blocks[k][0] >= min_weight:
            k += 1
            continue
        j = k + 1 if k == 0 else k - 1          # merge into a neighbour (the later one first)
        if 0 < k < len(blocks) - 1 and blocks[k + 1][0] < blocks[k - 1][0]:
            j = k + 1
        lo, hi = min(j, k), max(j, k)
        blocks[lo:hi + 1] = [[a + b for a, b in zip(blocks[lo], blocks[hi])]]
        k = 0
    probs = np.maximum.accumulate([(b[1] + 0.5) / (b[0] + 1.0) for b in blocks])
    return tuple((float(b[2] / b[0]), float(p)) for b, p in zip(blocks, probs))


def fit_confidence(values: Sequence[dict[str, float]], right: Sequence[bool],
                   features: Sequence[str], groups: Sequence[str], l2: float = 10.0,
                   weight: Sequence[float] | None = None, refused: dict[str, float] | None = None,
                   split: str = '') -> ConfidenceModel:
    """
    Fit ``P(right | features)``: a logistic score, then an isotonic map of it to a probability.

    ``values`` the feature values of each answer (``confidence.feature_values``), ``right`` its
    label, ``groups`` the building it comes from, ``weight`` its weight. The logistic regression
    is fitted on every answer; the isotonic map on *cross-fitted* scores -- each building's
    answers scored by a regression fitted without that building -- so the probabilities are
    those of a building the regression has not seen.
    """
    x = np.array([[v[f] for f in features] for v in values], dtype=float)
    y = np.asarray(right, dtype=float)
    sw = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=float)
    g = np.asarray(groups)
    held = np.zeros(len(y))
    for name in np.unique(g):
        out = g == name
        mean, scale, w, b = fit_logistic(x[~out], y[~out], sw[~out], l2)
        held[out] = b + ((x[out] - mean) / scale) @ w
    mean, scale, w, b = fit_logistic(x, y, sw, l2)
    return ConfidenceModel(features=tuple(features), mean=tuple(float(v) for v in mean),
                           scale=tuple(float(v) for v in scale),
                           weights=tuple(float(v) for v in w), intercept=b,
                           refused=dict(refused or REFUSED_REASONS),
                           calibration=isotonic_knots(held, y, sw), split=split)


@dataclass(frozen=True)
class ReliabilityBin:
    """Answers whose confidence fell in ``[low, high)``: how many, their mean, how many right."""

    low: float
    high: float
    count: int
    mean_confidence: float
    right: int

    @property
    def observed(self) -> float:
        """Return the fraction of the bin's answers that were right (NaN for an empty bin)."""
        return self.right / self.count if self.count else math.nan

    @property
    def gap(self) -> float:
        """Return observed minus predicted, in probability (NaN for an empty bin)."""
        return self.observed - self.mean_confidence if self.count else math.nan


def reliability(confidence: Sequence[float], right: Sequence[bool],
                edges: Sequence[float] = BIN_EDGES) -> list[ReliabilityBin]:
    """Return the reliability bins of answers with a reported ``confidence`` and a label."""
    c = np.asarray(confidence, dtype=float)
    r = np.asarray(right, dtype=bool)
    out = []
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        last = k == len(edges) - 2
        m = (c >= lo) & ((c <= hi) if last else (c < hi))
        out.append(ReliabilityBin(float(lo), float(hi), int(m.sum()),
                                  float(c[m].mean()) if m.any() else math.nan, int(r[m].sum())))
    return out


def format_reliability(bins: list[ReliabilityBin], min_count: int = 50) -> str:
    """Return a table of ``bins``; bins with at least ``min_count`` answers are judged."""
    lines = ['  confidence     n   mean conf  observed   gap']
    for b in bins:
        if not b.count:
            continue
        mark = '' if b.count < min_count else ('  within 2 points' if abs(b.gap) <= 0.02
                                               else '  OFF by more than 2 points')
        lines.append(f'  {b.low:.2f}-{b.high:.2f} {b.count:6d}   {b.mean_confidence:.3f}     '
                     f'{b.observed:.3f}   {b.gap:+.3f}{mark}')
    return '\n'.join(lines)
