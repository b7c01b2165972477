"""The nearest-neighbour baseline of the interactions evaluation (app.evaluation.baselines
.NearestNeighbour): open-end DTW on the observed agent's prefix against the beginning of every
training recording, the match's controlled agent (time-scaled, and moved with translation
groups) as the prediction. The oracle: a held-out copy of a training recording must be matched
to it, at the very sample where its prefix ends (scale 1), and a copy moved by a known offset
must be predicted moved by that offset."""

import numpy as np
import pytest

from mixture_ip_ros.app.evaluation.baselines import NearestNeighbour
from mixture_ip_ros.core.demonstration import Demonstration

RATE = 30.0
FRACTIONS = (0.3, 0.5, 1.0)
SHARED = ((0, 3), (1, 4), (2, 5))


def _recording(kind, duration, n_ctrl=3):
    """Two 3-D hands (observed, controlled) at 30 Hz, shapes of different kinds: a sine, a
    straight line (at a minimum-jerk speed: a line at constant speed has one velocity
    throughout, which derivative DTW can match anywhere), a circle, a parabola."""
    t = np.arange(int(round(duration * RATE)) + 1) / RATE
    z = t / t[-1]
    if kind == 'sine':
        obs = np.column_stack([0.3 * np.sin(2 * np.pi * z), 0.1 * z, 0.2 + 0 * z])
    elif kind == 'line':
        s = 10 * z ** 3 - 15 * z ** 4 + 6 * z ** 5
        obs = np.column_stack([0.4 * s, -0.3 * s, 0.1 * s])
    elif kind == 'circle':
        obs = np.column_stack([0.2 * np.cos(np.pi * z), 0.2 * np.sin(np.pi * z), -0.1 * z])
    else:
        obs = np.column_stack([0.5 * z ** 2, 0.05 * np.sin(4 * z), 0.3 * (1 - z) ** 2])
    ctl = np.column_stack([1.0 - obs[:, 1], 0.5 * obs[:, 0] + 0.2, obs[:, 2] ** 2 + z])
    return Demonstration(t, obs, ctl[:, :n_ctrl] if n_ctrl else None, label=kind, name=kind)


KINDS = ('sine', 'line', 'circle', 'parabola')
DURATIONS = (2.0, 3.0, 2.5, 4.0)


def _training(n_ctrl=3):
    demos = [_recording(k, T, n_ctrl) for k, T in zip(KINDS, DURATIONS)]
    return demos, [d.label for d in demos]


def _moved(d, o_obs, o_ctl=None):
    return Demonstration(d.t.copy(), d.observed + o_obs,
                         None if o_ctl is None else d.controlled + o_ctl, d.label, 'moved')


def _rest(d, fraction):
    return np.flatnonzero(d.t > fraction * d.duration + 1e-9)


def _last_two(nn, d):
    """The stamps of the last two samples the baseline takes of ``d`` (decimated)."""
    t, _, _ = nn._series(d)
    return t[-2], t[-1]


def test_a_copy_of_a_training_recording_is_matched_to_it_at_scale_one():
    demos, labels = _training()
    nn = NearestNeighbour().fit(demos, labels)
    for j, d in enumerate(demos):
        copy = Demonstration(d.t.copy(), d.observed.copy(), d.controlled.copy())
        for (i, scale, shift), f in zip(nn.matches(copy, FRACTIONS), FRACTIONS):
            # Zero cost at the sample where the prefix ends: the same time, scale exactly 1.
            assert i == j and scale == pytest.approx(1.0, abs=1e-12), (j, f, i, scale)
            assert shift.shape == (3,) and np.array_equal(shift, np.zeros(3))
            rest = _rest(d, f)
            label, pred = nn.predict(i, scale, d.t[rest], shift)
            assert label == labels[j]
            assert pred.shape == (rest.size, 3)
            assert np.allclose(pred, d.controlled[rest], rtol=0, atol=1e-12)


def test_with_translation_a_copy_is_matched_to_it_at_scale_one_before_the_end():
    """Derivative DTW: the same samples, the same derivative estimates, zero cost where the
    prefix ends. At the end (fraction 1) the last two derivative estimates of both series are
    equal by construction (V[-1] = V[-2], Keogh and Pazzani's end rule), so the whole
    recording may be matched one decimated sample early: scale t[-2] / t[-1], and a shift of
    the difference of two means over almost the same samples (a few mm): nothing is left to
    predict there."""
    demos, labels = _training()
    nn = NearestNeighbour(translation=SHARED).fit(demos, labels)
    for j, d in enumerate(demos):
        (a, b, c) = nn.matches(Demonstration(d.t, d.observed, d.controlled), FRACTIONS)
        for (i, scale, shift), f in zip((a, b), FRACTIONS):
            assert i == j and scale == pytest.approx(1.0, abs=1e-12), (j, f, i, scale)
            assert np.allclose(shift, 0.0, atol=1e-12)
            rest = _rest(d, f)
            label, pred = nn.predict(i, scale, d.t[rest], shift)
            assert label == labels[j] and np.allclose(pred, d.controlled[rest], atol=1e-12)
        early, last = _last_two(nn, d)
        assert c[0] == j and c[1] in (pytest.approx(1.0), pytest.approx(early / last))
        assert np.all(np.abs(c[2]) < 0.01)


def test_a_copy_with_tiny_noise_is_still_matched_to_its_recording_at_about_scale_one():
    """Noise of 1 mm on paths that differ by tens of cm: the match is the same recording. On
    positions (no translation) the matched sample may move by a decimated step (2 / 30 s) or
    two, not at the end, where the movements come to rest and the last samples are alike.
    Derivative DTW (translation) localises the end less well under noise (1 mm of noise on
    steps of a few mm), so only the recording is asserted there."""
    demos, labels = _training()
    rng = np.random.default_rng(0)
    for translation in ((), SHARED):
        nn = NearestNeighbour(translation=translation).fit(demos, labels)
        for j, d in enumerate(demos):
            noisy = _moved(d, 0.001 * rng.standard_normal(d.observed.shape), 0.0)
            for (i, scale, _), f in zip(nn.matches(noisy, FRACTIONS), FRACTIONS):
                assert i == j, (translation, j, f, i)
                if f < 1 and not translation:
                    assert abs(scale - 1) * f * d.duration <= 2 * 2 / RATE + 1e-9, (j, f, scale)


def test_without_translation_a_slowed_copy_is_matched_at_the_time_scale_of_its_speed():
    """The copy runs 1.5 times slower: where its prefix ends (f 1.5 T) the training recording
    is at f T, so the scale is 1 / 1.5, the matched training time within a decimated step
    (2 / 30 s) of f T."""
    demos, labels = _training()
    nn = NearestNeighbour().fit(demos, labels)
    for j, d in enumerate(demos):
        t = np.arange(int(round(1.5 * d.duration * RATE)) + 1) / RATE
        obs = np.column_stack([np.interp(t / 1.5, d.t, d.observed[:, k]) for k in range(3)])
        slow = Demonstration(t, obs, np.zeros((t.size, 3)))
        t_s, _, _ = nn._series(slow)
        for (i, scale, _), f in zip(nn.matches(slow, FRACTIONS), FRACTIONS):
            n = int(np.searchsorted(t_s, f * slow.duration + 1e-9, side='right'))
            assert i == j, (j, f, i)
            assert abs(scale * t_s[n - 1] - t_s[n - 1] / 1.5) <= 2 / RATE + 1e-9, (j, f, scale)


def test_with_translation_a_moved_copy_is_matched_and_its_partner_predicted_moved_by_the_offset():
    """Derivative DTW does not see the offset; the shift is the prefix's mean observed position
    minus the matched training prefix's (the same samples, here), hence exactly the offset."""
    demos, labels = _training()
    nn = NearestNeighbour(translation=SHARED).fit(demos, labels)
    o = np.array([0.4, -0.25, 0.15])
    fractions = (0.3, 0.5, 0.8)
    for j, d in enumerate(demos):
        moved = _moved(d, o, o)
        for (i, scale, shift), f in zip(nn.matches(moved, fractions), fractions):
            assert i == j and scale == pytest.approx(1.0, abs=1e-12), (j, f, i, scale)
            assert np.allclose(shift, o, rtol=0, atol=1e-12)
            rest = _rest(d, f)
            label, pred = nn.predict(i, scale, moved.t[rest], shift)
            assert label == labels[j]
            assert np.allclose(pred, moved.controlled[rest], rtol=0, atol=1e-12)
        (i, _, shift), = nn.matches(moved, (1.0,))
        assert i == j and np.allclose(shift, o, atol=0.01)       # see the end rule above


def test_the_shift_is_the_difference_of_the_prefix_means_of_the_matched_samples():
    """A copy moved by o with 1 mm noise: the shift is the mean of the prefix's decimated
    observed samples minus the mean of the training recording's up to the matched one (read
    back from the scale), per axis; and o to within the noise's and the matched segment's
    differences (3 cm, against offsets of 10-30 cm: derivative DTW may end the match a few
    samples off under noise, and the two prefix means then differ by a cm or so)."""
    demos, labels = _training()
    nn = NearestNeighbour(translation=SHARED).fit(demos, labels)
    rng = np.random.default_rng(1)
    o = np.array([0.1, 0.2, -0.3])
    for j, d in enumerate(demos):
        probe = _moved(d, o + 0.001 * rng.standard_normal(d.observed.shape), o)
        t_p, _, raw = nn._series(probe)
        t_tr, _, raw_tr = nn._train[j]
        for (i, scale, shift), f in zip(nn.matches(probe, FRACTIONS), FRACTIONS):
            assert i == j
            n = int(np.searchsorted(t_p, f * probe.duration + 1e-9, side='right'))
            m = int(np.argmin(np.abs(t_tr - scale * t_p[n - 1])))   # the matched sample
            assert abs(t_tr[m] - scale * t_p[n - 1]) < 1e-9
            expected = raw[:n].mean(axis=0) - raw_tr[:m + 1].mean(axis=0)
            assert np.allclose(shift, expected, rtol=0, atol=1e-12)
            assert np.allclose(shift, o, atol=0.03), (j, f, shift)


def test_without_translation_the_shift_is_zero_even_for_a_moved_copy():
    demos, labels = _training()
    nn = NearestNeighbour().fit(demos, labels)
    moved = _moved(demos[2], np.array([0.3, 0.3, 0.3]), 0.3)
    for i, scale, shift in nn.matches(moved, FRACTIONS):
        assert np.array_equal(shift, np.zeros(3))


@pytest.mark.parametrize('translation', [(), ((0,), (1,), (2,))])
def test_a_single_agent_set_is_matched_and_predicts_an_empty_partner(translation):
    demos, labels = _training(n_ctrl=0)
    nn = NearestNeighbour(translation=translation).fit(demos, labels)
    o = np.array([0.2, -0.1, 0.05]) if translation else np.zeros(3)
    for j, d in enumerate(demos):
        probe = _moved(d, o)
        early, last = _last_two(nn, d)
        for (i, scale, shift), f in zip(nn.matches(probe, FRACTIONS), FRACTIONS):
            assert i == j and (scale == pytest.approx(1.0, abs=1e-12)
                               or (f == 1.0 and translation
                                   and scale == pytest.approx(early / last)))
            assert shift.shape == (0,)
            times = d.t[_rest(d, f)]
            label, pred = nn.predict(i, scale, times, shift)
            assert label == labels[j] and pred.shape == (times.size, 0)
        label, pred = nn.predict(j, 1.0, d.t)
        assert label == labels[j] and pred.shape == (d.t.size, 0)


def test_predict_time_scales_the_partner_and_holds_its_last_sample_after_the_end():
    demos, labels = _training()
    nn = NearestNeighbour().fit(demos, labels)
    d = demos[0]
    times = np.array([0.0, 0.5, 1.0, 3.0])
    label, pred = nn.predict(0, 2.0, times)
    s = np.clip(times * 2.0, 0, d.duration)
    expected = np.column_stack([np.interp(s, d.t, d.controlled[:, k]) for k in range(3)])
    assert label == 'sine' and np.allclose(pred, expected)
    assert np.allclose(pred[-2:], d.controlled[-1])
    _, moved = nn.predict(0, 2.0, times, np.array([1.0, 2.0, 3.0]))
    assert np.allclose(moved - pred, [1.0, 2.0, 3.0])


@pytest.mark.parametrize('translation', [(), SHARED])
def test_a_prefix_is_matched_on_its_own_samples_only(translation):
    """Two probes identical up to the end of the prefix (half the movement) that part smoothly
    after it (4 mm at the next sample taken) must get the same match for that prefix: the
    baseline sees the prefix only, as the mixture's online estimator does."""
    demos, labels = _training()
    d = demos[3]
    end = 0.5 * d.duration
    after = d.t > end + 1e-9
    bent = d.observed.copy()
    bent[after, 1] += (d.t[after] - end) ** 2
    nn = NearestNeighbour(translation=translation).fit(demos, labels)
    (a,) = nn.matches(Demonstration(d.t, d.observed, d.controlled), (0.5,))
    (b,) = nn.matches(Demonstration(d.t, bent, d.controlled), (0.5,))
    assert (a[0], a[1]) == (b[0], b[1]) and np.array_equal(a[2], b[2]), (a, b)


def test_a_group_of_controlled_dofs_only_gives_a_finite_shift():
    """Nothing observed moves with such a group: nothing to infer its shift from, and the
    prediction must still be a number (the training partner unmoved is the natural one)."""
    demos, labels = _training()
    nn = NearestNeighbour(translation=((3,),)).fit(demos, labels)
    (i, scale, shift), = nn.matches(demos[0], (0.5,))
    assert np.all(np.isfinite(shift)), shift
