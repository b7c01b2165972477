"""Splices (core.splice): one recording's beginning joined to another's rest, the turn between
them a minimum-jerk fade of the gap into B's own path."""

import numpy as np
import pytest

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.splice import BLEND, splice


def _recording(T, dt, phase, label, name, P=2, Q=1):
    """A smooth movement of both agents over T s, samples dt apart."""
    t = np.arange(0.0, T + 1e-9, dt)
    z = t / t[-1]
    observed = np.column_stack([np.sin(2.0 * z + phase + j) + j for j in range(P)])
    controlled = np.column_stack([np.cos(1.5 * z - phase + j) - 2 * j for j in range(Q)]
                                 + [np.zeros((len(t), 0))])
    return Demonstration(t, observed, controlled, label=label, name=name)


@pytest.fixture
def a():
    return _recording(1.0, 0.01, 0.0, 'reach', 'a1')


@pytest.fixture
def b():
    return _recording(1.5, 0.01, 2.0, 'wave', 'b7')


def test_the_splice_is_as_beginning_then_bs_rest_from_the_same_share(a, b):
    s = splice(a, b, 0.4)
    d = s.demo
    head = np.flatnonzero(a.t <= 0.4 * a.duration + 1e-9)      # 0 .. 0.4 s of A
    tail = np.flatnonzero(b.t >= 0.4 * b.duration - 1e-9)      # 0.6 .. 1.5 s of B
    assert len(head) == 41 and tail[0] == 60
    assert len(d.t) == len(head) + len(tail)
    assert d.t[0] == 0.0 and np.all(np.diff(d.t) > 0)
    # A's beginning as it was
    assert np.array_equal(d.t[:41], a.t[head])
    assert np.array_equal(d.observed[:41], a.observed[head])
    assert np.array_equal(d.controlled[:41], a.controlled[head])
    # B's rest one of its sample periods after A's last sample, at B's own spacing
    assert s.t_change == pytest.approx(0.41, abs=1e-12) and d.t[41] == s.t_change
    assert np.allclose(d.t[41:] - s.t_change, b.t[tail] - b.t[tail[0]], rtol=0, atol=1e-12)
    # it starts where A left both agents ...
    assert np.allclose(d.observed[41], a.observed[40], rtol=0, atol=1e-14)
    assert np.allclose(d.controlled[41], a.controlled[40], rtol=0, atol=1e-14)
    assert not np.allclose(a.observed[40], b.observed[60], atol=0.1)      # a real gap
    # ... and is B's own once the turn is over
    over = d.t[41:] - s.t_change >= BLEND + 1e-9
    assert over.sum() > 50
    assert np.array_equal(d.observed[41:][over], b.observed[tail][over])
    assert np.array_equal(d.controlled[41:][over], b.controlled[tail][over])
    # labelled as B, and says what it joins
    assert d.label == 'wave' and (s.first, s.second) == ('reach', 'wave')
    assert d.name == 'a1>b7@0.4'


def test_the_turn_takes_blend_seconds(a, b):
    for blend in (0.1, 0.5):
        s = splice(a, b, 0.5, blend=blend)
        d, tail = s.demo, np.flatnonzero(b.t >= 0.5 * b.duration - 1e-9)
        start = len(d.t) - len(tail)
        since = d.t[start:] - s.t_change
        same = np.all(d.observed[start:] == b.observed[tail], axis=1)
        assert not same[since < blend - 1e-9].any()
        assert same[since >= blend + 1e-9].all()
    # no turn: A's last positions once, then B's own path
    s = splice(a, b, 0.5, blend=0.0)
    start = 51
    assert np.allclose(s.demo.observed[start], a.observed[50], rtol=0, atol=1e-14)
    assert np.array_equal(s.demo.observed[start + 1:], b.observed[76:])


def test_the_fade_is_minimum_jerk_and_the_positions_continuous():
    """Still recordings, A at x0 and B at y0: the spliced tail is y0 + f(s) (x0 - y0), f the
    fade over s = (t - t_change) / blend; on a dense grid f is the minimum-jerk polynomial from
    1 to 0, with zero slope and curvature at both ends."""
    dt, blend = 0.001, 0.3
    t = np.arange(0.0, 2.0 + 1e-9, dt)
    x0, y0 = np.array([0.2, -0.4]), np.array([1.0, 0.6])
    still = [Demonstration(t, np.tile(p, (len(t), 1)), np.tile(p[:1] * 2, (len(t), 1)))
             for p in (x0, y0)]
    s = splice(*still, 0.5, blend=blend)
    start = int(np.searchsorted(s.demo.t, s.t_change))
    sec = s.demo.t[start:] - s.t_change
    fade = (s.demo.observed[start:] - y0) / (x0 - y0)
    assert np.allclose(fade[:, 0], fade[:, 1], rtol=0, atol=1e-12)
    assert np.allclose((s.demo.controlled[start:, 0] - 2 * y0[0]) / (2 * (x0[0] - y0[0])),
                       fade[:, 0], rtol=0, atol=1e-12)                   # both agents alike
    f = fade[:, 0]
    u = np.clip(sec / blend, 0, 1)
    assert np.allclose(f, 1 - (10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5), rtol=0, atol=1e-12)
    assert f[0] == pytest.approx(1.0, abs=1e-15) and np.all(f[sec >= blend + 1e-9] == 0)
    assert np.all(np.diff(f) <= 1e-15)                                     # monotone
    inside = sec <= blend + 1e-9
    slope = np.gradient(f[inside], sec[inside])
    curvature = np.gradient(slope, sec[inside])
    peak = np.abs(slope).max()
    assert peak == pytest.approx(1.875 / blend, rel=1e-3)                 # 15/8 at mid-turn
    for end in (slice(0, 3), slice(-3, None)):
        assert np.abs(slope[end]).max() < 1e-3 * peak
    # no curvature at the ends either (a cubic smoothstep has its largest there)
    assert max(abs(curvature[0]), abs(curvature[-1])) < 0.05 * np.abs(curvature).max()
    # the positions do not jump: every step of the spliced path is one of A's, B's or the
    # fade's on a dense grid
    step = np.abs(np.diff(s.demo.observed, axis=0)).max()
    assert step <= peak * dt * np.abs(x0 - y0).max() * 1.01


def test_moving_recordings_join_without_a_jump(a, b):
    s = splice(a, b, 0.3)
    steps = np.abs(np.diff(s.demo.observed, axis=0)).max(axis=0)
    own = np.maximum(np.abs(np.diff(a.observed, axis=0)).max(axis=0),
                     np.abs(np.diff(b.observed, axis=0)).max(axis=0))
    start = int(np.searchsorted(s.demo.t, s.t_change))
    gap = np.abs(a.observed[start - 1] - b.observed[np.searchsorted(b.t, 0.3 * b.duration
                                                                    - 1e-9)])
    assert np.all(steps <= own + 1.875 / BLEND * 0.01 * gap + 1e-12)


def test_bad_splices_are_refused(a, b):
    for at in (0.0, 1.0, -0.1, 1.5, np.nan):
        with pytest.raises(ValueError, match='share of the first movement'):
            splice(a, b, at)
    for other in (_recording(1.5, 0.01, 2.0, 'x', 'x', P=1),
                  _recording(1.5, 0.01, 2.0, 'x', 'x', Q=2),
                  _recording(1.5, 0.01, 2.0, 'x', 'x', Q=0)):
        with pytest.raises(ValueError, match='different layouts'):
            splice(a, other, 0.5)
    for blend in (-0.1, np.nan):
        with pytest.raises(ValueError, match='blend'):
            splice(a, b, 0.5, blend=blend)
    with pytest.raises(ValueError, match='too few samples'):
        splice(a, b, 0.005)             # A's first 5 ms: one sample
    with pytest.raises(ValueError, match='too few samples'):
        splice(a, b, 0.999)             # B's last 1.5 ms: one sample


def test_missing_samples_stay_missing_and_leave_the_other_agents_join_alone(a, b):
    """A NaN row (a sample not recorded) where one agent is joined: that agent is not offset
    (no gap is known) and the other agent's join is as without it; NaN rows of B's rest stay
    NaN rows, and no other entry becomes NaN."""
    last, first = 40, 60                  # A's last sample and B's first at the share 0.4
    start = last + 1                      # the first sample of B's rest in the splice
    clean = splice(a, b, 0.4).demo
    for agent, other, recording, row in (('observed', 'controlled', 'a', last),
                                         ('controlled', 'observed', 'b', first)):
        x, y = _recording(1.0, 0.01, 0.0, 'reach', 'a1'), _recording(1.5, 0.01, 2.0, 'wave',
                                                                     'b7')
        getattr(x if recording == 'a' else y, agent)[row] = np.nan
        y.observed[[70, 71]] = np.nan     # rows of B's rest missing: both agents
        y.controlled[90] = np.nan
        d = splice(x, y, 0.4).demo
        missing = {'observed': [start + 10, start + 11], 'controlled': [start + 30]}
        missing[agent].append(last if recording == 'a' else start)
        for name in ('observed', 'controlled'):
            values = getattr(d, name)
            rows = np.isin(np.arange(len(d.t)), missing[name])
            assert np.array_equal(np.isnan(values), np.repeat(rows[:, None], values.shape[1], 1))
        # the agent whose join is missing: B's own rest, not offset
        assert np.array_equal(getattr(d, agent)[start:], getattr(y, agent)[first:],
                              equal_nan=True)
        # the other agent: joined at A's last positions as without the missing sample
        kept = ~np.isnan(getattr(d, other)).any(axis=1)
        assert np.array_equal(getattr(d, other)[kept], getattr(clean, other)[kept])
        assert np.allclose(getattr(d, other)[start], getattr(x, other)[last], rtol=0,
                           atol=1e-14)
