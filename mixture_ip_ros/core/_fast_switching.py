"""The change points' fast paths (core.switching): the belief and the joint posterior on every
observation, compiled (numba). They call only each other (see core._fast on numba's cache).
Each says which plain computation it must equal; test_core_switching compares them.
"""

import numba
import numpy as np

# exp(x) is exactly 0.0 in double precision below this (it underflows past the smallest
# subnormal, 5e-324 = exp(-744.4), below -745.13).
_UNDERFLOW = -746.0


@numba.njit(cache=True, nogil=True, inline='always')
def _exp(x):
    """np.exp(x), to the bit. Most terms of the belief's sums are hypotheses the samples ruled
    out, thousands of nats down, and the library's exp takes a slow path to return their 0."""
    return 0.0 if x < _UNDERFLOW else np.exp(x)


@numba.njit(cache=True, nogil=True, boundscheck=False)
def grouped_logsumexp(values, groups, n_groups):
    """out[g] = log sum of exp(values[c]) over the c with groups[c] = g, (n_groups,); -inf for a
    group without a finite value. Equals scipy.special.logsumexp of each group to rounding (the
    change points' per-component evidence, core.switching, on every observation)."""
    top = np.full(n_groups, -np.inf)
    for c in range(values.shape[0]):
        if values[c] > top[groups[c]]:
            top[groups[c]] = values[c]
    total = np.zeros(n_groups)
    for c in range(values.shape[0]):
        g = groups[c]
        if top[g] > -np.inf:
            total[g] += _exp(values[c] - top[g])
    out = np.full(n_groups, -np.inf)
    for g in range(n_groups):
        if top[g] > -np.inf:
            out[g] = top[g] + np.log(total[g])
    return out


@numba.njit(cache=True, nogil=True, boundscheck=False)
def switching_joint(log_prior, loglik, n, hypothesis, n_alpha, n_components, stay, offset,
                    started_loglik, started_component, joint):
    """p(k, alpha_m | D) = b(k) p(alpha_m | D, k) into ``joint`` (K M,) (core.switching): the
    segment since the onset from its first ``n`` columns (log_prior + loglik, hypothesis
    (k, m) = divmod(hypothesis[c], n_alpha)) with log(1 - h) summed in ``stay``, the started
    segments' columns offset + started_loglik of component started_component; the belief b(k)
    sums both per component, over the components with a hypothesis since the onset. Returns
    the smallest probability of a tracked hypothesis. The same numbers as ChangePoints.belief
    with the onset's grouped_logsumexp, to rounding."""
    lw = np.empty(n)
    groups = np.empty(n, dtype=np.int64)
    for c in range(n):
        lw[c] = log_prior[c] + loglik[c]
        groups[c] = hypothesis[c] // n_alpha
    onset = grouped_logsumexp(lw, groups, n_components)
    started = grouped_logsumexp(offset + started_loglik[:offset.shape[0]], started_component,
                                n_components)
    per_k = np.empty(n_components)
    top = -np.inf
    for k in range(n_components):
        # a component with no hypothesis since the onset (pruned whole) has no phase speeds
        # to hold its belief: left out
        a, b = onset[k] + stay, started[k] if onset[k] > -np.inf else -np.inf
        hi = max(a, b)
        per_k[k] = -np.inf if hi == -np.inf else hi + np.log(np.exp(a - hi) + np.exp(b - hi))
        top = max(top, per_k[k])
    total = 0.0
    for k in range(n_components):
        total += np.exp(per_k[k] - top)
    # log b(k), the part of each column's exponent its component gives, once per component:
    # the same terms summed in the same order as per column
    log_total = np.log(total)
    log_b = np.empty(n_components)
    for k in range(n_components):
        log_b[k] = per_k[k] - top - log_total
    joint[:] = 0.0
    smallest = 1.0
    for c in range(n):
        k = groups[c]
        p = _exp(log_b[k] + lw[c] - onset[k])
        joint[hypothesis[c]] = p
        smallest = min(smallest, p)
    return smallest
