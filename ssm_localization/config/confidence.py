"""
The calibrated confidence model: ``P(right | evidence)``.

A logistic regression weighs the evidence of an answer into one score (its log-odds); an
isotonic (monotone, piecewise-linear) map, fitted on scores of buildings the regression did not
see, turns the score into a probability. ``scripts/learn_confidence.py`` fits both on labelled
answers of the calibration split (right poses, wrong places in the same building, scans of other
buildings) and writes ``config/confidence_model.yaml``; :data:`CONFIDENCE_MODEL` is copied from
that file (a test checks they agree). The paper itself learns its pairwise potentials by
logistic regression (section II.B); here the same tool weighs the evidence of a whole answer.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

#: what "right" means wherever a confidence is fitted or measured: within this of the truth
RIGHT_XY = 0.5                      # metres
RIGHT_YAW = math.radians(5.0)       # radians
#: reasons the rules refuse an answer before the model is asked, with a neutral rate
REFUSED_REASONS = {'implausible': 0.0, 'rival': 0.5, 'degenerate': 0.5}


@dataclass(frozen=True)
class ConfidenceModel:
    """
    ``P(right) = 1 / (1 + exp(-(intercept + sum_k w_k (f_k - mean_k) / scale_k)))``.

    ``features`` name the inputs (see ``localization/confidence.py`` for how each is made from
    the evidence of an answer); ``calibration`` the isotonic map from that log-odds to the
    probability, as ``(log-odds, probability)`` knots in increasing order, interpolated linearly
    and held constant beyond the ends (empty: the logistic probability itself); ``split`` names
    the data it was fitted on.
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
    calibration: tuple[tuple[float, float], ...] = ()
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
        knots = [v for k in self.calibration for v in k]
        pairs = list(zip(self.calibration, self.calibration[1:]))
        if (any(len(k) != 2 for k in self.calibration)
                or not all(0.0 <= p <= 1.0 for _, p in self.calibration)
                or any(a[0] > b[0] or a[1] > b[1] for a, b in pairs)):
            raise ValueError('ConfidenceModel.calibration: (log-odds, probability) knots, both '
                             'increasing, probabilities in [0, 1]')
        values = (*self.mean, *self.scale, *self.weights, self.intercept, *knots)
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


#: fitted by ``scripts/learn_confidence.py`` on the calibration split
#: (``config/confidence_model.yaml``, 2026-11-25: 3203 answers the rules accept, 2654 right)
CONFIDENCE_MODEL = ConfidenceModel(
    features=('through', 'short', 'missing',
              'on_wall', 'unknown', 'unexplained_runs',
              'explained', 'margin', 'log_position_std',
              'log_yaw_std', 'log_scan_length', 'log_extent'),
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
        -0.30288661696267766, 0.4417321462560222, -1.337595961415421,
        0.5284667825502662, -0.40136689342186527, -0.36165228135918176,
        0.8859437213098846, 1.7960709879717838, -0.22599870865186175,
        -0.3931027027533198, 0.3038628595345358, 0.48360244883349496,
    ),
    intercept=4.21991077920179,
    refused={'implausible': 0.0015, 'rival': 0.1205, 'degenerate': 0.1421},
    calibration=(
        (-6.2884769908339, 0.003765985825247809),
        (-3.2841775126653543, 0.1134995700773862),
        (-2.1747546438726273, 0.1477622543215724),
        (-1.4411402488219238, 0.19289026275115917),
        (-0.6390223087131153, 0.30188679245283034),
        (0.26429176265076254, 0.46369449861671735),
        (0.8764423880968771, 0.7357926221335991),
        (1.2231698344389301, 0.7722369475436108),
        (1.563903483989717, 0.8910994158810942),
        (1.847965458309947, 0.9254092057563441),
        (2.2446111875734767, 0.9424509140148952),
        (2.552026682223251, 0.9424509140148952),
        (2.7219352371068273, 0.9601954596355493),
        (3.1553049019642097, 0.9866989117291415),
        (3.8461675338308194, 0.9866989117291415),
        (4.8661983106242745, 0.9952673019376471),
        (7.793746886497953, 0.9995951417004049),
    ),
    split='calibration: intel, aces, fhw, depot, empty_room')

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
