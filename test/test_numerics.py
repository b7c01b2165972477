"""core.numerics against scipy.special.logsumexp (the oracle): bit for bit, row by row; and the
tolerance within which a decision is a tie."""

import numpy as np
import pytest
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


def test_a_difference_within_rounding_is_a_tie_that_the_first_option_takes():
    from mixture_ip_ros.core.numerics import TIE_RTOL, first_best, tie_tolerance
    # What another BLAS kernel might give: the second option "better" by 1e-13 relative.
    v = np.array([-3.25, -3.25 * (1 - 1e-13), -7.0])
    assert int(np.argmax(v)) == 1 and first_best(v) == 0
    assert first_best([1.0, 1.0 + 1e-6]) == 1                # a real difference is not a tie
    assert first_best([2.0, 1.0], higher_is_better=False) == 1
    assert first_best([np.nan, -np.inf, 5.0]) == 2
    assert tie_tolerance(np.array([1e3, -2.0])) == pytest.approx(TIE_RTOL * 1e3)
    assert tie_tolerance(np.array([1e-3])) == TIE_RTOL          # numbers below 1 tie below 1e-9


def test_a_k_within_rounding_of_the_plateau_edge_is_decided_for_the_simpler_model():
    """Candidate 2 beats candidate 1 by exactly two paired standard errors plus rounding: the
    edge of selection_curve's plateau. Within rounding, the plateau keeps candidate 1 (the
    smaller K) on every machine; a real margin (1e-6) does not."""
    from mixture_ip_ros.core.selection import not_significantly_worse, selection_curve
    rng = np.random.default_rng(0)
    d = rng.standard_normal(30)
    se = d.std(ddof=1) / np.sqrt(len(d))               # a shift leaves it as it is
    base = rng.standard_normal(30)
    for eps, expected in ((1e-14, 0), (-1e-14, 0), (1e-6, 1)):
        gain = d - d.mean() + 2.0 * se * (1 + eps)      # mean difference 2 se (1 + eps)
        g = np.vstack([base, base + gain])
        assert not_significantly_worse(g)[0] == (expected == 0), eps
        assert selection_curve(g, higher_is_better=True, paired=True)['index'] == expected, eps
