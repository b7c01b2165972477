"""scenarios.corruption against sampled data with known parameters: each corruption's numbers
(offset std, noise std and correlation, dropped share, stamp jitter) are estimated from many
samples and compared with the magnitudes it was given, within a few standard errors of the
estimate; the seeding (one stream per corruption) and the inputs left unchanged."""

import dataclasses

import numpy as np
import pytest

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.scenarios.corruption import (DEFAULTS, Corruption, ar1_noise, corrupted,
                                                 noisy, reclocked, retimed, shifted)


def _pair(n=60, rate=30.0, n_obs=3, n_ctrl=3, phase=0.0, name=None):
    """A two-agent recording at ``rate`` Hz: smooth, distinct paths for every DOF."""
    t = np.arange(n) / rate
    obs = np.column_stack([np.sin(2 * t + phase + j) + 0.1 * j for j in range(n_obs)])
    ctl = (np.column_stack([np.cos(3 * t + phase + j) - 0.2 * j for j in range(n_ctrl)])
           if n_ctrl else None)
    return Demonstration(t, obs, ctl, label='a', name=name)


def _copies(demos):
    return [(d.t.copy(), d.observed.copy(), d.controlled.copy()) for d in demos]


def _unchanged(demos, copies):
    return all(np.array_equal(d.t, t) and np.array_equal(d.observed, o, equal_nan=True)
               and np.array_equal(d.controlled, c, equal_nan=True)
               for d, (t, o, c) in zip(demos, copies))


def test_the_defaults_are_the_documented_magnitudes_and_frozen():
    assert DEFAULTS == Corruption((0.3, 0.15, 0.2), 0.02, 0.1, 0.004, 0.1, 5, 0.3, 0.2)
    with pytest.raises(dataclasses.FrozenInstanceError):
        DEFAULTS.drop = 0.5


# -- shifted --------------------------------------------------------------------------------
def test_a_shifted_pair_moves_both_agents_by_one_offset_per_recording():
    demos = [_pair(phase=k) for k in range(5)]
    before = _copies(demos)
    out = shifted(demos, np.random.default_rng(3))
    assert _unchanged(demos, before)
    offsets = []
    for d, s in zip(demos, out):
        assert np.array_equal(s.t, d.t) and (s.label, s.name) == (d.label, d.name)
        do, dc = s.observed - d.observed, s.controlled - d.controlled
        # One offset over the whole recording, the same for both agents (rounding only).
        assert np.allclose(do, do[0], rtol=0, atol=1e-12)
        assert np.allclose(dc, do[0], rtol=0, atol=1e-12)
        offsets.append(do[0])
    offsets = np.array(offsets)
    assert np.all(np.abs(offsets) > 0)
    assert len({tuple(o) for o in offsets}) == len(demos)       # one draw per recording


def test_shifted_offsets_have_the_given_std_per_axis():
    """4000 recordings: the std estimate's standard error is std / sqrt(2 n) = 1.1 % of it, the
    mean's std / sqrt(n) = 1.6 % of it; both are asserted within 4 standard errors, and the
    axes are independent (correlation within 4 / sqrt(n))."""
    n, std = 4000, np.array([0.3, 0.15, 0.2])
    t = np.array([0.0, 0.1])
    demos = [Demonstration(t, np.zeros((2, 3)), np.zeros((2, 3))) for _ in range(n)]
    out = shifted(demos, np.random.default_rng(11), tuple(std))
    o = np.array([s.observed[0] for s in out])
    assert np.array_equal(o, np.array([s.controlled[1] for s in out]))
    assert np.all(np.abs(o.std(axis=0, ddof=1) - std) < 4 * std / np.sqrt(2 * n))
    assert np.all(np.abs(o.mean(axis=0)) < 4 * std / np.sqrt(n))
    corr = np.corrcoef(o, rowvar=False)[np.triu_indices(3, 1)]
    assert np.all(np.abs(corr) < 4 / np.sqrt(n))


def test_shifted_leaves_a_controlled_agent_with_fewer_dofs_than_axes_and_extra_dofs_unchanged():
    demos = [_pair(n_obs=5, n_ctrl=2), _pair(n_obs=3, n_ctrl=0)]
    before = _copies(demos)
    out = shifted(demos, np.random.default_rng(0))
    assert _unchanged(demos, before)
    assert np.array_equal(out[0].controlled, demos[0].controlled)
    assert np.array_equal(out[0].observed[:, 3:], demos[0].observed[:, 3:])
    assert np.all(np.abs(out[0].observed[:, :3] - demos[0].observed[:, :3]) > 0)
    assert out[1].controlled.shape == (60, 0)


def test_shifted_with_a_zero_std_axis_leaves_that_axis():
    (d,) = [_pair()]
    (s,) = shifted([d], np.random.default_rng(1), (0.0, 0.2))
    assert np.array_equal(s.observed[:, 0], d.observed[:, 0])
    assert np.array_equal(s.observed[:, 2], d.observed[:, 2])
    assert not np.array_equal(s.observed[:, 1], d.observed[:, 1])


# -- ar1_noise ------------------------------------------------------------------------------
def _bartlett_se(rho, lag, n):
    """Standard error of a lag-``lag`` autocorrelation estimate from n samples of an AR(1)
    series of lag-1 correlation ``rho`` (Bartlett's formula)."""
    r2k = rho ** (2 * lag)
    return np.sqrt(((1 + rho ** 2) * (1 - r2k) / (1 - rho ** 2) - 2 * lag * r2k) / n)


def test_ar1_noise_on_a_long_regular_series_has_the_stationary_std_and_lag_correlation():
    """dt / tau = 0.1, rho = exp(-0.1) = 0.905, 4 DOFs x 50000 samples. The variance estimate
    of an AR(1) series has relative standard error sqrt(2 (1 + rho^2) / ((1 - rho^2) n)), so the
    std's is about 0.5 % (1 % per DOF); the lag-k correlations' are Bartlett's (0.001 at lag 1,
    0.006 at lag 10, averaged over the DOFs). Asserted within 4-6 standard errors, far below the
    change a wrong time constant makes (tau * 1.2: rho = 0.920, 16 standard errors at lag 1)."""
    n, dt, tau, std, dofs = 50000, 0.01, 0.1, 0.02, 4
    rho = np.exp(-dt / tau)
    t = np.arange(n) * dt
    x = ar1_noise(t, dofs, np.random.default_rng(5), std, tau)
    assert x.shape == (n, dofs)
    inflation = (1 + rho ** 2) / (1 - rho ** 2)
    assert abs(x.std() / std - 1) < 4 * np.sqrt(2 * inflation / (n * dofs)) / 2
    assert np.all(np.abs(x.std(axis=0) / std - 1) < 6 * np.sqrt(2 * inflation / n) / 2)
    for lag in (1, 2, 5, 10):
        r = np.mean([np.corrcoef(x[:-lag, j], x[lag:, j])[0, 1] for j in range(dofs)])
        assert abs(r - rho ** lag) < 4 * _bartlett_se(rho, lag, n * dofs), (lag, r)
    # DOFs are independent: the cross-correlation of two independent AR(1) series has
    # standard error sqrt(inflation / n) (0.014 here); 5 of them.
    c = np.corrcoef(x, rowvar=False)[np.triu_indices(dofs, 1)]
    assert np.all(np.abs(c) < 5 * np.sqrt(inflation / n))


def test_ar1_noise_correlation_follows_the_actual_spacing_of_irregular_stamps():
    """40000 independent chains (one per DOF) over irregular stamps: across the chains, every
    stamp's noise has std ``std`` (also the first: stationary from the start) and two stamps
    correlate as exp(-|t_a - t_b| / tau). A correlation estimate from N pairs has standard
    error (1 - rho^2) / sqrt(N) <= 0.005: tolerance 0.02; the std's 0.35 %: tolerance 2 %."""
    t = np.array([0.0, 0.01, 0.06, 0.07, 0.27, 0.28])
    tau, std, n = 0.1, 0.5, 40000
    x = ar1_noise(t, n, np.random.default_rng(7), std, tau)
    assert np.all(np.abs(x.std(axis=1) / std - 1) < 0.02)
    r = np.corrcoef(x)
    for a in range(len(t)):
        for b in range(a + 1, len(t)):
            assert abs(r[a, b] - np.exp(-(t[b] - t[a]) / tau)) < 0.02, (a, b, r[a, b])


def test_noisy_adds_ar1_noise_to_every_dof_of_both_agents_and_keeps_missing_samples_missing():
    d = _pair(n=3000, rate=100.0)
    d.observed[10:20] = np.nan
    before = _copies([d])
    (s,) = noisy([d], np.random.default_rng(2), std=0.03, time_constant=0.05)
    assert _unchanged([d], before)
    assert np.isnan(s.observed[10:20]).all() and not np.isnan(s.controlled).any()
    ok = ~np.isnan(d.observed).any(axis=1)
    e = np.hstack([s.observed[ok] - d.observed[ok], s.controlled[ok] - d.controlled[ok]])
    # 6 DOFs x ~3000 samples, rho = exp(-0.2) = 0.82: the std's standard error is 1.2 %, the
    # lag-1 correlation's 0.004, a cross-correlation's 0.04; asserted within 4-5 of them.
    n, rho = len(e), np.exp(-0.01 / 0.05)
    inflation = (1 + rho ** 2) / (1 - rho ** 2)
    assert abs(e.std() / 0.03 - 1) < 4 * np.sqrt(2 * inflation / (6 * n)) / 2
    r = np.mean([np.corrcoef(e[:-1, j], e[1:, j])[0, 1] for j in range(6)])
    assert abs(r - rho) < 4 * _bartlett_se(rho, 1, 6 * n)
    cross = np.corrcoef(e, rowvar=False)[np.triu_indices(6, 1)]
    assert np.all(np.abs(cross) < 5 * np.sqrt(inflation / n))


# -- reclocked ------------------------------------------------------------------------------
def _indexed(n, rate=30.0):
    """A recording whose first observed DOF is its row index: the kept rows are readable."""
    t = np.arange(n) / rate
    obs = np.column_stack([np.arange(n, dtype=float), np.sin(t), np.cos(t)])
    return Demonstration(t, obs, np.column_stack([t ** 2, -t]), label='b', name='long')


def test_reclocked_keeps_first_and_last_frames_original_rows_and_increasing_stamps_from_zero():
    demos = [_indexed(300), _indexed(50)]
    before = _copies(demos)
    out = reclocked(demos, np.random.default_rng(4))
    assert _unchanged(demos, before)
    for d, s in zip(demos, out):
        rows = s.observed[:, 0].astype(int)
        assert rows[0] == 0 and rows[-1] == len(d.t) - 1
        assert np.all(np.diff(rows) > 0)
        assert np.array_equal(s.observed, d.observed[rows])
        assert np.array_equal(s.controlled, d.controlled[rows])
        assert s.t[0] == 0 and np.all(np.diff(s.t) > 0)
        assert (s.label, s.name) == (d.label, d.name)
    assert len(out[0].t) < 300          # 0.1 of 300 frames: some are dropped


def test_reclocked_drops_about_the_given_share_in_bursts_and_jitters_stamps_by_the_given_std():
    """200 recordings of 600 frames. Bursts start with probability p = drop / mean burst and
    last 1..burst frames, so a frame is kept with probability prod_k (1 - p (burst - k) /
    burst), k < burst (0.904 for drop 0.1, burst 5, not exactly 0.9: bursts overlap). The kept
    share is checked within 4 standard errors (over the recordings) of that, and within 2
    points of 1 - drop. Jitter: the kept stamps minus the original stamps of the same rows
    (the first excluded: it is pinned), std within 4 standard errors (std / sqrt(2 n))."""
    drop, burst, jitter = 0.1, 5, 0.004
    demos = [_indexed(600) for _ in range(200)]
    out = reclocked(demos, np.random.default_rng(8), jitter_std=jitter, drop=drop, burst=burst)
    shares = np.array([(len(s.t) - 2) / (len(d.t) - 2) for d, s in zip(demos, out)])
    p = drop / ((1 + burst) / 2)
    expected = np.prod([1 - p * (burst - k) / burst for k in range(burst)])
    se = shares.std(ddof=1) / np.sqrt(len(shares))
    assert abs(shares.mean() - expected) < 4 * se, (shares.mean(), expected, se)
    assert abs(shares.mean() - (1 - drop)) < 0.02
    # Drops come in bursts: runs of consecutive dropped frames longer than 1 occur.
    gaps = np.concatenate([np.diff(s.observed[:, 0]) for s in out]) - 1
    assert gaps.max() >= burst and np.mean(gaps[gaps > 0] > 1) > 0.3
    # The jitter of every kept stamp but the first, against the original stamp of its row.
    e = np.concatenate([s.t[1:] - d.t[s.observed[1:, 0].astype(int)] for d, s in zip(demos, out)])
    assert abs(e.std() - jitter) < 4 * jitter / np.sqrt(2 * e.size)
    assert abs(e.mean()) < 4 * jitter / np.sqrt(e.size)


def test_reclocked_without_jitter_or_drops_returns_the_recording():
    d = _indexed(100)
    (s,) = reclocked([d], np.random.default_rng(0), jitter_std=0.0, drop=0.0)
    assert np.array_equal(s.t, d.t) and np.array_equal(s.observed, d.observed)


def test_reclocked_keeps_stamps_at_least_a_tenth_of_the_period_apart_under_large_jitter():
    d = _indexed(400)
    (s,) = reclocked([d], np.random.default_rng(1), jitter_std=0.1, drop=0.0)
    assert len(s.t) == 400 and np.all(np.diff(s.t) >= 0.1 / 30 - 1e-12)


# -- corrupted ------------------------------------------------------------------------------
def _set(n=6):
    return [_pair(n=45 + 5 * k, phase=0.3 * k, name=f'r{k}') for k in range(n)]


# -- retimed --------------------------------------------------------------------------------
def test_retimed_keeps_every_sample_the_onset_and_the_end_and_moves_the_stamps_monotonically():
    demos = [_pair(phase=k, name=f'r{k}') for k in range(4)]
    demos[1].observed[5:9] = np.nan                      # a gap stays where it was, by sample
    before = _copies(demos)
    out = retimed(demos, np.random.default_rng(2))
    assert _unchanged(demos, before)
    for d, r in zip(demos, out):
        assert (r.label, r.name) == (d.label, d.name)
        assert np.array_equal(r.observed, d.observed, equal_nan=True)
        assert np.array_equal(r.controlled, d.controlled)
        assert r.t[0] == 0.0 and r.t[-1] == d.t[-1]
        assert np.all(np.diff(r.t) > 0)
        assert np.max(np.abs(r.t - d.t)) > 0.01        # stamps moved, not rounded
    assert not np.allclose(out[0].t, out[1].t)           # one pace per recording


def test_retimed_log_pace_has_the_given_std_and_correlation_along_the_movement():
    """The time between samples i and i + 1 is c du exp(-r_i), so x_i = log(dt'_i / dt_i) is
    -r_i plus a constant per recording and E[(x_i - x_{i+k})^2] = 2 std^2 (1 - rho^k),
    rho = exp(-du / correlation). 2000 recordings of 60 regular samples (du = 1/59, rho =
    0.919): the mean over recordings is asserted within 4 of its standard errors (estimated
    from the recordings) at k = 1, 5 and 20; a std 10 % off or a correlation twice as long
    moves it by 14 or more of them at every k."""
    n, std, corr = 2000, 0.3, 0.2
    demos = [_pair() for _ in range(n)]
    out = retimed(demos, np.random.default_rng(9), std, corr)
    x = np.array([np.log(np.diff(r.t) / np.diff(d.t)) for d, r in zip(demos, out)])
    du = 1.0 / 59
    for k in (1, 5, 20):
        per = np.mean((x[:, :-k] - x[:, k:]) ** 2, axis=1)
        expected = 2 * std ** 2 * (1 - np.exp(-k * du / corr))
        se = per.std(ddof=1) / np.sqrt(n)
        assert abs(per.mean() - expected) < 4 * se, (k, per.mean(), expected, se)


def test_retimed_with_zero_std_returns_the_recordings_as_they_were():
    demos = [_pair(), _pair(phase=1.0)]
    assert _same(retimed(demos, np.random.default_rng(0), 0.0), demos)


def _same(a, b):
    return len(a) == len(b) and all(
        np.array_equal(x.t, y.t) and np.array_equal(x.observed, y.observed)
        and np.array_equal(x.controlled, y.controlled) for x, y in zip(a, b))


ALL = ['offset', 'noise', 'clock', 'tempo']


def test_corrupted_is_deterministic_per_seed_and_leaves_its_inputs():
    demos = _set()
    before = _copies(demos)
    a, b = corrupted(demos, ALL, seed=3), corrupted(demos, ALL, seed=3)
    assert _same(a, b) and not _same(a, corrupted(demos, ALL, seed=4))
    assert _unchanged(demos, before)
    for which in (['offset'], ['noise'], ['clock'], ['tempo']):
        assert not _same(corrupted(demos, which, 0), corrupted(demos, which, 1))


def test_corrupted_refuses_an_unknown_corruption_by_name():
    with pytest.raises(ValueError, match=r"unknown corruptions \['shake'\]"):
        corrupted(_set(2), ['offset', 'shake'], 0)


def test_corrupted_offsets_are_those_of_shifted_on_its_own_stream_whatever_else_is_added():
    """Stream 0 of SeedSequence(seed).spawn(3) draws the offsets: adding the noise (stream 1)
    or naming the corruptions in another order changes neither the offsets nor the noise."""
    demos, seed = _set(), 12
    streams = np.random.SeedSequence(seed).spawn(3)
    alone = shifted(demos, np.random.default_rng(streams[0]), DEFAULTS.offset_std)
    assert _same(corrupted(demos, ['offset'], seed), alone)
    noise = corrupted(demos, ['noise'], seed)
    expected_noise = noisy(demos, np.random.default_rng(streams[1]), DEFAULTS.noise_std,
                           DEFAULTS.noise_time)
    assert _same(noise, expected_noise)
    both = corrupted(demos, ['noise', 'offset'], seed)
    assert _same(both, corrupted(demos, ['offset', 'noise'], seed))
    for d, a, n, b in zip(demos, alone, noise, both):
        # b = d + noise + o, n = d + noise, a = d + o: the same o and the same noise.
        assert np.allclose(b.observed - n.observed, a.observed - d.observed, atol=1e-12)
        assert np.allclose(b.controlled - n.controlled, a.controlled - d.controlled, atol=1e-12)


def test_corrupted_retimes_first_then_reclocks_then_adds_noise_then_moves_the_pair():
    """The people's pace is theirs (stream 3 of SeedSequence(seed).spawn(4)); the tracker's
    clock, noise and the pair's place follow on streams 2, 1 and 0, as before the pace was
    added (spawned streams do not depend on how many are spawned)."""
    demos, seed = _set(), 5
    streams = np.random.SeedSequence(seed).spawn(4)
    tempo = retimed(demos, np.random.default_rng(streams[3]), DEFAULTS.tempo_std,
                    DEFAULTS.tempo_time)
    assert _same(corrupted(demos, ['tempo'], seed), tempo)
    clock = reclocked(demos, np.random.default_rng(streams[2]), DEFAULTS.jitter_std,
                      DEFAULTS.drop, DEFAULTS.burst)
    assert _same(corrupted(demos, ['clock'], seed), clock)
    clock = reclocked(tempo, np.random.default_rng(streams[2]), DEFAULTS.jitter_std,
                      DEFAULTS.drop, DEFAULTS.burst)
    noise = noisy(clock, np.random.default_rng(streams[1]), DEFAULTS.noise_std,
                  DEFAULTS.noise_time)
    expected = shifted(noise, np.random.default_rng(streams[0]), DEFAULTS.offset_std)
    assert _same(corrupted(demos, ALL, seed), expected)


def test_corrupted_uses_the_given_magnitudes():
    demos = _set(3)
    none = Corruption(offset_std=(0.0, 0.0, 0.0), noise_std=0.0, jitter_std=0.0, drop=0.0,
                      tempo_std=0.0)
    assert _same(corrupted(demos, ALL, 0, none), demos)
    assert _same(corrupted(demos, [], 0), demos)
