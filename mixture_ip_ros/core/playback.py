"""Playing a recording into an online estimator: which of a demonstration's samples an
estimator fed it absorbs, in what order, and what it predicts after each beginning of the
recording. Written once for the evaluations, training's calibrations and the phase warps.
The estimator is any object with OnlineEstimator's interface (core.online)."""

from typing import NamedTuple

import numpy as np

from .noise import decimated_rows


def observed_rows(demo) -> np.ndarray:
    """Indices of ``demo``'s samples with every observed DOF recorded: what an estimator fed
    the recording sees (OnlineEstimator.offer refuses a sample with a DOF missing)."""
    return np.flatnonzero(~np.isnan(demo.observed).any(axis=1))


def absorbed_rows(demo, min_interval: float) -> np.ndarray:
    """Indices of the samples of ``demo`` an estimator with decimation ``min_interval`` (s)
    absorbs when fed the whole recording from its onset: :func:`observed_rows`, the first of
    them and then each at least ``min_interval`` after the last one absorbed
    (core.noise.decimated_rows)."""
    rows = observed_rows(demo)
    return rows[decimated_rows(demo.t[rows], min_interval)]


def rest_rows(demo, t_cut: float) -> np.ndarray:
    """Indices of ``demo``'s samples after ``t_cut`` (s since onset) with the controlled agent
    recorded: where a prediction of the rest of the movement from its beginning is scored."""
    return np.flatnonzero((demo.t > t_cut + 1e-9) & ~np.isnan(demo.controlled).any(axis=1))


def prefixes(est, demo, cuts):
    """Play ``demo``'s observed agent to ``est`` from its onset as the estimator node would be
    fed it (OnlineEstimator.offer_many: offer() of each sample in turn), stopping at each of
    the increasing ``cuts`` (s since onset): a generator that resets ``est`` and, after the
    samples up to each cut are in, yields that cut (the estimator then holds that beginning of
    the recording). The one way every evaluation, calibration and bench plays a recording to
    the estimator."""
    est.reset()
    rows = observed_rows(demo)
    t = demo.t[rows]
    j = 0
    for t_max in cuts:
        end = int(np.searchsorted(t, t_max + 1e-9, side='right'))
        if end > j:
            est.offer_many(t[j:end], demo.observed[rows[j:end]])
            j = end
        yield t_max


def played_to(est, demo, t_max):
    """:func:`prefixes` to one cut: ``est`` reset and fed ``demo`` up to ``t_max`` s."""
    for _ in prefixes(est, demo, (t_max,)):
        pass


class Prefix(NamedTuple):
    """What :func:`prefix_predictions` makes of one beginning of a recording."""

    component: int          # the MAP component k*
    controlled: object      # its expected controlled path at ``rest`` (m, Q), None if m = 0
    rest: np.ndarray        # the samples after the beginning with the controlled agent recorded
    alpha: float            # k*'s MAP phase speed (1/s): the phase estimated at t is alpha t


def prefix_predictions(est, demo, fractions) -> list:
    """What the estimator node makes of ``demo`` from its beginning, the phase unknown: the
    OnlineEstimator ``est``, reset, fed the observed agent sample by sample and, after the
    first f T of the movement for each of the increasing ``fractions``, a :class:`Prefix`:
    the MAP component, the controlled agent's expected path under it
    (OnlineEstimator.expected_controlled) at the samples after f T where it was recorded, and
    the MAP phase speed. One estimator serves every recording of a model."""
    out = []
    for f, _ in zip(fractions, prefixes(est, demo, np.multiply(fractions, demo.duration))):
        rest = rest_rows(demo, f * demo.duration)
        k, alpha = est.map_hypothesis()
        pred = (est.expected_controlled(demo.t[rest], component=k, derivatives=False)[1]
                if rest.size else None)
        out.append(Prefix(int(k), pred, rest, float(alpha)))
    return out
