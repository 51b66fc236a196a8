"""
Calibration of the confidence: fitting ``P(right | evidence)`` and measuring its reliability.

``fit_confidence`` is the logistic regression of ``scripts/learn_confidence.py``;
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


def fit_confidence(values: Sequence[dict[str, float]], right: Sequence[bool],
                   features: Sequence[str], l2: float = 10.0,
                   refused: dict[str, float] | None = None, split: str = '') -> ConfidenceModel:
    """
    Fit ``P(right | features)`` by L2-regularised logistic regression on standardised features.

    ``values`` the feature values of each answer (``confidence.feature_values``), ``right`` its
    label; ``l2`` the penalty on the standardised weights (not on the intercept).
    """
    x = np.array([[v[f] for f in features] for v in values], dtype=float)
    y = np.asarray(right, dtype=float)
    if len(y) == 0 or y.min() == y.max():
        raise ValueError('calibration needs right and wrong answers')
    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale[scale <= 0.0] = 1.0
    z1 = np.column_stack((np.ones(len(y)), (x - mean) / scale))

    def loss(w):
        z = z1 @ w
        p = 1.0 / (1.0 + np.exp(-z))
        grad = z1.T @ (p - y)
        grad[1:] += l2 * w[1:]
        return float(np.sum(np.logaddexp(0.0, z) - y * z) + 0.5 * l2 * w[1:] @ w[1:]), grad

    w = minimize(loss, np.zeros(z1.shape[1]), jac=True, method='L-BFGS-B').x
    return ConfidenceModel(features=tuple(features), mean=tuple(float(v) for v in mean),
                           scale=tuple(float(v) for v in scale),
                           weights=tuple(float(v) for v in w[1:]), intercept=float(w[0]),
                           refused=dict(refused or REFUSED_REASONS), split=split)


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
