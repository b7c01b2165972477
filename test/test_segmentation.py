"""Motion segmentation against synthetic minimum-jerk reaches with known start and stop."""

import math

import numpy as np
import pytest

from mixture_ip_ros.core.cubic_onset import fit_cubic_onset
from mixture_ip_ros.core.segmentation import Event, MotionSegmenter, segment_motion

T_ABS = 1.7e9  # realistic epoch stamps: exercises the running sums' precision


def min_jerk(s):
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def reach(rate, distance, duration, start=1.0, tail=1.5, noise=5e-4, seed=0, curve=0.05,
          t0=0.0):
    """A curved minimum-jerk reach in 3-D: (t, positions, true onset, true end)."""
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(0.0, start + duration + tail, 1.0 / rate)
    s = min_jerk((t - t0 - start) / duration)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    side = np.cross(d, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    p = (np.array([0.4, -0.2, 1.1]) + np.outer(s * distance, d)
         + np.outer(curve * np.sin(np.pi * s), side))
    p += rng.normal(scale=noise, size=p.shape)
    return t, p, t0 + start, t0 + start + duration


def run_stream(seg, t, p):
    """Feed a stream; returns [(event, time of the sample that produced it)]."""
    out = []
    for ti, pi in zip(t.tolist(), p.tolist()):
        if not math.isnan(pi[0]):
            out.extend((ev, ti) for ev in seg.update(ti, pi))
    return out


@pytest.mark.parametrize('rate, noise, onset_tol', [(500, 1e-3, 0.03), (1000, 1e-3, 0.03),
                                                     (100, 1e-3, 0.05)])
def test_onset_and_end_of_min_jerk_reaches(rate, noise, onset_tol):
    rng = np.random.default_rng(rate)
    for seed in range(10):
        distance, duration = rng.uniform(0.25, 0.5), rng.uniform(0.7, 1.5)
        t, p, true_on, true_end = reach(rate, distance, duration, noise=noise, seed=seed, t0=T_ABS)
        onset, end = segment_motion(t, p)
        assert abs(onset - true_on) < onset_tol, (seed, onset - true_on)
        assert abs(end - true_end) < 0.06, (seed, end - true_end)


def test_slow_reaches_occluded_while_rising():
    # Like the generated box-assembly data: 100 Hz, 1 mm noise, 2-3 s reaches, short rests,
    # and an occlusion that starts before the detector is sure of the onset.
    rng = np.random.default_rng(5)
    for seed in range(10):
        distance, duration = rng.uniform(0.25, 0.5), rng.uniform(2.0, 3.0)
        t, p, true_on, true_end = reach(100, distance, duration, start=0.4, tail=0.5,
                                        noise=1e-3, seed=seed)
        p[(t >= true_on + 0.1 * duration) & (t < true_on + 0.1 * duration + 0.2)] = np.nan
        kinds = [ev.kind for ev, _ in run_stream(MotionSegmenter(), t, p)]
        assert kinds == ['gap', 'onset', 'end'] or kinds == ['onset', 'gap', 'end'], kinds
        onset, end = segment_motion(t, p)
        assert abs(onset - true_on) < 0.08, (seed, onset - true_on)
        assert abs(end - true_end) < 0.08, (seed, end - true_end)


def test_fit_cubic_onset_recovers_a_known_onset():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 1.0, 0.004)
    direction = np.array([0.6, -0.8, 0.0])
    for t_on in (0.2, 0.537, 0.8):
        p = 0.3 + np.outer(4.0 * np.clip(t - t_on, 0, None) ** 3, direction)
        assert fit_cubic_onset(t, p, 0.0, 0.95) == pytest.approx(t_on, abs=1e-3)
        noisy = p + rng.normal(scale=5e-4, size=p.shape)
        assert fit_cubic_onset(t, noisy, 0.0, 0.95) == pytest.approx(t_on, abs=0.03)
    # Reversed time dates an end (arrival at rest) the same way.
    arrival = 1.0 - np.outer(4.0 * np.clip(0.6 - t, 0, None) ** 3, direction)
    assert -fit_cubic_onset(-t[::-1], arrival[::-1], -0.95, -0.05) == pytest.approx(0.6, abs=1e-3)
    # The answer stays in [lo, hi] even when the data would put it elsewhere.
    p = 0.3 + np.outer(4.0 * np.clip(t - 0.5, 0, None) ** 3, direction)
    assert 0.0 <= fit_cubic_onset(t, p, 0.0, 0.3) <= 0.3


def test_onset_is_back_dated_from_detection():
    t, p, true_on, true_end = reach(500, 0.4, 1.0, seed=3)
    events = run_stream(MotionSegmenter(), t, p)
    assert [ev.kind for ev, _ in events] == ['onset', 'end']
    (onset, t_detect), (end, t_end_detect) = events
    # The detector needs the hand well under way before it is sure ...
    assert t_detect - true_on > 0.1
    assert t_end_detect - true_end > 0.25
    # ... but dates the events to when the hand started / stopped.
    assert abs(onset.time - true_on) < 0.03
    assert abs(end.time - true_end) < 0.1
    assert onset.time < t_detect and end.time < t_end_detect


def test_streaming_and_offline_agree_exactly():
    t, p, _, _ = reach(250, 0.35, 1.2, seed=5)
    p[300:310] = np.nan  # a short occlusion mid-reach
    events = [ev for ev, _ in run_stream(MotionSegmenter(onset_hold=0.08), t, p)]
    onset, end = segment_motion(t, p, onset_hold=0.08)
    assert events == [Event('onset', onset), Event('end', end)]


def test_time_origin_does_not_change_the_result():
    t, p, _, _ = reach(500, 0.3, 0.9, seed=7)
    on0, end0 = segment_motion(t, p)
    on1, end1 = segment_motion(t + T_ABS, p)
    # Adding 1.7e9 rounds the stamps to 2.4e-7 s; sums over absolute stamps would lose
    # every digit (t^2 ~ 3e18), relative sums lose none.
    assert on1 - T_ABS == pytest.approx(on0, abs=2e-6)
    assert end1 - T_ABS == pytest.approx(end0, abs=2e-6)


def test_stationary_noise_gives_no_onset():
    rng = np.random.default_rng(11)
    for rate, noise in [(500, 1e-3), (100, 0.5e-3)]:
        t = np.arange(0.0, 10.0, 1.0 / rate)
        p = np.array([0.5, 0.0, 1.0]) + rng.normal(scale=noise, size=(t.size, 3))
        seg = MotionSegmenter()
        assert run_stream(seg, t, p) == []
        assert not seg.moving
        with pytest.raises(ValueError, match='no movement'):
            segment_motion(t, p)


def test_slow_drift_below_onset_speed_is_not_a_movement():
    t = np.arange(0.0, 6.0, 1.0 / 200)
    p = np.zeros((t.size, 3))
    p[:, 0] = 0.02 * t  # 2 cm/s creep (e.g. marker slip, posture sway)
    p += np.random.default_rng(2).normal(scale=3e-4, size=p.shape)
    with pytest.raises(ValueError, match='no movement'):
        segment_motion(t, p)


def test_nan_rows_are_skipped():
    t, p, true_on, true_end = reach(500, 0.4, 1.0, seed=9)
    holes = p.copy()
    rows = np.random.default_rng(0).choice(t.size, size=t.size // 10, replace=False)
    holes[rows] = np.nan  # 10 % of samples missing, scattered
    on_h, end_h = segment_motion(t, holes)
    assert abs(on_h - true_on) < 0.03 and abs(end_h - true_end) < 0.15
    keep = ~np.isnan(holes).any(axis=1)
    assert segment_motion(t[keep], p[keep]) == (on_h, end_h)


def test_long_occlusion_mid_reach_gives_gap_and_keeps_interaction():
    t, p, true_on, true_end = reach(500, 0.5, 1.5, seed=4)
    lost = (t > true_on + 0.5) & (t < true_on + 0.8)  # 0.3 s occlusion at full speed
    p[lost] = np.nan
    events = [ev for ev, _ in run_stream(MotionSegmenter(), t, p)]
    last_before = t[np.argmax(lost) - 1]
    assert [ev.kind for ev in events] == ['onset', 'gap', 'end']
    assert events[1].time == last_before
    assert abs(events[0].time - true_on) < 0.03
    assert abs(events[2].time - true_end) < 0.15
    assert segment_motion(t, p) == (events[0].time, events[2].time)


def test_gap_reported_once_early_or_late():
    t = np.arange(0.0, 1.0, 0.002)
    p = np.tile([0.5, 0.0, 1.0], (t.size, 1))
    seg = MotionSegmenter(gap_timeout=0.1)
    run_stream(seg, t, p)
    last = float(t[-1])
    assert seg.gap(last + 0.05) == []               # not silent long enough yet
    assert seg.gap(last + 0.2) == [Event('gap', last)]
    assert seg.gap(last + 0.4) == []                # once per silence
    assert seg.update(last + 0.5, p[0]) == []       # already reported
    # Offline, the same gap is found from the stamps alone.
    seg2 = MotionSegmenter(gap_timeout=0.1)
    run_stream(seg2, t, p)
    assert seg2.update(last + 0.5, p[0]) == [Event('gap', last)]


def test_long_silence_during_interaction_closes_it():
    t, p, true_on, _ = reach(500, 0.4, 1.0, seed=1)
    cut = t < true_on + 0.5
    seg = MotionSegmenter(max_gap=2.0)
    events = run_stream(seg, t[cut], p[cut])
    assert [ev.kind for ev, _ in events] == ['onset'] and seg.moving
    last = float(t[cut][-1])
    assert seg.gap(last + 1.0) == [Event('gap', last)]
    assert seg.moving  # an occlusion, not yet lost
    assert seg.gap(last + 2.5) == [Event('end', last)]
    assert not seg.moving


def test_two_reaches_and_first_is_returned():
    t1, p1, on1, end1 = reach(500, 0.4, 1.0, seed=2, tail=1.0)
    back = p1[::-1][1:]
    t2 = t1[-1] + (t1[1:] - t1[0])
    t = np.concatenate([t1, t2])
    p = np.concatenate([p1, back])
    # The reach back starts at the mirror image of the first one's end.
    on2 = t1[-1] + (t1[-1] - end1)
    end2 = t1[-1] + (t1[-1] - on1)
    events = [ev for ev, _ in run_stream(MotionSegmenter(), t, p)]
    assert [ev.kind for ev in events] == ['onset', 'end', 'onset', 'end']
    assert abs(events[0].time - on1) < 0.03 and abs(events[1].time - end1) < 0.15
    assert abs(events[2].time - on2) < 0.03 and abs(events[3].time - end2) < 0.15
    assert segment_motion(t, p) == (events[0].time, events[1].time)


def test_recording_stopping_while_moving():
    t, p, true_on, true_end = reach(500, 0.4, 1.0, seed=6)
    moving = t < true_on + 0.6
    onset, end = segment_motion(t[moving], p[moving])
    assert abs(onset - true_on) < 0.03
    assert end == t[moving][-1]
    # Stopped shortly after the hand came to rest (rest not yet confirmed): end is that rest.
    short = t < true_end + 0.15
    onset2, end2 = segment_motion(t[short], p[short])
    assert onset2 == onset
    assert abs(end2 - true_end) < 0.1


def test_a_silence_at_rest_confirms_the_end_as_samples_at_rest_would():
    """The hand comes to rest and the tracker loses it before the rest is long enough to
    confirm: a silence of end_hold confirms the end the recording's end gives (dated from the
    same samples), online as offline, once; a shorter one, or one at speed, does not."""
    t, p, true_on, true_end = reach(500, 0.4, 1.0, seed=6)
    short = t < true_end + 0.15
    onset, end = segment_motion(t[short], p[short])           # the recording stops there
    seg = MotionSegmenter()
    assert [ev.kind for ev, _ in run_stream(seg, t[short], p[short])] == ['onset']
    last = float(t[short][-1])
    assert seg.gap(last + 0.11) == [Event('gap', last)] and seg.moving
    assert seg.gap(last + seg.end_hold - 0.01) == [] and seg.moving
    assert seg.gap(last + seg.end_hold) == [Event('end', end)] and not seg.moving
    assert seg.gap(last + 1.0) == []
    assert abs(end - true_end) < 0.1
    lost = (t >= true_end + 0.15) & (t < true_end + 0.75)     # offline: the samples come back
    assert segment_motion(t[~lost], p[~lost]) == (onset, end)
    seg = MotionSegmenter()
    kinds = [ev.kind for ev, _ in run_stream(seg, t[~lost], p[~lost])]
    assert kinds == ['onset', 'gap', 'end']
    fast = t < true_on + 0.5
    seg = MotionSegmenter()
    run_stream(seg, t[fast], p[fast])
    assert seg.gap(float(t[fast][-1]) + 1.0) == [Event('gap', float(t[fast][-1]))]
    assert seg.moving


def test_onset_never_before_stream_start():
    t, p, true_on, _ = reach(500, 0.4, 1.0, seed=8)
    late = t > true_on + 0.15  # recording starts with the hand already moving
    onset, _ = segment_motion(t[late], p[late])
    assert t[late][0] <= onset < true_on + 0.3


def wandering(t, speed_lo, speed_hi, rng):
    """Positions of a hand that never holds still: speed between speed_lo and speed_hi,
    direction turning slowly."""
    speed = rng.uniform(speed_lo, speed_hi, t.size)
    speed = np.convolve(speed, np.ones(15) / 15, mode='same')
    speed = np.clip(speed, speed_lo, speed_hi)
    turn = np.cumsum(rng.normal(0, 0.15, t.size))
    v = speed[:, None] * np.column_stack([np.cos(turn), np.sin(turn), 0.3 * np.sin(2 * turn)])
    return np.cumsum(v * np.gradient(t)[:, None], axis=0)


def test_real_hand_drifting_before_and_hovering_after_is_segmented():
    """A 120 Hz recording of a handover: the wrist drifts at 4-7 cm/s before the reach (above
    the 6 cm/s floor) and hovers at 4-8 cm/s after it (never under the 3 cm/s floor); mocap
    jitter 0.1-0.24 mm. Fixed speeds fire the onset at t = 0 and never see the end."""
    rng = np.random.default_rng(4)
    rate, start, duration, tail = 120.0, 1.5, 1.2, 2.0
    t = np.arange(0.0, start + duration + tail, 1.0 / rate)
    pre = t < start
    post = t > start + duration
    s = min_jerk((t - start) / duration)
    p = np.outer(s * 0.45, [0.8, 0.5, 0.33])
    drift = wandering(t, 0.04, 0.07, rng)
    hover = wandering(t, 0.04, 0.08, rng)
    p[pre] += drift[pre] - drift[pre][-1]
    p[post] += hover[post] - hover[post][0]
    jitter = rng.uniform(0.1e-3, 0.24e-3, t.size)[:, None] * rng.normal(size=(t.size, 3))
    p += jitter
    fixed = dict(rest_min=0.0, onset_noise_factor=1e-9, end_noise_factor=1e-10)
    events = [ev for ev, _ in run_stream(MotionSegmenter(**fixed), t, p)]
    assert events and events[0].kind == 'onset' and events[0].time < 0.3    # the failure
    assert 'end' not in [ev.kind for ev in events[:2]] or events[1].time < start
    seg = MotionSegmenter()
    events = [ev for ev, _ in run_stream(seg, t, p)]
    assert [ev.kind for ev in events] == ['onset', 'end'], events
    assert abs(events[0].time - start) < 0.15
    assert abs(events[1].time - (start + duration)) < 0.3
    assert seg.onset_threshold > 0.06 and seg.end_threshold > 0.03


def test_invalid_input_is_rejected():
    seg = MotionSegmenter()
    seg.update(0.0, (0, 0, 0))
    with pytest.raises(ValueError, match='strictly increase'):
        seg.update(0.0, (0, 0, 0))
    with pytest.raises(ValueError, match='non-finite'):
        seg.update(1.0, (np.nan, 0, 0))
    with pytest.raises(ValueError, match='3 numbers'):
        seg.update(1.0, (0, 0))
    with pytest.raises(ValueError, match='below'):
        MotionSegmenter(onset_speed=0.02, end_speed=0.03)
    with pytest.raises(ValueError, match='speed_window'):
        MotionSegmenter(speed_window=0.0)
    t = np.arange(10.0)
    with pytest.raises(ValueError, match='shape'):
        segment_motion(t, np.zeros((10, 2)))
    with pytest.raises(ValueError, match='strictly increasing'):
        segment_motion(t[::-1], np.zeros((10, 3)))
    with pytest.raises(ValueError, match='Inf'):
        segment_motion(t, np.full((10, 3), np.inf))


def test_rest_statistics_median_is_numpys():
    """The rest level and spread come from sorted lists: np.median's values exactly (odd and
    even counts, ties)."""
    from mixture_ip_ros.core.segmentation import median_sorted
    rng = np.random.default_rng(2)
    for n in list(range(1, 40)) + [99, 100, 500, 501]:
        v = np.abs(rng.normal(0.05, 0.02, n))
        v[rng.integers(n, size=n // 3)] = v[0]
        level = median_sorted(sorted(v.tolist()))
        assert level == float(np.median(v))
        assert median_sorted(sorted(abs(x - level) for x in v.tolist())) == \
            float(np.median(np.abs(v - level)))
