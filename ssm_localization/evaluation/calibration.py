"""
Calibration of the confidence: fitting ``P(right | evidence)`` and measuring its reliability.

``fit_confidence`` is the score (a logistic regression, or boosted regression trees) and the
isotonic map of ``scripts/learn_confidence.py``;
``reliability`` bins answers by their reported confidence and compares each bin's mean
confidence with the fraction of its answers that were right (a reliability diagram, drawn by
``plotting.plot_reliability``).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Mapping, Sequence

import numpy as np
from scipy.optimize import minimize
from scipy.stats import binomtest

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


#: boosted trees: rounds, learning rate, depth, least weight in a leaf, L2 on leaf values, bins
BOOSTING = {'rounds': 150, 'rate': 0.1, 'depth': 2, 'min_leaf': 40.0, 'l2': 1.0, 'bins': 32}


def fit_boosted(x: np.ndarray, y: np.ndarray, start: np.ndarray,
                weight: np.ndarray | None = None, rounds: int = 150, rate: float = 0.1,
                depth: int = 2, min_leaf: float = 40.0, l2: float = 1.0, bins: int = 32,
                monotone: Sequence[int] | None = None) -> tuple:
    """
    Return gradient-boosted regression trees on the logistic loss, grown from the score ``start``.

    ``start`` is each answer's log-odds before the trees (a logistic regression's, in
    :func:`fit_confidence`).
    Each round fits a tree of at most ``depth`` splits to the loss's gradient with Newton leaf
    values ``-G / (H + l2)`` (second-order boosting), scaled by ``rate``. Splits are searched at
    ``bins`` quantiles of each feature; a leaf holds at least ``min_leaf`` of the sample weight
    (no leaf rests on a handful of answers). Unlike the linear score it can weigh one piece of
    evidence by another: a lead over the rivals means more when the scan sees much.
    ``monotone`` gives each feature's direction (+1: the score never falls as it grows, -1:
    never rises, 0: free): a split that would break it is not taken, and the leaves below a
    split are bounded by the midpoint of its two values, so every tree, and their sum, keeps
    the directions everywhere, also far outside the data (worse evidence never earns more
    trust). Trees are tuples of ``(feature, threshold, left, right, value)`` nodes
    (``ConfidenceModel.trees``).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    sw = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=float)
    if len(y) == 0 or y.min() == y.max():
        raise ValueError('calibration needs right and wrong answers')
    direction = np.zeros(x.shape[1], int) if monotone is None else np.asarray(monotone, int)
    if direction.shape != (x.shape[1],):
        raise ValueError(f'monotone: one direction per feature ({x.shape[1]})')
    cuts = [np.unique(np.quantile(x[:, j], np.linspace(0.0, 1.0, bins + 1)[1:-1]))
            for j in range(x.shape[1])]
    # code k <=> x <= cuts[k] (and above cuts[k - 1])
    codes = np.column_stack([np.searchsorted(c, x[:, j], side='left')
                             for j, c in enumerate(cuts)])
    grow = _Grower(codes, cuts, direction, sw, depth, min_leaf, l2, rate)
    score = np.array(start, dtype=float)
    trees = []
    for _ in range(rounds):
        p = 1.0 / (1.0 + np.exp(-score))
        tree = grow.tree(sw * (p - y), sw * p * (1.0 - p))
        trees.append(tree)
        score += tree_values(tree, x)
    return tuple(trees)


@dataclass
class _Grower:
    """One regression tree per call of :meth:`tree`, on binned features (:func:`fit_boosted`)."""

    codes: np.ndarray
    cuts: list
    direction: np.ndarray
    sw: np.ndarray
    depth: int
    min_leaf: float
    l2: float
    rate: float

    def tree(self, g: np.ndarray, h: np.ndarray) -> tuple:
        nodes: list[tuple[int, float, int, int, float]] = []
        self._grow(nodes, g, h, np.arange(len(g)), self.depth, -math.inf, math.inf)
        return tuple(nodes)

    def _grow(self, nodes: list, g: np.ndarray, h: np.ndarray, idx: np.ndarray, depth: int,
              low: float, high: float) -> int:
        """Append the (sub)tree of the answers ``idx`` to ``nodes``; return its root's index."""
        k = len(nodes)
        big_g, big_h, weight = float(g[idx].sum()), float(h[idx].sum()), float(self.sw[idx].sum())
        nodes.append((-1, 0.0, -1, -1,
                      float(self.rate * min(max(-big_g / (big_h + self.l2), low), high))))
        if depth == 0 or weight < 2.0 * self.min_leaf:
            return k
        parent, best, where = big_g * big_g / (big_h + self.l2), 1e-9, None
        # (feature, bin, left value, right value) of the best split
        for j, c in enumerate(self.cuts):
            if len(c) == 0:
                continue
            cj = self.codes[idx, j]
            gl = np.cumsum(np.bincount(cj, g[idx], len(c) + 1))[:-1]
            hl = np.cumsum(np.bincount(cj, h[idx], len(c) + 1))[:-1]
            wl = np.cumsum(np.bincount(cj, self.sw[idx], len(c) + 1))[:-1]
            gr, hr = big_g - gl, big_h - hl
            gain = gl ** 2 / (hl + self.l2) + gr ** 2 / (hr + self.l2) - parent
            gain[(wl < self.min_leaf) | (weight - wl < self.min_leaf)] = -np.inf
            left, right = -gl / (hl + self.l2), -gr / (hr + self.l2)
            if self.direction[j]:
                gain[self.direction[j] * (right - left) < 0.0] = -np.inf
            b = int(np.argmax(gain))
            if gain[b] > best:
                best, where = float(gain[b]), (j, b, float(left[b]), float(right[b]))
        if where is None:
            return k
        j, b, left_value, right_value = where
        go_left = self.codes[idx, j] <= b
        lo_kids, hi_kids = (low, high), (low, high)
        if self.direction[j]:
            mid = 0.5 * (min(max(left_value, low), high) + min(max(right_value, low), high))
            if self.direction[j] > 0:        # the left subtree stays below the right one
                lo_kids, hi_kids = (low, mid), (mid, high)
            else:
                lo_kids, hi_kids = (mid, high), (low, mid)
        left = self._grow(nodes, g, h, idx[go_left], depth - 1, *lo_kids)
        right = self._grow(nodes, g, h, idx[~go_left], depth - 1, *hi_kids)
        nodes[k] = (j, float(self.cuts[j][b]), left, right, 0.0)
        return k


def tree_values(tree: tuple, x: np.ndarray) -> np.ndarray:
    """Return the value of ``tree`` (``ConfidenceModel.trees``) for each row of ``x``."""
    at = np.zeros(len(x), dtype=int)
    feature = np.array([n[0] for n in tree])
    threshold = np.array([n[1] for n in tree])
    left, right = np.array([n[2] for n in tree]), np.array([n[3] for n in tree])
    rows = np.arange(len(x))
    for _ in range(len(tree)):
        f = feature[at]
        inner = f >= 0
        if not inner.any():
            break
        go_left = x[rows[inner], f[inner]] <= threshold[at[inner]]
        at[inner] = np.where(go_left, left[at[inner]], right[at[inner]])
    return np.array([n[4] for n in tree])[at]


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


def recalibration_points(outer: Sequence[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(probabilities, new probabilities)`` of a recalibration map, ready for ``np.interp``.

    ``outer``'s knots inside (0, 1), extended to ``(0, 0)`` and ``(1, 1)`` and made strictly
    increasing (a stretch that would be flat rises by 1e-9 a knot), so that the map keeps every
    pair of answers in the order the model's own map puts them.
    """
    pts = sorted((float(c), float(q)) for c, q in outer if 0.0 < c < 1.0)
    pts = [(0.0, 0.0)] + pts + [(1.0, 1.0)]
    xs = np.array([c for c, _ in pts])
    qs = np.array([q for _, q in pts])
    for k in range(1, len(qs)):
        qs[k] = min(max(qs[k], qs[k - 1] + 1e-9), 1.0)
    return xs, qs


def compose_calibration(knots: Sequence[tuple[float, float]],
                        outer: Sequence[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
    """
    Return the knots of the map ``knots`` followed by the map ``outer``.

    ``knots`` maps log-odds to a probability, ``outer`` a probability to a probability; both
    are piecewise linear and held constant beyond their ends. A recalibration: ``outer`` maps
    the probabilities a model reports to the fraction of its answers that were right
    (``isotonic_knots`` of labelled answers on their reported confidence), made strictly
    increasing by :func:`recalibration_points`, so the composed map orders every pair of
    answers as the model's own map does, and a threshold ``t`` on the old probability is the
    threshold ``outer(t)`` on the new. The result is exact: its knots are those of ``knots``
    and the log-odds where the old probability crosses a knot of ``outer``.
    """
    if not knots:
        raise ValueError('compose_calibration: the model has no isotonic map to compose with')
    xs, qs = recalibration_points(outer)
    zs = [float(z) for z, _ in knots]
    ps = [float(p) for _, p in knots]
    out = [(zs[0], ps[0])]
    for (z0, p0), (z1, p1) in zip(zip(zs, ps), zip(zs[1:], ps[1:])):
        if p1 > p0:                 # the old map crosses these knots of outer in (z0, z1)
            for c in xs[(xs > p0) & (xs < p1)]:
                out.append((z0 + (z1 - z0) * (c - p0) / (p1 - p0), float(c)))
        out.append((z1, p1))
    return tuple((z, float(np.interp(p, xs, qs))) for z, p in out)


def fit_confidence(values: Sequence[dict[str, float]], right: Sequence[bool],
                   features: Sequence[str], groups: Sequence[str], l2: float = 10.0,
                   weight: Sequence[float] | None = None, refused: dict[str, float] | None = None,
                   split: str = '', boosted: dict | None = None) -> ConfidenceModel:
    """
    Fit ``P(right | features)``: a score, then an isotonic map of it to a probability.

    The score is a logistic regression (L2 ``l2``), with ``boosted`` (the keywords of
    :func:`fit_boosted`, e.g. :data:`BOOSTING`) plus boosted regression trees grown from it
    (the regression carries the evidence beyond the data, the trees how one piece of it weighs
    another). ``values`` the feature values of each answer (``confidence.feature_values``),
    ``right`` its label, ``groups`` the building it comes from, ``weight`` its weight. The
    score is fitted on every answer; the isotonic map on *cross-fitted* scores -- each
    building's answers scored by a model fitted without that building -- so the probabilities
    are those of a building the model has not seen.
    """
    x = np.array([[v[f] for f in features] for v in values], dtype=float)
    y = np.asarray(right, dtype=float)
    sw = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=float)
    g = np.asarray(groups)

    def fit(rows):
        """Fit the regression, and the trees grown from its score, on the answers ``rows``."""
        mean, scale, w, b = fit_logistic(x[rows], y[rows], sw[rows], l2)
        trees = () if boosted is None else fit_boosted(
            x[rows], y[rows], b + ((x[rows] - mean) / scale) @ w, sw[rows], **boosted)
        return mean, scale, w, b, trees

    def score(z, mean, scale, w, b, trees):
        return b + ((z - mean) / scale) @ w + sum((tree_values(t, z) for t in trees),
                                                  np.zeros(len(z)))

    held = np.zeros(len(y))
    for name in np.unique(g):
        out = g == name
        held[out] = score(x[out], *fit(~out))
    mean, scale, w, b, trees = fit(np.ones(len(y), bool))
    return ConfidenceModel(features=tuple(features), mean=tuple(float(v) for v in mean),
                           scale=tuple(float(v) for v in scale),
                           weights=tuple(float(v) for v in w), intercept=float(b),
                           refused=dict(refused or REFUSED_REASONS),
                           calibration=isotonic_knots(held, y, sw), split=split, trees=trees)


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

    def interval(self, level: float = 0.95) -> tuple[float, float]:
        """
        Return the Wilson score interval of the fraction right (scipy's ``binomtest``).

        What chance alone allows: with 50 answers right 80 % of the time, the observed fraction
        strays by 11 points either way one time in twenty, so a bin's gap beyond 2 points is not
        by itself a miscalibration; a mean confidence outside this interval is one.
        """
        if not self.count:
            return math.nan, math.nan
        ci = binomtest(self.right, self.count).proportion_ci(level, method='wilson')
        return float(ci.low), float(ci.high)

    @property
    def beyond_chance(self) -> bool:
        """Return True when the bin's mean confidence lies outside its 95 % interval."""
        low, high = self.interval()
        return self.count > 0 and not low <= self.mean_confidence <= high


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
    """
    Return a table of ``bins``; bins with at least ``min_count`` answers are judged.

    Judged against the issue's 2 points, and against chance: ``95 % of right`` is the Wilson
    interval of the fraction right (:meth:`ReliabilityBin.interval`), and a bin whose mean
    confidence lies outside it is marked ``beyond chance``.
    """
    lines = ['  confidence     n   mean conf  observed   95 % of right   gap']
    for b in bins:
        if not b.count:
            continue
        low, high = b.interval()
        mark = '' if b.count < min_count else ('  within 2 points' if abs(b.gap) <= 0.02
                                               else '  OFF by more than 2 points')
        if mark and abs(b.gap) > 0.02:
            mark += ', beyond chance' if b.beyond_chance else ', within chance'
        lines.append(f'  {b.low:.2f}-{b.high:.2f} {b.count:6d}   {b.mean_confidence:.3f}     '
                     f'{b.observed:.3f}   {low:.3f}-{high:.3f}     {b.gap:+.3f}{mark}')
    return '\n'.join(lines)


def reliability_report(graded: Mapping[str, Sequence[tuple[float, bool]]],
                       what: str = 'reliability') -> tuple[dict[str, list[ReliabilityBin]], str]:
    """
    Return the reliability bins of each split's ``(confidence, right)`` answers, and their text.

    The splits in reverse order of their names (validation before tuning), each headed by
    ``what``, its name and its count; a split without answers is left out.
    """
    tables, parts = {}, []
    for split, pairs in sorted(graded.items(), reverse=True):
        if not pairs:
            continue
        confidence, right = zip(*pairs)
        tables[split] = reliability(confidence, right)
        parts += [f'{what}, {split} split ({len(pairs)} answers; a bin is judged with at least '
                  f'50):', format_reliability(tables[split])]
    return tables, '\n'.join(parts)
