"""A fitted mixture's phase warps (the thesis's eq. 34, core.warp): each component's Gaussian
over a monotone warp of the phase, learned from the demonstrations the mixture was fitted to
(:class:`PhaseWarps`), the component posterior with each component's warp integrated out, and
the held-out criterion training chooses between the warped and the linear phase with.

A mixture holds its warps as ``model.warps_`` (None: the linear phase z = t / T everywhere).
"""

from typing import NamedTuple

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from .checks import checked_observation
from .demonstration import Demonstration
from .phase import alpha_log_density
from .playback import absorbed_rows
from .promp import cho_inverse, feature_stats, weight_posterior
from .warp import N_WARP, START_SD, WarpAt, laplace, learn_warp_priors, map_warp


class ObservedPrior(NamedTuple):
    """Component k's Gaussian over the observed agent's weights (P N,) as its warp evidence
    takes it, computed once for all of k's recordings (:func:`observed_prior`)."""

    mean: np.ndarray        # (P N,)
    chol: tuple             # lower Cholesky factor of the covariance (scipy cho_factor)
    precision: np.ndarray   # (P N, P N)


def observed_prior(model, k) -> ObservedPrior:
    """:class:`ObservedPrior` of ``model``'s component k."""
    do = model.n_observed_ * model.n_basis
    chol = linalg.cho_factor(model.covariances_[k][:do, :do], lower=True)
    return ObservedPrior(model.means_[k][:do], chol, cho_inverse(chol))


def warp_spacing(model) -> float:
    """How far apart (s) the samples a warp is read from are: as far as ``model``'s observed
    agent's residuals stay correlated, so that each is worth one observation at that spacing
    (core.noise); closer ones would count the same deviation many times and make every warp
    look certain."""
    model._check_fitted()
    return float(np.max(model.noise_time_[:model.n_observed_], initial=0.0))


def reading_interval(model, min_interval) -> float:
    """The spacing (s) a recording's warp is read at: :func:`warp_spacing`, at least
    ``min_interval`` (the online estimator's decimation)."""
    try:
        interval = float(min_interval)
    except (TypeError, ValueError):
        interval = np.nan
    if not (np.isfinite(interval) and interval >= 0):
        raise ValueError(f'min_interval must be a number of seconds >= 0, got '
                         f'{min_interval!r}')
    return max(warp_spacing(model), interval)


def warp_reading(demo, interval):
    """(relative times (m,), observed agent (m, P)) of the samples of ``demo`` an estimator
    with decimation ``interval`` absorbs (core.playback.absorbed_rows)."""
    rows = absorbed_rows(demo, interval)
    return demo.phase[rows], demo.observed[rows]


class WarpEvidence:
    """b -> (log p(D | k, b), its gradient (N_WARP,)): the observed agent Y_obs (m, P) at
    relative times ``u`` (m,) sampled at least ``interval`` s apart (eq. 21, under the noise
    of such samples: MixtureIProMP.observed_noise_var_at), at phases z = g(u; b), under
    component k's weights (``prior``: :func:`observed_prior`, None: made here). The gradient
    is the posterior expectation of the complete data's: d log p(D) / d psi_i =
    sum_j ((y_ij - psi_i^T m_j) m_j - S_j psi_i) / sigma_j^2 (m_j, S_j the posterior mean and
    covariance of DOF j's weights), through psi's derivative and dz / db (core.warp).

    The last b and its answer are kept: Laplace's method asks again at the mode the
    optimiser ended on."""

    def __init__(self, model, k, u, Y_obs, interval, prior=None):
        self.basis = model.basis_
        self.P, self.N = model.n_observed_, model.n_basis
        self.mean, self.chol, self.precision = (observed_prior(model, k) if prior is None
                                                else prior)
        self.noise = model.observed_noise(k, interval)
        self.Y_obs = Y_obs
        self.Y = np.nan_to_num(Y_obs)
        self.weight = ~np.isnan(Y_obs) / self.noise                # (m, P): 0 where missing
        self.at = WarpAt(u)
        self.last_b = self.last = None

    def __call__(self, b):
        if self.last_b is not None and np.array_equal(b, self.last_b):
            return self.last
        P, N = self.P, self.N
        z, dz = self.at(b)
        psi, dpsi = self.basis.evaluate(z, order=1)
        m, S, ll = weight_posterior(feature_stats(psi, self.Y_obs), self.mean, self.chol,
                                    self.noise, self.precision)
        M = m.reshape(P, N)
        blocks = S.reshape(P, N, P, N)[np.arange(P), :, np.arange(P)]         # S_j, (P, N, N)
        dll = (((self.Y - psi @ M.T) * self.weight) @ M
               - np.einsum('ij,jik->ik', self.weight, psi @ blocks))
        self.last_b = np.array(b, dtype=float)
        self.last = ll, dz.T @ np.einsum('in,in->i', dpsi, dll)
        return self.last


class PhaseWarps:
    """Each component's Gaussian over a monotone phase warp b (core.warp): a demonstration of
    component k is at phase z = g(t / T; b), b ~ N(mean_[k], diag(sd_[k]^2)).

    ``min_interval`` (s): each recording is read at samples at least this far apart (the
    online estimator's decimation: a warp is learned from the evidence it will be used on)
    and as far apart as its residuals stay correlated (:func:`warp_spacing`). ``fit`` learns
    ``mean_``, ``sd_`` (K, N_WARP) and ``failed_``, the names (else indices) of the
    demonstrations whose warp fit did not converge (left out of the Gaussian)."""

    def __init__(self, min_interval: float = 0.05):
        self.min_interval = min_interval

    def fit(self, model, demonstrations):
        """Learn the Gaussians from ``demonstrations``, the ones ``model`` was fitted to, in
        that order: each one's observed agent at phase z = g(t / T; b), b its MAP under its
        most probable component (``model.resp_``), each component's Gaussian learned from its
        members' warps by EM (core.warp.learn_warp_priors). Returns self."""
        model._check_fitted()
        if not hasattr(model, 'resp_'):
            raise ValueError('the phase warps need the responsibilities of a fit; a model read '
                             'from a file has none (fit it again)')
        demos = list(demonstrations)
        if len(demos) != len(model.resp_) or not all(isinstance(d, Demonstration)
                                                      for d in demos):
            raise ValueError(f'the phase warps need the {len(model.resp_)} Demonstrations the '
                             f'model was fitted to, got {len(demos)}')
        component = np.argmax(model.resp_, axis=1)
        interval = reading_interval(model, self.min_interval)
        priors = [observed_prior(model, k) for k in range(model.n_components)]
        evidences = [WarpEvidence(model, k, *warp_reading(d, interval), interval, priors[k])
                     for d, k in zip(demos, component)]
        self.mean_, self.sd_, good = learn_warp_priors(evidences, component, model.n_components)
        self.failed_ = [d.name if d.name else i for i, d in enumerate(demos) if not good[i]]
        return self

    def gains(self, model, demonstrations) -> np.ndarray:
        """How much better each demonstration's observed agent is predicted with a phase warp
        than at the linear phase (nats (n,); positive: the warp predicts it better), for
        demonstrations held out from ``model``: log int p(D | k, b) N(b; 0, START_SD^2 I) db
        (Laplace, core.warp) - log p(D | k, b = 0), under k, its most probable component at
        the linear phase, read as :meth:`fit` reads a recording. The warp at the Gaussian
        :meth:`fit` starts from: the criterion needs no warps learned, and so no learning per
        fold. Training's held-out choice of the phase."""
        model._check_fitted()
        demos = list(demonstrations)
        if not all(isinstance(d, Demonstration) for d in demos):
            raise ValueError('the warp gains need Demonstrations')
        interval = reading_interval(model, self.min_interval)
        priors = [observed_prior(model, k) for k in range(model.n_components)]
        start = np.zeros(N_WARP), np.full(N_WARP, START_SD)
        gains = np.zeros(len(demos))
        for i, d in enumerate(demos):
            reading = warp_reading(d, interval)
            evidences = [WarpEvidence(model, k, *reading, interval, priors[k])
                         for k in range(model.n_components)]
            # A recording whose evidence or warp cannot be computed, or whose warp fit did not
            # converge, counts as no gain: it argues for neither phase.
            try:
                linear = np.array([f(start[0])[0] for f in evidences])
                k = int(np.argmax(np.log(model.weights_) + linear + alpha_log_density(
                    [1.0 / d.duration], model.alpha_mean_, model.alpha_std_ ** 2)[0]))
                b, converged = map_warp(evidences[k], *start, gradient=True)
                gain = laplace(evidences[k], b, *start)[0] - linear[k] if converged else 0.0
            except (ValueError, np.linalg.LinAlgError):
                gain = 0.0
            gains[i] = gain if np.isfinite(gain) else 0.0
        return gains

    def component_posterior(self, model, u, Y_obs, alpha=None, interval=None):
        """Eq. 11 with each component's own phase: observations Y_obs (m, P) of ``model``'s
        observed agent at relative times ``u`` = t / T (the movement's end known), at least
        ``interval`` s apart (the noise of such samples, MixtureIProMP.observed_noise_var_at;
        None: the recordings' own rate, as MixtureIProMP.component_posterior), under
        component k at phase g(u; b), the warp integrated out under k's Gaussian over it by
        Laplace's method at its MAP b_k (core.warp.laplace): p(k | D) ~ p(k) int p(D | k, b)
        p(b | k) db, with ``alpha`` = 1/T also p(alpha | k). Returns (p(k | D) (K,),
        b (K, N_WARP)). A component whose evidence cannot be computed at its mode (a
        numerical failure) gets probability 0; if every one does, ValueError."""
        model._check_fitted()
        if not hasattr(self, 'mean_'):
            raise ValueError('no phase warp learned: fit the PhaseWarps first')
        u, Y_obs = checked_observation(u, Y_obs, model.n_observed_)
        lp, b = np.log(model.weights_), np.empty((model.n_components, N_WARP))
        for k in range(model.n_components):
            evidence = WarpEvidence(model, k, u, Y_obs, interval)
            prior = self.mean_[k], self.sd_[k]
            b[k] = map_warp(evidence, *prior, gradient=True)[0]
            try:
                lp[k] += laplace(evidence, b[k], *prior)[0]
            except (ValueError, np.linalg.LinAlgError):
                lp[k] = -np.inf
        lp[~np.isfinite(lp)] = -np.inf
        if not np.isfinite(lp).any():
            raise ValueError('no component can explain these observations at any warp')
        if alpha is not None:
            lp += alpha_log_density([alpha], model.alpha_mean_, model.alpha_std_ ** 2)[0]
        return np.exp(lp - logsumexp(lp)), b
