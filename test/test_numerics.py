"""core.numerics against scipy.special.logsumexp (the oracle): bit for bit, row by row."""

import numpy as np
from scipy.special import logsumexp as scipy_logsumexp

from mixture_ip_ros.core.numerics import logsumexp, logsumexp_rows


def _cases(rng):
    for n in (1, 2, 3, 150, 1200):
        for scale in (1e-3, 1.0, 50.0, 1e4):
            a = rng.normal(rng.normal(0, 1e3, (20, 1)), scale, (20, n))
            if n > 2:
                for row in a:
                    row[rng.integers(n, size=2)] = row.max()       # tied maxima
                    row[rng.integers(n)] = -np.inf                  # a term with no mass
            yield a


def test_logsumexp_is_scipys_bit_for_bit():
    """Every row exactly scipy's value: ties of the maximum, one element and -inf terms."""
    rng = np.random.default_rng(11)
    for a in _cases(rng):
        np.testing.assert_array_equal(logsumexp_rows(a), scipy_logsumexp(a, axis=1))
        for row in a[:3]:
            assert logsumexp(row) == float(scipy_logsumexp(row))


def test_rows_without_a_finite_maximum_are_scipys():
    a = np.array([[-np.inf, -np.inf], [np.inf, 0.0], [np.nan, 1.0], [0.5, 1.0]])
    np.testing.assert_array_equal(logsumexp_rows(a), scipy_logsumexp(a, axis=1))
    for row in a:
        np.testing.assert_equal(logsumexp(row), float(scipy_logsumexp(row)))
