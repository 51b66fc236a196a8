"""
The calibrated confidence model: ``P(right | evidence)``.

A score weighs the evidence of an answer (its log-odds of being right); an isotonic (monotone,
piecewise-linear) map, fitted on scores of buildings the score's fit did not see, turns it into a
probability. ``scripts/learn_confidence.py`` fits both on labelled answers of the calibration
split (right poses, wrong places in the same building, scans of other buildings). The global
answers' score (:data:`CONFIDENCE_MODEL`) is a logistic regression plus boosted regression trees
grown from it, kept as package data in ``confidence_model.json`` beside this module; the
tracker's (:data:`TRACK_CONFIDENCE_MODEL`) is a logistic regression, copied here from
``config/track_confidence_model.yaml`` (a test checks they agree). The paper itself learns its
pairwise potentials by logistic regression (section II.B); here the same loss weighs the
evidence of a whole answer.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import json
import math
from pathlib import Path

#: what "right" means wherever a confidence is fitted or measured: within this of the truth
RIGHT_XY = 0.5                      # metres
RIGHT_YAW = math.radians(5.0)       # radians
#: cell size of the real buildings' maps the models were fitted on (metres; of the simulated
#: calibration maps the empty room has 0.1 m cells); on real maps of coarser cells the verdict
#: was measured to be less reliable (``localization.confidence.resolution_warning``)
CALIBRATION_RESOLUTION = 0.05
#: reasons the rules refuse an answer before the model is asked, with a neutral rate
REFUSED_REASONS = {'implausible': 0.0, 'rival': 0.5, 'degenerate': 0.5}


@dataclass(frozen=True)
class ConfidenceModel:
    """
    ``P(right) = calibrated(intercept + sum_k w_k (f_k - mean_k) / scale_k + sum_t tree_t(f))``.

    ``features`` name the inputs (see ``localization/confidence.py`` for how each is made from
    the evidence of an answer). The score (log-odds) has a linear part (``mean``, ``scale``,
    ``weights``; empty: none) and a boosted part (``trees``; empty: none): small regression
    trees on the raw features, each a tuple of nodes ``(feature, threshold, left, right,
    value)``, node 0 the root; a node with ``feature`` -1 is a leaf worth ``value``, any other
    sends an answer to the node ``left`` when its feature is at most ``threshold``, else to
    ``right``. ``calibration`` is the isotonic map from the score to the probability, as
    ``(log-odds, probability)`` knots in increasing order, interpolated linearly and held
    constant beyond the ends (empty: the logistic probability itself); ``split`` names the
    data it was fitted on.
    """

    features: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    weights: tuple[float, ...]
    intercept: float
    #: P(right) of answers the rules refuse before the model is asked, by reason (``implausible``:
    #: too much seen through walls or too little explained; ``rival``: a distinct pose scores
    #: about as well; ``degenerate``: the position is undetermined along some direction), the
    #: rate at which such answers were right on the calibration split (``rival`` as measured;
    #: the verdict reports ``min(P, pair)`` or ``min(P, 2/(k+1))`` for those, ``verdict``)
    refused: dict[str, float] = field(default_factory=lambda: dict(REFUSED_REASONS))
    calibration: tuple[tuple[float, float], ...] = ()
    split: str = ''
    trees: tuple[tuple[tuple[int, float, int, int, float], ...], ...] = ()
    #: the most an answer refused for one distinct rival (a pair of look-alikes) reports: the
    #: rate at which the best of such a pair was right where the model said more (the verdict
    #: reports ``min(P, pair)``, and ``min(P, 2/(k+1))`` for k > 2 look-alikes)
    pair: float = 2.0 / 3.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.pair <= 1.0:
            raise ValueError(f'ConfidenceModel.pair: a rate in [0, 1], got {self.pair!r}')
        if set(self.refused) != set(REFUSED_REASONS) or not all(
                0.0 <= v <= 1.0 for v in self.refused.values()):
            raise ValueError(f'ConfidenceModel.refused: a rate in [0, 1] for each of '
                             f'{sorted(REFUSED_REASONS)}, got {self.refused!r}')
        n = len(self.features)
        linear = (len(self.mean), len(self.scale), len(self.weights))
        if linear not in ((n, n, n), (0, 0, 0)) or (n == 0):
            raise ValueError(f'ConfidenceModel: {n} features but {len(self.mean)} means, '
                             f'{len(self.scale)} scales and {len(self.weights)} weights')
        knots = [v for k in self.calibration for v in k]
        pairs = list(zip(self.calibration, self.calibration[1:]))
        if (any(len(k) != 2 for k in self.calibration)
                or not all(0.0 <= p <= 1.0 for _, p in self.calibration)
                or any(a[0] > b[0] or a[1] > b[1] for a, b in pairs)):
            raise ValueError('ConfidenceModel.calibration: (log-odds, probability) knots, both '
                             'increasing, probabilities in [0, 1]')
        for tree in self.trees:
            _check_tree(tree, n)
        nodes = [v for tree in self.trees for node in tree for v in (node[1], node[4])]
        values = (*self.mean, *self.scale, *self.weights, self.intercept, *knots, *nodes)
        if not all(math.isfinite(v) for v in values) or min(self.scale, default=1.0) <= 0.0:
            raise ValueError('ConfidenceModel: means, weights, tree nodes and the intercept '
                             'must be finite and scales > 0')

    def rival_cap(self, k: int) -> float:
        """
        Return the most an answer refused for ``k`` distinct poses that fit as well reports.

        A pair: ``pair``; more: ``2/(k+1)``, as if the best were twice as likely as each other.
        """
        return self.pair if k <= 2 else 2.0 / (k + 1)

    def logit(self, values: dict[str, float]) -> float:
        """Return the log-odds of a right pose given the feature ``values`` by name."""
        z = self.intercept
        for name, m, s, w in zip(self.features, self.mean, self.scale, self.weights):
            z += w * (values[name] - m) / s
        if self.trees:
            x = [values[name] for name in self.features]
            for tree in self.trees:
                node = tree[0]
                while node[0] >= 0:
                    node = tree[node[2] if x[node[0]] <= node[1] else node[3]]
                z += node[4]
        return z

    def probability(self, values: dict[str, float]) -> float:
        """Return ``P(right | evidence)`` for the feature ``values`` by name."""
        return self.calibrated(self.logit(values))

    def calibrated(self, z: float) -> float:
        """Return the probability of the log-odds ``z``: the isotonic map, else the logistic."""
        knots = self.calibration
        if not knots:
            return 1.0 / (1.0 + math.exp(-z)) if z >= -700.0 else 0.0
        if z <= knots[0][0]:
            return knots[0][1]
        for (z0, p0), (z1, p1) in zip(knots, knots[1:]):
            if z <= z1:
                return p0 + (p1 - p0) * (z - z0) / (z1 - z0) if z1 > z0 else p1
        return knots[-1][1]

    @classmethod
    def from_dict(cls, doc: dict) -> 'ConfidenceModel':
        """Return the model of a mapping as ``scripts/learn_confidence.py`` writes it."""
        tuples = {k: tuple(doc.get(k, ())) for k in ('features', 'mean', 'scale', 'weights')}
        return cls(**tuples, intercept=float(doc['intercept']),
                   refused={k: float(v) for k, v in doc['refused'].items()},
                   calibration=tuple((float(z), float(p)) for z, p in doc['calibration']),
                   split=str(doc.get('split', '')), pair=float(doc.get('pair', cls.pair)),
                   trees=tuple(tuple((int(f), float(t), int(lo), int(hi), float(v))
                                     for f, t, lo, hi, v in tree)
                               for tree in doc.get('trees', ())))


def _check_tree(tree, features: int) -> None:
    """
    Raise ``ValueError`` unless ``tree`` is a tree of ``(feature, threshold, ...)`` nodes.

    Each node is ``(feature, threshold, left, right, value)``; a split names one of the
    ``features`` inputs and leads to later nodes.
    """
    n = len(tree)
    ok = n > 0 and all(len(node) == 5 for node in tree) and all(
        f < 0 or (f < features and k < lo < n and k < hi < n)
        for k, (f, _, lo, hi, _) in enumerate(tree))
    if not ok:
        raise ValueError('ConfidenceModel.trees: nodes (feature, threshold, left, right, value) '
                         'with features in range and children after their parent')


def load_model(path: Path) -> ConfidenceModel:
    """Return the model of a JSON file written by ``scripts/learn_confidence.py``."""
    return ConfidenceModel.from_dict(json.loads(path.read_text(encoding='utf-8'))['model'])


#: fitted by ``scripts/learn_confidence.py`` on the calibration split (boosted trees)
CONFIDENCE_MODEL = load_model(Path(__file__).with_name('confidence_model.json'))

#: the tracker's, fitted by ``scripts/learn_confidence.py --tracker`` on tracked answers
#: (``config/track_confidence_model.yaml``, 2026-11-25: 7285 answers the rules accept, 7253 right)
TRACK_CONFIDENCE_MODEL = ConfidenceModel(
    features=('through', 'short', 'missing',
              'on_wall', 'unknown', 'unexplained_runs',
              'explained', 'margin', 'log_position_std',
              'log_yaw_std', 'log_scan_length', 'log_extent',
              'log_prior_distance', 'log_scan_position_std'),
    mean=(
        0.049351154322983246, 0.05163915977838543, 0.014971402425075013,
        0.9620145449274649, 0.06294100644767821, 0.0023890875619504825,
        0.9006470763111123, 0.8438528617251929, -2.795860744019808,
        -4.212208487684603, 2.2891813764593043, 1.8564503915504285,
        0.626596086252648, -2.7931644262895476,
    ),
    scale=(
        0.04653040442115692, 0.0770506070056771, 0.037787071237147134,
        0.07425730103586711, 0.06460248526530214, 0.02006586423106467,
        0.06777443621381288, 0.13173164186922617, 0.15400539723980003,
        0.4003367689899871, 0.48553074433987636, 0.674652208295111,
        0.28089774726076083, 0.16723581205962212,
    ),
    weights=(
        0.06493638156894474, -0.1119392416963464, -0.4115833885155921,
        -0.19316768495840103, -0.41695421679069394, -0.15045172338857593,
        0.013277278535387857, 0.5146787839285415, -0.1269312619285399,
        -0.5767132118295628, 0.4979711025550513, 0.34397998031841476,
        -0.9878548925323206, 0.406103579814722,
    ),
    intercept=7.518180790934085,
    refused={'implausible': 0.0, 'rival': 0.5, 'degenerate': 0.5},
    calibration=(
        (0.4585672800891232, 0.8708333333333333),
        (1.9571712778791073, 0.9711538461538461),
        (2.791982190731335, 0.9875690607734806),
        (3.3782032965438966, 0.9885496183206107),
        (3.7142138156118345, 0.9911032028469751),
        (4.240429551308068, 0.9953007518796992),
        (5.786846667853642, 0.9971931137724551),
        (9.010970322764027, 0.9998409163219854),
    ),
    split='tracker calibration: intel, aces, fhw')
