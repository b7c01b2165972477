"""Interaction ProMP: one Gaussian over the stacked weights of the observed agent (P DOFs,
first) and the controlled agent (Q DOFs); conditioning on the observed agent (eqs. 3-5) and
the resulting distribution over trajectories of every DOF (eq. 3), with velocities.
"""

import numpy as np
from scipy import linalg

from .basis import GaussianBasis
from .promp import block_diag_info, observation_stats


def condition_on_observed(mean, cov, basis: GaussianBasis, n_observed: int, z, Y, noise_var):
    """Eqs. 3-5: p(w | D) for observations D of the observed agent only.

    ``z`` (m,) phases of the observations, ``Y`` (m, P) observed positions (NaN = missing),
    ``noise_var`` (P,) observation noise variances (Sigma_D). Equivalent to the Kalman form of
    eq. 4 with H_t of eq. 5 (zero rows for the controlled agent), computed through the
    observed-agent block so the cost is independent of the number of observations:
    w_o | D from the information form, then w | D = mu + B (mu_o+ - mu_o), B = Sigma_:o Sigma_oo^-1.
    """
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    N = basis.n_basis
    do = n_observed * N
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 2 or Y.shape[1] != n_observed:
        raise ValueError(f'observations must have shape (m, {n_observed}), got {Y.shape}')
    if Y.shape[0] == 0 or np.isnan(Y).all():
        raise ValueError('empty observation: nothing to condition on')
    if np.any(np.isinf(Y)):
        raise ValueError('observations contain Inf')
    noise_var = np.broadcast_to(np.asarray(noise_var, dtype=float), (n_observed,))
    if np.any(~np.isfinite(noise_var)) or np.any(noise_var <= 0):
        raise ValueError('observation noise variances must be positive and finite')
    st = observation_stats(basis, np.asarray(z, dtype=float), Y)
    info, eta = block_diag_info(st, noise_var)
    mu_o = mean[:do]
    S_oo = cov[:do, :do]
    S_xo = cov[:, :do]
    chol_oo = linalg.cho_factor(S_oo, lower=True)
    prec = linalg.cho_solve(chol_oo, np.eye(do)) + info
    post_oo = linalg.cho_solve(linalg.cho_factor(prec, lower=True), np.eye(do))
    post_oo = 0.5 * (post_oo + post_oo.T)
    post_mu_o = mu_o + post_oo @ (eta - info @ mu_o)
    B = linalg.cho_solve(chol_oo, S_xo.T).T                     # Sigma_:o Sigma_oo^-1
    new_mean = mean + B @ (post_mu_o - mu_o)
    new_cov = cov - B @ (S_oo - post_oo) @ B.T
    return new_mean, 0.5 * (new_cov + new_cov.T)


def trajectory_distribution(mean, cov, basis: GaussianBasis, z, alpha: float = 1.0, dofs=None):
    """Eqs. 1-3: mean and covariance of positions, velocities and accelerations of ``dofs``.

    Positions at phases ``z``; velocities and accelerations are time derivatives for the phase
    speed ``alpha`` = 1/T (z = alpha t). Returns a dict with 'position', 'velocity',
    'acceleration' of shape (len(z), n) and 'position_cov' (len(z), n, n) (joint covariance
    between the selected DOFs at each phase), or without 'position_cov' when ``cov`` is None
    (a robot command needs only the mean).
    """
    N = basis.n_basis
    n_dofs = mean.shape[0] // N
    dofs = list(range(n_dofs)) if dofs is None else list(dofs)
    psi, dpsi, ddpsi = basis.evaluate(z, order=2)
    W = mean.reshape(n_dofs, N)[dofs]                               # (n, N)
    out = {
        'position': psi @ W.T,
        'velocity': alpha * (dpsi @ W.T),
        'acceleration': alpha ** 2 * (ddpsi @ W.T),
    }
    if cov is None:
        return out
    idx = np.array([i for j in dofs for i in range(j * N, (j + 1) * N)], dtype=int)
    C = cov[np.ix_(idx, idx)].reshape(len(dofs), N, len(dofs), N)
    out['position_cov'] = np.einsum('tn,injk,tk->tij', psi, C, psi, optimize=True)
    return out
