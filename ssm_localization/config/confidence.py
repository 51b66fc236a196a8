"""
The calibrated confidence model: ``P(right | evidence)`` by logistic regression.

``scripts/learn_confidence.py`` fits it on labelled answers of the calibration split (right
poses, wrong places in the same building, scans of other buildings) and writes
``config/confidence_model.yaml``; :data:`CONFIDENCE_MODEL` is copied from that file (a test
checks they agree). The paper itself learns its pairwise potentials by logistic regression
(section II.B); here the same tool weighs the evidence of a whole answer.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

#: reasons the rules refuse an answer before the model is asked, with a neutral rate
REFUSED_REASONS = {'implausible': 0.0, 'rival': 0.5, 'degenerate': 0.5}


@dataclass(frozen=True)
class ConfidenceModel:
    """
    ``P(right) = 1 / (1 + exp(-(intercept + sum_k w_k (f_k - mean_k) / scale_k)))``.

    ``features`` name the inputs (see ``localization/confidence.py`` for how each is made from
    the evidence of an answer); ``split`` names the data it was fitted on.
    """

    features: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    weights: tuple[float, ...]
    intercept: float
    #: P(right) of answers the rules refuse before the model is asked, by reason (``implausible``:
    #: too much seen through walls or too little explained; ``rival``: a distinct pose scores
    #: about as well; ``degenerate``: the position is undetermined along some direction), the
    #: rate at which such answers were right on the calibration split
    refused: dict[str, float] = field(default_factory=lambda: dict(REFUSED_REASONS))
    split: str = ''

    def __post_init__(self) -> None:
        if set(self.refused) != set(REFUSED_REASONS) or not all(
                0.0 <= v <= 1.0 for v in self.refused.values()):
            raise ValueError(f'ConfidenceModel.refused: a rate in [0, 1] for each of '
                             f'{sorted(REFUSED_REASONS)}, got {self.refused!r}')
        n = len(self.features)
        if not (len(self.mean) == len(self.scale) == len(self.weights) == n):
            raise ValueError(f'ConfidenceModel: {n} features but {len(self.mean)} means, '
                             f'{len(self.scale)} scales and {len(self.weights)} weights')
        values = (*self.mean, *self.scale, *self.weights, self.intercept)
        if not all(math.isfinite(v) for v in values) or min(self.scale, default=1.0) <= 0.0:
            raise ValueError('ConfidenceModel: means, weights and the intercept must be finite '
                             'and scales > 0')

    def logit(self, values: dict[str, float]) -> float:
        """Return the log-odds of a right pose given the feature ``values`` by name."""
        z = self.intercept
        for name, m, s, w in zip(self.features, self.mean, self.scale, self.weights):
            z += w * (values[name] - m) / s
        return z

    def probability(self, values: dict[str, float]) -> float:
        """Return ``P(right | evidence)`` for the feature ``values`` by name."""
        z = self.logit(values)
        return 1.0 / (1.0 + math.exp(-z)) if z >= -700.0 else 0.0


#: fitted by ``scripts/learn_confidence.py`` on the calibration split
#: (``config/confidence_model.yaml``, 2026-11-25: 3203 answers the rules accept, 2654 right)
CONFIDENCE_MODEL = ConfidenceModel(
    features=('through', 'short', 'missing', 'on_wall',
              'unknown', 'unexplained_runs', 'explained', 'margin',
              'log_position_std', 'log_yaw_std', 'log_scan_length', 'log_extent'),
    mean=(
        0.061737884173253176, 0.059048039330351985, 0.040979810594234826,
        0.9465888174625001, 0.06542114338384186, 0.012606268610343125,
        0.8918968850280238, 0.4597411864774715, -2.9061719145890135,
        -4.3217732550686145, 2.415691351902958, 1.9726511730698846,
    ),
    scale=(
        0.0962014736204141, 0.09190130334598885, 0.1267887832878405,
        0.094754201162173, 0.08434103515138576, 0.05649760874817434,
        0.1026359272780082, 0.3110929128251355, 0.23013394607136886,
        0.423691626786044, 0.6011974902500591, 0.6712588041146128,
    ),
    weights=(
        -0.2913618314081437, 0.4917585288021092, -1.4196536846363943,
        0.5310622560133046, -0.4159795165987884, -0.3997737718022265,
        0.9953210093981333, 1.8550014926446705, -0.27040134214723727,
        -0.3527079763442606, 0.2738670465404719, 0.5396180376302737,
    ),
    intercept=3.9820817346704542,
    refused={'implausible': 0.0009, 'rival': 0.101, 'degenerate': 0.1111},
    split='calibration: intel, aces, fhw, depot, empty_room')
