"""log sum exp, the one normaliser of every posterior in the package (EM responsibilities, the
pattern mixture, K selection, the online estimator's evidence); and the tolerance within which
two numbers that decide something are a tie.

scipy.special.logsumexp computes it as max + log(count of the maximum) + log1p(the others'
exp-sum shifted by the maximum, divided by that count); this is the same sequence of numpy
operations on every row at once, so each row's value is scipy's bit for bit, without the
array-API layers that make scipy's call take hundreds of microseconds on a few hundred numbers
(the online estimator calls it on every observation). Rows whose maximum is not finite go to
scipy itself.
"""

import numpy as np
from scipy.special import logsumexp as _scipy_logsumexp


def logsumexp_rows(a) -> np.ndarray:
    """log sum_j exp(a_ij) for every row i of a 2-D real array: (n,)."""
    a = np.asarray(a, dtype=float)
    top = a.max(axis=1)
    finite = np.isfinite(top)
    if not finite.all():
        out = np.empty(len(a))
        out[~finite] = _scipy_logsumexp(a[~finite], axis=1)
        if finite.any():
            out[finite] = logsumexp_rows(a[finite])
        return out
    is_max = a == top[:, None]
    m = np.count_nonzero(is_max, axis=1).astype(float)
    s = np.exp(np.where(is_max, -np.inf, a) - top[:, None]).sum(axis=1)
    s = np.where(s != 0, s / m, s)
    return np.log1p(s) + np.log(m) + top


def logsumexp(a) -> float:
    """log sum_j exp(a_j) of a real 1-D array."""
    return float(logsumexp_rows(np.asarray(a, dtype=float)[None])[0])


# Differences below this share of the compared numbers' magnitude are ties. BLAS kernels (one
# machine's AVX2 against another's AVX-512) sum in other orders and leave results apart by
# about 1e-15 relative per operation, 1e-12 after the thousands an EM fit makes; a decision
# taken on a difference that small is decided by the CPU. A tie goes to the simpler model (the
# smaller K, the larger floor, the weight nearer eq. 16), so every machine takes the same.
TIE_RTOL = 1e-9


def tie_tolerance(*values) -> float:
    """The absolute difference below which numbers of the magnitude of ``values`` are a tie."""
    finite = [np.abs(v)[np.isfinite(v)] for v in map(np.asarray, values)]
    scale = max((float(np.max(f)) for f in finite if f.size), default=0.0)
    return TIE_RTOL * max(scale, 1.0)


def first_best(values, higher_is_better: bool = True) -> int:
    """Index of the first of ``values`` that is best up to a tie (:func:`tie_tolerance`), so
    that the order of the options, simplest first, settles a tie on every machine alike."""
    v = np.asarray(values, dtype=float)
    g = v if higher_is_better else -v
    finite = np.isfinite(g)
    if not finite.any():
        return 0
    top = np.max(g[finite])
    return int(np.flatnonzero(finite & (g >= top - tie_tolerance(top)))[0])
