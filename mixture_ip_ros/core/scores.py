"""How well a fitted Mixture of Interaction ProMPs predicts demonstrations it did not learn
from, each score a held-out criterion of core.selection and the evaluations:

- :func:`controlled_rms`, the thesis's error of the controlled agent given the observed one
  (Figs. 8 and 10), and its batched form for many demonstrations at once (:func:`final_rms`);
- :func:`online_scores`, the controlled agent predicted and the pattern named online from the
  observed agent's beginning, the phase unknown, as the estimator node does;
- :func:`score_completion`, the rest of a demonstration predicted from its beginning, the
  phase known (the single-agent criterion).
"""

from typing import NamedTuple

import numpy as np

from .demonstration import Demonstration
from .interaction import trajectory_distribution
from .numerics import logsumexp_rows
from .online import OnlineEstimator
from .phase import alpha_log_density
from .playback import observed_rows, prefix_predictions
from .promp import ObservationStats, log_evidence, observation_stats, stack_stats

# Where the completion criterion cuts a held-out demonstration into the beginning it observes
# and the rest it predicts: the fractions recognition is reported at (app.evaluation), spread
# over the movement so that no single cut decides.
COMPLETION_FRACTIONS = (0.3, 0.5, 0.7)


def beginning_stats(basis, demos, fractions):
    """Per fraction f, the stacked statistics of every demonstration's beginning: its samples
    (every DOF of both agents) at phases z <= f."""
    out = []
    for f in fractions:
        out.append(stack_stats([observation_stats(basis, d.phase[d.phase <= f],
                                                  np.hstack([d.observed, d.controlled])[
                                                      d.phase <= f]) for d in demos]))
    return out


def checked_fractions(fractions):
    """``fractions`` as a tuple of numbers in (0, 1) (a clear error otherwise)."""
    f = np.atleast_1d(np.asarray(fractions, dtype=float))
    if f.ndim != 1 or f.size == 0 or not np.all((f > 0) & (f < 1)):
        raise ValueError(f'fractions must be numbers in (0, 1), got {fractions!r}')
    return tuple(float(x) for x in f)


def controlled_rms(model, demo: Demonstration, observe: str = 'final'):
    """RMS error of the predicted controlled trajectory of ``demo`` over its own samples."""
    z = demo.phase
    rows = observed_rows(demo)
    if observe == 'final':
        rows = rows[-1:]
    elif observe != 'full':
        raise ValueError(f"observe must be 'final' or 'full', got {observe!r}")
    k, mean, _ = model.condition(z[rows], demo.observed[rows])
    dofs = range(model.n_observed_, model.n_observed_ + model.n_controlled_)
    pred = trajectory_distribution(mean, None, model.basis_, z, dofs=dofs)['position']
    ok = ~np.isnan(demo.controlled).any(axis=1)
    return float(np.sqrt(np.mean((pred[ok] - demo.controlled[ok]) ** 2)))


class FinalView(NamedTuple):
    """What :func:`controlled_rms` (observe='final') needs of each demonstration, whatever model
    it is scored under: the basis at its final observed sample ``phi`` (n, N) and that sample
    ``y`` (n, P); per demonstration the basis at its samples with the controlled agent observed
    ``psi`` and those samples ``yc``. Cross-validation computes it once for every fold."""

    phi: np.ndarray
    y: np.ndarray
    psi: list
    yc: list


def final_views(basis, demos) -> FinalView:
    """The :class:`FinalView` of ``demos`` under ``basis``."""
    rows = [observed_rows(d)[-1] for d in demos]
    ok = [~np.isnan(d.controlled).any(axis=1) for d in demos]
    return FinalView(basis(np.array([d.phase[r] for d, r in zip(demos, rows)])),
                     np.array([d.observed[r] for d, r in zip(demos, rows)]),
                     [basis(d.phase[m]) for d, m in zip(demos, ok)],
                     [d.controlled[m] for d, m in zip(demos, ok)])


def final_rms(model, view: FinalView, idx) -> np.ndarray:
    """:func:`controlled_rms` (observe='final') of the demonstrations ``idx`` of ``view`` at
    once: one observation, so the Kalman form of eq. 4 (a P x P innovation per component)
    gives the evidence of eq. 11 and the conditional mean of eq. 13 directly."""
    idx = np.asarray(idx)
    P, N = model.n_observed_, model.n_basis
    do, K = P * N, model.n_components
    phi, y = view.phi[idx], view.y[idx]                                    # (m, N), (m, P)
    mu, cov = model.means_, model.covariances_
    hm = np.einsum('kpn,in->ikp', mu[:, :do].reshape(K, P, N), phi)        # H mu, (m, K, P)
    SH = np.einsum('kdpn,in->ikdp', cov[:, :, :do].reshape(K, -1, P, N), phi)  # Sigma H^T
    S = np.einsum('ikpnq,in->ikpq', SH[:, :, :do].reshape(len(idx), K, P, N, P), phi)
    nv = model.observed_noise_var_
    S = S + (np.eye(P) * nv[..., None, :])                       # (P,) tied or (K, P) each
    r = y[:, None, :] - hm
    chol = np.linalg.cholesky(S)
    u = np.linalg.solve(chol, r[..., None])[..., 0]
    logdet = 2 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)
    lp = np.log(model.weights_) - 0.5 * ((u ** 2).sum(axis=-1) + logdet)
    k = np.argmax(lp, axis=1)
    m = np.arange(len(idx))
    gain = np.linalg.solve(S[m, k], r[m, k][..., None])[..., 0]            # S^-1 (y - H mu)
    mean = mu[k] + np.einsum('idp,ip->id', SH[m, k], gain)
    out = np.empty(len(idx))
    for j, i in enumerate(idx):
        pred = view.psi[i] @ mean[j, do:].reshape(-1, N).T
        out[j] = np.sqrt(np.mean((pred - view.yc[i]) ** 2)) if len(pred) else np.nan
    return out


class OnlineScores(NamedTuple):
    """:func:`online_scores` of each demonstration (n,): ``rms`` of the controlled agent, NaN
    for one with nothing left to predict; ``named``, the share of its beginnings whose MAP
    component names its pattern."""

    rms: np.ndarray
    named: np.ndarray


def online_scores(model, demos, patterns=None, names=None, fractions=None,
                  n_alpha: int = 50, min_interval: float = 0.05) -> OnlineScores:
    """How well ``model`` does online what the estimator node does with each of ``demos``:
    after the first f T of the observed agent (phase unknown) for each ``fraction`` f (default
    COMPLETION_FRACTIONS), averaged over the fractions,

    - ``rms``: the MAP component's expected path of the controlled agent over the rest of the
      movement (core.playback.prefix_predictions) against the recorded one, the RMS over the
      rest's samples and DOFs (NaN without a controlled agent or anything left to predict);
    - ``named``: whether the MAP component is one that ``names`` (K,) gives the
      demonstration's pattern ``patterns`` (n,), the decision the estimator takes (NaN without
      ``patterns``)."""
    fractions = checked_fractions(COMPLETION_FRACTIONS if fractions is None else fractions)
    if (patterns is None) != (names is None):
        raise ValueError('online_scores names patterns with both patterns and names, or neither')
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    rms, named = np.full(len(demos), np.nan), np.full(len(demos), np.nan)
    for i, demo in enumerate(demos):
        beginnings = prefix_predictions(est, demo, fractions)
        errors = [np.sqrt(np.mean((p.controlled - demo.controlled[p.rest]) ** 2))
                  for p in beginnings if p.controlled is not None]
        if errors:
            rms[i] = np.mean(errors)
        if patterns is not None:
            named[i] = np.mean([names[p.component] == patterns[i] for p in beginnings])
    return OnlineScores(rms, named)


def online_rms(model, demos, fractions=None, n_alpha: int = 50,
               min_interval: float = 0.05) -> np.ndarray:
    """:func:`online_scores`' RMS of the controlled agent predicted online, (len(demos),)."""
    return online_scores(model, demos, fractions=fractions, n_alpha=n_alpha,
                         min_interval=min_interval).rms


def score_completion(model, demonstrations, fractions=None):
    """How well ``model`` (a fitted MixtureIProMP) predicts the rest of each demonstration from
    its beginning, the phase known (z = t / T, so alpha = 1/T too), for every ``fraction`` f
    (default COMPLETION_FRACTIONS): the beginning B is the samples at z <= f, the rest R those
    at z > f, every DOF of both agents. Returns (log_density, rms), each (n, len(fractions)):

    - log p(R | B, alpha) = log p(R, B, alpha) - log p(B, alpha) under the mixture (eq. 6
      with eq. 21 and p(alpha | k)): the predictive density of the rest, each component
      weighted by its posterior given the beginning (eq. 11);
    - the RMS error of the rest predicted as the thesis predicts (eqs. 12-13): the most
      probable component given B and alpha, conditioned on B, its mean at the rest's
      phases; over every DOF of the rest in the DOF's own unit (comparable across K, not
      across data sets).
    """
    model._check_fitted()
    fractions = checked_fractions(COMPLETION_FRACTIONS if fractions is None else fractions)
    demos = list(demonstrations)
    D = model.n_observed_ + model.n_controlled_
    for demo in demos:
        if demo.n_observed_dofs + demo.n_controlled_dofs != D:
            raise ValueError(f'demonstration {demo.name!r} has {demo.n_observed_dofs} + '
                             f'{demo.n_controlled_dofs} DOFs; the model has '
                             f'{model.n_observed_} + {model.n_controlled_}')
    full = stack_stats([observation_stats(model.basis_, d.phase,
                                          np.hstack([d.observed, d.controlled]))
                        for d in demos])
    return completion_statistics(model, full, beginning_stats(model.basis_, demos, fractions),
                                  np.array([1.0 / d.duration for d in demos]))


def completion_statistics(model, full: ObservationStats, beginnings, alphas):
    """The :func:`score_completion` of stacked statistics of the whole demonstrations, of
    their beginnings (one stack per fraction) and their alpha = 1/T."""
    K, D = model.n_components, model.n_observed_ + model.n_controlled_
    N = model.n_basis
    n = len(alphas)
    noise = np.broadcast_to(model.noise_var_, (K, D))
    prior = np.log(model.weights_) + alpha_log_density(alphas, model.alpha_mean_,
                                                      model.alpha_std_ ** 2)
    whole = prior + np.column_stack([log_evidence(full, model.means_[k], model.covariances_[k],
                                                  noise[k]) for k in range(K)])
    log_whole = logsumexp_rows(whole)
    density = np.empty((n, len(beginnings)))
    rms = np.empty((n, len(beginnings)))
    for c, begin in enumerate(beginnings):
        lp = prior.copy()
        post = np.empty((K, n, D * N))
        for k in range(K):
            ll, post[k] = log_evidence(begin, model.means_[k], model.covariances_[k], noise[k],
                                       posterior_means=True)
            lp[:, k] += ll                                                  # eq. 11
        density[:, c] = log_whole - logsumexp_rows(lp)
        w = post[np.argmax(lp, axis=1), np.arange(n)].reshape(n, D, N)     # eqs. 12-13
        # The rest's statistics are the whole's minus the beginning's (sums over samples).
        G, b = full.G - begin.G, full.b - begin.b
        sq = (full.yy - begin.yy - 2 * np.einsum('ijn,ijn->ij', w, b)
              + np.einsum('ijn,ijnk,ijk->ij', w, G, w))
        m = (full.m - begin.m).sum(axis=1)
        rms[:, c] = np.sqrt(np.maximum(sq.sum(axis=1), 0.0) / np.maximum(m, 1.0))
    return density, rms
