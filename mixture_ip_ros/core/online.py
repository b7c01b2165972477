"""Online estimation of the interaction pattern and its phase (chapter 5 future work): the
recursive posterior p(k, alpha | D) over mixture components k and phase-speed hypotheses
alpha (core.recursive), and what it predicts of both agents.

The controlled agent is recovered exactly only when asked for: since D depends on the
observed weights alone, w_c | D follows from w_o | D through B_k = Sigma_co Sigma_oo^-1.
Between and beyond the grid of phase speeds, the samples absorbed give any hypothesis exactly
(:meth:`OnlineEstimator.posterior_at`), and the posterior once the movement's end time is
known (:meth:`OnlineEstimator.end_posterior`).
"""

import numpy as np
from scipy import linalg

from ._fast import basis_rows, expected_trajectory, mean_trajectory
from .interaction import trajectory_distribution
from .noise import decimated_rows
from .promp import observation_stats, weight_posterior
from .recursive import RecursivePosterior
from .warped import reading_interval


# Phase speeds, or components, less probable than this times the most probable one are left
# out of the expected path (supported).
SPEED_SUPPORT = 1e-3


def supported(p):
    """The hypotheses that hold a distribution ``p`` (probabilities, or weights of any scale):
    (indices, probabilities renormalised over them). One less probable than SPEED_SUPPORT times
    the most probable is left out: its share of a prediction is below that, and each one kept
    costs a trajectory."""
    keep = np.flatnonzero(p >= SPEED_SUPPORT * p.max())
    return keep, p[keep] / p[keep].sum()


class OnlineEstimator(RecursivePosterior):
    """The online estimator: p(k, alpha | D) for a fitted :class:`MixtureIProMP` updated per
    observation (core.recursive.RecursivePosterior: decimation ``min_interval`` (s), the grid
    of ``n_alpha`` phase speeds over ``alpha_range_std`` prior standard deviations, pruning
    below ``prune_below``, the rate of changes of mind ``switch_rate``: None, the model's), and
    the trajectories of both agents it predicts."""

    def __init__(self, model, n_alpha: int = 50, min_interval: float = 0.05,
                 alpha_range_std: float = 3.0, prune_below: float = 0.0,
                 switch_rate: float = None):
        super().__init__(model, n_alpha, min_interval, alpha_range_std, prune_below,
                         switch_rate)
        do = self.n_observed * self.n_basis
        # Regression of controlled on observed weights per component (exact conditioning).
        self._gain, self._cond_cov = [], []
        for k in range(self.n_components):
            C = model.covariances_[k]
            if C.shape[0] == do:            # no controlled agent: nothing to regress
                B = np.zeros((0, do))
            else:
                B = linalg.cho_solve(linalg.cho_factor(C[:do, :do], lower=True), C[:do, do:]).T
            self._gain.append(B)
            self._cond_cov.append(C[do:, do:] - B @ C[:do, do:])

    def controlled_mean(self, k, mu_o):
        """Mean of the controlled agent's weights (Q*N,) under component ``k`` given a mean
        ``mu_o`` (P*N,) of the observed agent's, or one per row (eq. 13's conditional mean,
        through the regression B_k of controlled on observed weights), for instance that of
        :meth:`posterior_at` at any alpha."""
        prior_mean = self.model.means_[k]
        do = mu_o.shape[-1]
        return prior_mean[do:] + (mu_o - prior_mean[:do]) @ self._gain[k].T

    def posterior_at(self, component, alpha):
        """Posterior N(mean, cov) of the observed agent's weights and log p(D | k, alpha) under
        ``component`` k and any phase speed ``alpha`` > 0, from the samples absorbed (eqs.
        17-18 in batch, z_i = alpha t_i): what the recursive state of a grid hypothesis holds,
        for an alpha the grid does not hold. Raises ValueError before any observation."""
        k = int(component)
        if not 0 <= k < self.n_components:
            raise ValueError(f'component must be in [0, {self.n_components}), got {component}')
        if not (np.isfinite(alpha) and alpha > 0):
            raise ValueError(f'alpha must be a positive number, got {alpha!r}')
        if not self._times:
            raise ValueError('no observation absorbed yet')
        model = self.model
        do = self.n_observed * self.n_basis
        stats = observation_stats(model.basis_, float(alpha) * np.asarray(self._times),
                                  np.asarray(self._values))
        return weight_posterior(stats, model.means_[k][:do],
                                linalg.cho_factor(model.covariances_[k][:do, :do], lower=True),
                                model.observed_noise(k, self.min_interval))

    def end_posterior(self, t_end: float):
        """p(k | D, T = t_end): the component posterior once the movement's end time is known
        (the observer's 'end' event, ``t_end`` s after onset), where its phase is 1, so
        alpha = 1/t_end exactly: p(k) p(alpha | k) p(D | k, alpha) normalised over k (eqs. 11,
        17-18 at that alpha; the Jacobian from T to alpha is the same for every k). Without
        phase warps in the model this is the batch posterior with the phase known
        (MixtureIProMP.component_posterior with alpha) from the samples absorbed; with them
        (``model.warps_``, core.warped.PhaseWarps), each component's warp is integrated out
        (PhaseWarps.component_posterior) over the samples spaced as training read the warps:
        a pace that changed within the movement does not misplace the phase.
        Samples after ``t_end`` are taken at phase 1: the end is dated back to when the hand
        stopped, and after it the hand is at rest where the movement ended. With changes of
        mind (``switch_rate`` > 0, core.switching) too: the change points' segments start
        their phase lines where the phase was believed, which the end time does not correct,
        and a belief that moves at the movement's end moves on the ending several patterns
        share. Raises ValueError without samples or for a t_end that is not positive."""
        if not self._times:
            raise ValueError('no observation absorbed yet')
        if not (np.isfinite(t_end) and t_end > 0):
            raise ValueError(f'the end time must be a positive number of seconds, got {t_end!r}')
        alpha = 1.0 / float(t_end)
        t, Y = np.asarray(self._times), np.asarray(self._values)
        if self.model.warps_ is not None:
            # Samples read as training read each recording's warp (PhaseWarps.fit), at this
            # estimator's decimation.
            spacing = reading_interval(self.model, self.min_interval)
            order = np.argsort(t, kind='stable')
            rows = order[decimated_rows(t[order], spacing)]
            try:
                p = self.model.warps_.component_posterior(
                    self.model, np.minimum(alpha * t[rows], 1.0), Y[rows], alpha, spacing)[0]
            except (ValueError, np.linalg.LinAlgError):
                p = None
            if p is not None and np.all(np.isfinite(p)):
                return p
            # A numerical failure of every warp: the linear phase still gives an answer.
        return self.model.component_posterior(np.minimum(alpha * t, 1.0), Y, alpha=alpha)

    def predict(self, z_grid, component=None, alpha=None, covariance: bool = True):
        """Conditioned trajectories under (k*, alpha*) (or the given ones) at phases ``z_grid``.

        Returns a dict: 'time' (s since onset = z / alpha), 'component', 'alpha', 'controlled'
        and 'observed', each a dict of 'position', 'velocity', 'acceleration' (len, n) and
        'position_cov' (len, n, n) (omitted with ``covariance=False``).
        """
        k, m = self._hypothesis(component, alpha)
        a = float(self.alphas[m])
        mu_o, sig_o = self.observed_weights(k, m)
        mean_c = self.controlled_mean(k, mu_o)
        cov_c = None
        if covariance:
            B = self._gain[k]
            cov_c = self._cond_cov[k] + B @ sig_o @ B.T
            cov_c = 0.5 * (cov_c + cov_c.T)
        z_grid = np.asarray(z_grid, dtype=float)
        ctrl = trajectory_distribution(mean_c, cov_c, self.model.basis_, z_grid, a)
        obs = trajectory_distribution(mu_o, sig_o if covariance else None, self.model.basis_,
                                      z_grid, a)
        return {'time': z_grid / a, 'component': k, 'alpha': a, 'controlled': ctrl,
                'observed': obs}

    def mean_trajectories(self, z_controlled, z_observed=(), component=None, alpha=None):
        """The means of :meth:`predict` without its covariances, for robot commands: (k, alpha,
        controlled (position, velocity, acceleration) at phases ``z_controlled``, observed
        positions at ``z_observed``). Same defaults and grid snapping as predict."""
        k, m = self._hypothesis(component, alpha)
        a = float(self.alphas[m])
        basis = self.model.basis_
        mu_o = self._observed_mean(k, m)
        # Only what is asked for (the estimator node asks for one agent at a time).
        z_c = np.asarray(z_controlled, dtype=float)
        if z_c.size:
            controlled = mean_trajectory(self.controlled_mean(k, mu_o).reshape(
                -1, self.n_basis), z_c, basis.centers, basis.width, a)
        else:
            controlled = tuple(np.zeros((0, self.model.n_controlled_)) for _ in range(3))
        z_o = np.asarray(z_observed, dtype=float)
        if z_o.size:
            observed = (basis_rows(z_o, basis.centers, basis.width)
                        @ mu_o.reshape(-1, self.n_basis).T)
        else:
            observed = np.zeros((0, self.n_observed))
        return k, a, controlled, observed

    def speed_hypotheses(self, component=None):
        """The phase speeds that hold component k's (k* if None) tempered posterior: (grid
        indices, probabilities renormalised over them): :func:`supported`."""
        k = self._map_indices()[0] if component is None else int(component)
        lw = self._speed_log_weights(k)
        return supported(np.exp(lw - lw.max()))

    def expected_controlled(self, times, component=None, derivatives: bool = True):
        """The controlled agent's expected path at ``times`` (s since onset) under component k
        (k* if None), the phase speed marginalised: sum_m p_eta(alpha_m | D, k)
        E[y_c(alpha_m t) | D, k, alpha_m] over :meth:`speed_hypotheses`. Under squared error
        this is the best prediction the posterior allows; the MAP speed's path commits to one
        timing, and when the speed is uncertain (a wave whose pace the prefix does not tell) a
        path off by half a period errs more than the mean. Each hypothesis holds its final
        posture after its own end (alpha_m t > 1). Returns (k, positions, velocities,
        accelerations), each (len(times), Q); without ``derivatives`` (an evaluation of
        positions) the velocities and accelerations are None and not computed. With changes of
        mind, the part of k's belief after a change is predicted by the started segments' own
        weights and phase lines (core.switching.ChangePoints.lines), the rest as above."""
        k = self._map_indices()[0] if component is None else int(component)
        times = np.asarray(times, dtype=float)
        speeds, probs = self.speed_hypotheses(k)
        mu_o = np.array([self._observed_mean(k, m) for m in speeds])
        mean_c = self.controlled_mean(k, mu_o).reshape(len(speeds), -1, self.n_basis)
        basis = self.model.basis_
        alphas = self.alphas[speeds]
        share, columns, shares = 1.0, (), ()
        if self._changes is not None:
            share, columns, shares = self._changes.lines(k, self._onset_log_evidence()[0])
        pos, vel, acc = expected_trajectory(mean_c, alphas, alphas, probs * share, times,
                                            basis.centers, basis.width, derivatives)
        # After a change, the segments' own weights on their own phase lines
        # z = z0 + rate t (core.switching): each line's path at times shifted by z0 / rate.
        for c, p in zip(columns, shares):
            mu, z0, rate = self._changes.column(c)
            line = expected_trajectory(
                self.controlled_mean(k, mu).reshape(1, -1, self.n_basis), np.array([rate]),
                np.array([rate]), np.array([p]), times + z0 / rate, basis.centers,
                basis.width, derivatives)
            pos, vel, acc = pos + line[0], vel + line[1], acc + line[2]
        return (k, pos, vel, acc) if derivatives else (k, pos, None, None)

    def likely_components(self):
        """The components that hold p(k | D): (indices, probabilities renormalised over them),
        :func:`supported`."""
        return supported(self.component_posterior())

    def latest_end(self, components) -> float:
        """The end (s since onset) of the slowest phase speed holding any of ``components``'
        tempered posteriors: when every hypothesis of theirs has ended."""
        return max(1.0 / float(self.alphas[self.speed_hypotheses(k)[0]].min())
                   for k in components)

    def predictive_controlled(self, times, derivatives: bool = True):
        """The controlled agent's expected path at ``times`` (s since onset) with the component
        marginalised too: sum_k p(k | D) :meth:`expected_controlled` (times, k), over
        :meth:`likely_components`. Before the pattern is known this is the best prediction
        under squared error (each component's path commits to one interaction); it becomes
        k*'s as p(k* | D) goes to 1. Returns (positions, velocities, accelerations), each
        (len(times), Q); velocities and accelerations None without ``derivatives``."""
        components, probs = self.likely_components()
        paths = [self.expected_controlled(times, component=k, derivatives=derivatives)[1:]
                 for k in components]
        return tuple(None if paths[0][i] is None else sum(p * path[i] for p, path in
                                                          zip(probs, paths))
                     for i in range(3))

    def predict_at_rest(self, y_final, component=None):
        """The controlled agent's final posture once the movement has ended: eq. 13 with D the
        final position of the observed agent at z = 1 (phase known), as in the thesis's
        experiments. Returns the posture mean (Q,) and covariance (Q, Q).

        Conditioning the end posture on the final position only, rather than on the whole
        observed path, avoids regressing it on path-shape details that a component learned
        from a few demonstrations cannot estimate (spurious correlations of a weight vector
        with more entries than the component has demonstrations)."""
        k = self.map_hypothesis()[0] if component is None else int(component)
        _, mean, cov = self.model.condition([1.0], np.asarray(y_final, dtype=float)[None],
                                            component=k)
        dofs = range(self.n_observed, self.n_observed + self.model.n_controlled_)
        out = trajectory_distribution(mean, cov, self.model.basis_, [1.0], 1.0, dofs)
        return out['position'][0], out['position_cov'][0]
