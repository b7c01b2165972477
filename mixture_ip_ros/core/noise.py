"""How long a movement model's residuals stay correlated, and what one observation is worth.

Eq. 15's noise is white: every sample of a demonstration off its ProMP path by an independent
draw. Real recordings are not: a hand shaking or waving faster than the basis functions can
follow, or a skeleton tracker's slow drift, leaves residuals that keep their sign for a good
part of a second. Conditioning on samples a twentieth of a second apart as if each were
independent then counts the same deviation a dozen times; online the posterior over the phase
follows it, and a phase speed that lets the weights bend the path towards the wiggle wins
(on NuiSI's handshakes the movement was thought 20-40 % shorter than it was).

The correlation is measured on the training residuals: their integrated autocorrelation time
tau per DOF (Geyer's initial positive sequence estimator, in seconds). Samples taken ``interval``
apart then carry the information of samples tau apart, so each is given the noise variance
sigma^2 * max(1, tau / interval) (:func:`noise_factor`): white residuals (tau about one sample
period) change nothing.
"""

import numpy as np

# Residual correlations are measured up to this lag (s): longer than any correlation a
# movement's residual keeps, shorter than a movement.
MAX_LAG_S = 2.0


def residual_autocovariance(residuals, max_lag: int):
    """(sums (D, max_lag + 1), counts (D, max_lag + 1)): per DOF and lag l, the sum of
    r_t r_(t+l) over the pairs of samples where both are observed (NaN: missing) and how many
    pairs there are. ``residuals`` (T, D)."""
    R = np.asarray(residuals, dtype=float)
    ok = (~np.isnan(R)).astype(float)
    R0 = np.where(ok > 0, R, 0.0)
    T, D = R.shape
    sums = np.zeros((D, max_lag + 1))
    counts = np.zeros((D, max_lag + 1))
    for lag in range(min(max_lag, T - 1) + 1):
        sums[:, lag] = np.einsum('td,td->d', R0[:T - lag], R0[lag:])
        counts[:, lag] = np.einsum('td,td->d', ok[:T - lag], ok[lag:])
    return sums, counts


def correlation_time(sums, counts, period: float) -> np.ndarray:
    """The integrated autocorrelation time (s) per DOF of residuals sampled every ``period``
    s, from their pooled autocovariance (:func:`residual_autocovariance` summed over
    demonstrations): period * (-1 + 2 sum_m (rho_2m + rho_2m+1)), the sum stopped at the first
    pair that is not positive (Geyer 1992). About ``period`` for white residuals."""
    sums = np.atleast_2d(np.asarray(sums, dtype=float))
    counts = np.atleast_2d(np.asarray(counts, dtype=float))
    cov = np.where(counts > 0, sums / np.maximum(counts, 1), 0.0)
    out = np.empty(len(cov))
    for j, c in enumerate(cov):
        if c[0] <= 0:
            out[j] = period
            continue
        rho = c / c[0]
        total = 0.0
        for m in range(len(rho) // 2):
            pair = rho[2 * m] + rho[2 * m + 1]
            if pair <= 0:
                break
            total += pair
        out[j] = period * max(1.0, 2.0 * total - 1.0)
    return out


def noise_factor(tau, period: float, interval: float) -> np.ndarray:
    """What the noise variance of each DOF is multiplied by for samples at least ``interval``
    s apart (never closer than the recording's ``period``): max(1, tau / spacing)."""
    spacing = max(float(interval), float(period))
    tau = np.asarray(tau, dtype=float)
    if spacing <= 0:
        return np.ones_like(tau)
    return np.maximum(1.0, tau / spacing)


def spaced(t: float, t_last: float, min_interval: float) -> bool:
    """The decimation rule: whether a sample at ``t`` is at least ``min_interval`` after the
    last one used, at ``t_last`` (stamps are ns: no float slack beyond 1 ns)."""
    return t - t_last >= min_interval - 1e-9


def decimated_rows(t, min_interval, last=None) -> np.ndarray:
    """Indices of the samples the online estimator absorbs from increasing times ``t``, after
    one used at ``last`` (None: none yet): the first, then each one at least ``min_interval``
    after the last one absorbed (OnlineEstimator.admit, in float64)."""
    rows = []
    for i, ti in enumerate(np.asarray(t, dtype=float).tolist()):
        if last is None or spaced(ti, last, min_interval):
            rows.append(i)
            last = ti
    return np.array(rows, dtype=int)
