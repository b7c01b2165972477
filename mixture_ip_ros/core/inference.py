"""What a fitted mixture of Interaction ProMPs says with the phase known (z = t / T): the
observation noise of the observed agent (eq. 4), the component evidence and posterior
(eqs. 11, 21), each demonstration's log-likelihood (eq. 6 with eq. 21, the held-out criterion
for K) and the controlled agent conditioned on the most probable component (eqs. 12-13).

:class:`PhaseKnownInference` is MixtureIProMP's base (core.mixture): it reads the fitted
attributes ``fit`` sets. With the phase unknown, core.online; with a warped phase,
core.warped.
"""

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from .checks import checked_observation
from .interaction import condition_on_observed, trajectory_distribution
from .noise import noise_factor
from .numerics import logsumexp_rows
from .phase import alpha_log_density
from .promp import ObservationStats, log_evidence, observation_stats, stack_stats, weight_posterior


class PhaseKnownInference:
    """Inference of a fitted MixtureIProMP with the phase known (see the module)."""

    @property
    def observed_noise_var_(self):
        """Sigma_D of eq. 4 per observed DOF: the learned noise variance of eq. 15 plus the
        online sensor noise; (P,) when tied, (K, P) per component."""
        return self.noise_var_[..., :self.n_observed_] + np.square(self.observation_noise)

    def observed_noise_var_at(self, interval: float):
        """:attr:`observed_noise_var_` for observations at least ``interval`` s apart: the
        learned variance of each DOF times how many samples its residuals stay correlated over
        at that spacing (core.noise: 1 for white residuals), plus the online sensor noise."""
        P = self.n_observed_
        factor = noise_factor(self.noise_time_[:P], self.sample_period_, interval)
        return self.noise_var_[..., :P] * factor + np.square(self.observation_noise)

    def observed_noise(self, k, interval=None):
        """Component k's (P,) :attr:`observed_noise_var_`, or its :meth:`observed_noise_var_at`
        ``interval``."""
        nv = (self.observed_noise_var_ if interval is None
              else self.observed_noise_var_at(interval))
        return nv if nv.ndim == 1 else nv[k]

    def component_log_evidence(self, z, Y_obs):
        """log p(D | k) for every component (the integral under eq. 11, eq. 21 with the observed
        agent's block), observed agent only."""
        self._check_fitted()
        z, Y_obs = checked_observation(z, Y_obs, self.n_observed_)
        do = self.n_observed_ * self.n_basis
        st = observation_stats(self.basis_, z, Y_obs)
        out = np.empty(self.n_components)
        for k in range(self.n_components):
            chol = linalg.cho_factor(self.covariances_[k][:do, :do], lower=True)
            out[k] = weight_posterior(st, self.means_[k][:do], chol, self.observed_noise(k))[2]
        return out

    def component_posterior(self, z, Y_obs, alpha=None):
        """Eq. 11: p(k | D) for observations Y_obs (m, P) of the observed agent at phases z.
        With ``alpha`` (1/T, known with the phase) also its evidence p(alpha | k)."""
        self._check_fitted()
        lp = np.log(self.weights_) + self.component_log_evidence(z, Y_obs)
        if alpha is not None:
            lp += alpha_log_density([alpha], self.alpha_mean_, self.alpha_std_ ** 2)[0]
        return np.exp(lp - logsumexp(lp))

    def score_demonstrations(self, demonstrations):
        """log p(D_i, alpha_i) of each demonstration, every DOF of both agents, phase known
        (z = t / T): eq. 6 over components with the marginal likelihood of eq. 21 in the space
        the mixture lives in (the stacked weights of both agents, under the learned noise of
        eq. 15) and the component's p(alpha | k). The held-out criterion for K.

        Both agents, because a pattern is a joint movement: where the patterns differ mostly in
        the controlled agent (the robot's posture for the same reach), the observed agent alone
        cannot tell a mixture from one broad Gaussian. Missing samples (NaN) are skipped."""
        self._check_fitted()
        demos = list(demonstrations)
        if not demos:
            return np.empty(0)
        D = self.n_observed_ + self.n_controlled_
        stats = []
        for demo in demos:
            Y = np.hstack([demo.observed, demo.controlled])
            if Y.shape[1] != D:
                raise ValueError(f'demonstration {demo.name!r} has {demo.n_observed_dofs} + '
                                 f'{demo.n_controlled_dofs} DOFs; the model has '
                                 f'{self.n_observed_} + {self.n_controlled_}')
            stats.append(observation_stats(self.basis_, demo.phase, Y))
        return self.score_statistics(stack_stats(stats),
                                     np.array([1.0 / demo.duration for demo in demos]))

    def score_statistics(self, stats: ObservationStats, alphas):
        """:meth:`score_demonstrations` of stacked statistics and their alpha = 1/T."""
        noise = np.broadcast_to(self.noise_var_, (self.n_components, self.noise_var_.shape[-1]))
        lp = np.log(self.weights_) + alpha_log_density(alphas, self.alpha_mean_,
                                                       self.alpha_std_ ** 2)
        for k in range(self.n_components):
            lp[:, k] += log_evidence(stats, self.means_[k], self.covariances_[k], noise[k])
        return logsumexp_rows(lp)

    def condition(self, z, Y_obs, component=None):
        """Eqs. 12-13: the most probable component (or ``component``) conditioned on D.

        Returns (k, mean, cov) of the stacked weights."""
        if component is None:
            component = int(np.argmax(self.component_posterior(z, Y_obs)))
        z, Y_obs = checked_observation(z, Y_obs, self.n_observed_)
        mean, cov = condition_on_observed(self.means_[component], self.covariances_[component],
                                          self.basis_, self.n_observed_, z, Y_obs,
                                          self.observed_noise(component))
        return component, mean, cov

    def predict_controlled(self, z, Y_obs, z_grid, alpha=1.0, component=None):
        """Controlled agent's trajectory distribution over ``z_grid`` given D (eq. 13)."""
        k, mean, cov = self.condition(z, Y_obs, component)
        dofs = range(self.n_observed_, self.n_observed_ + self.n_controlled_)
        out = trajectory_distribution(mean, cov, self.basis_, z_grid, alpha, dofs)
        out['component'] = k
        return out
