"""Loading bags into Demonstrations: time base, frames, gaps as missing data, bad bags in a folder."""

import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mixture_ip_ros.io.bags import BagError, write_demonstration_bag
from mixture_ip_ros.core.frames import FrameTransform
from mixture_ip_ros.io.dataset import (find_bags, load_dataset,
                                         load_demonstration, resample_wrist)

REST0, MOVE, REST1 = 0.4, 1.5, 0.6
START = np.array([1.3, -0.1, 1.0])
GOAL = np.array([0.75, 0.15, 1.25])


def truth_wrist(t):
    """Minimum-jerk reach in the robot base frame: at rest, reach, at rest."""
    s = np.clip((np.asarray(t) - REST0) / MOVE, 0, 1)
    h = 10 * s**3 - 15 * s**4 + 6 * s**5
    return START + h[:, None] * (GOAL - START)


def truth_joints(t):
    return np.column_stack([0.3 * np.sin(1.7 * t + j) + 0.1 * j for j in range(7)])


TF = FrameTransform(translation=(0.2, -0.5, 0.8),
                    quaternion=tuple(Rotation.from_euler('zyx', [70, 10, -5], degrees=True).as_quat()))


def _bag(path, rate=100.0, gap=None, joint_t=None, transform=TF, **kw):
    t = np.arange(0, REST0 + MOVE + REST1, 1 / rate)
    base = truth_wrist(t)
    # The bag holds the mocap world frame: invert p_base = R p_world + tr.
    R = Rotation.from_quat(transform.quaternion).as_matrix()
    world = (base - np.asarray(transform.translation)) @ R
    if gap is not None:
        world[(t >= gap[0]) & (t < gap[1])] = np.nan
    jt = np.arange(0, REST0 + MOVE + REST1, 0.01) if joint_t is None else joint_t
    return write_demonstration_bag(path, t, world, jt, truth_joints(jt), **kw), t


def test_frame_transform_matches_scipy():
    p = np.random.default_rng(1).normal(size=(10, 3))
    R = Rotation.from_quat(TF.quaternion)
    np.testing.assert_allclose(TF.apply_array(p), R.apply(p) + TF.translation, atol=1e-12)
    with pytest.raises(ValueError, match='not unit length'):
        FrameTransform(quaternion=(0, 0, 0, 2))


def test_resample_wrist_by_hand():
    t = np.array([0.0, 0.01, 0.02, 0.05, 0.06])
    x = np.column_stack([t * 100, t * 100, t * 100])  # x = sample index-ish, linear
    out = resample_wrist(t, x, np.array([0.005, 0.02, 0.03, 0.045, 0.055, 0.061, 0.08, -0.001]),
                         0.0125)
    np.testing.assert_allclose(out[:2, 0], [0.5, 2.0])
    assert np.isnan(out[2]).all()               # 0.03 and 0.045 lie in the 0.02..0.05 hole:
    assert np.isnan(out[3]).all()               # 30 ms > 2 * 12.5 ms, never bridged
    np.testing.assert_allclose(out[4], [5.5] * 3)
    np.testing.assert_allclose(out[5, 0], 6.0)  # just after the last sample: held
    assert np.isnan(out[6]).all()
    np.testing.assert_allclose(out[7, 0], 0.0)  # just before the first sample: held
    # One missing sample (0.00..0.02, 20 ms) is bridged; a NaN sample counts as absent.
    x[1] = np.nan
    np.testing.assert_allclose(resample_wrist(t, x, np.array([0.012]), 0.0125)[0], [1.2] * 3)
    assert np.isnan(resample_wrist(t, x, np.array([0.012]), 0.009)).all()


def test_load_demonstration_onset_time_base_and_robot_frame(tmp_path):
    bag, _ = _bag(tmp_path / 'plate_03', label='plate')
    demo = load_demonstration(bag, transform=(TF.translation, TF.quaternion), dt=0.01)
    assert demo.name == 'plate_03' and demo.label == 'plate'
    np.testing.assert_allclose(demo.t, 0.01 * np.arange(demo.t.size), atol=1e-12)
    # Onset/end found by segment_motion on the robot-frame stream.
    from mixture_ip_ros.core.segmentation import segment_motion
    tt = np.arange(0, REST0 + MOVE + REST1, 0.01)
    onset, end = segment_motion(tt, truth_wrist(tt))
    assert abs(onset - REST0) < 0.08 and abs(end - (REST0 + MOVE)) < 0.15
    assert demo.t.size == int(np.floor((end - onset) / 0.01 + 1e-9)) + 1
    grid = onset + demo.t
    assert not np.isnan(demo.observed).any()
    np.testing.assert_allclose(demo.observed, truth_wrist(grid), atol=2e-4)  # linear interp error
    np.testing.assert_allclose(demo.controlled, truth_joints(grid), atol=2e-4)


def test_occlusion_becomes_missing_rows_not_interpolated(tmp_path):
    gap = (1.0, 1.2)
    bag, t = _bag(tmp_path / 'b', gap=gap)
    demo = load_demonstration(bag, transform=TF)
    from mixture_ip_ros.core.segmentation import segment_motion
    kept = (t < gap[0]) | (t >= gap[1])
    onset, _ = segment_motion(t[kept], truth_wrist(t[kept]))
    grid = onset + demo.t
    have = t[kept]
    # Independent oracle: a grid time is observed iff the recorded samples around it are at most
    # 2 * 1.25 periods = 25 ms apart.
    prev = np.array([have[have <= g].max() for g in grid])
    nxt = np.array([have[have >= g].min() for g in grid])
    expect_missing = nxt - prev > 0.025
    missing = np.isnan(demo.observed).all(axis=1)
    np.testing.assert_array_equal(missing, expect_missing)
    assert 18 <= missing.sum() <= 22  # ~0.2 s at 100 Hz
    np.testing.assert_allclose(demo.observed[~missing], truth_wrist(grid[~missing]), atol=2e-4)
    assert not np.isnan(demo.controlled).any()


def test_single_dropped_packet_is_bridged_and_other_rates(tmp_path):
    bag, _ = _bag(tmp_path / 'drop', gap=(1.0, 1.005))  # exactly one sample lost
    assert not np.isnan(load_demonstration(bag, transform=TF).observed).any()
    bag, _ = _bag(tmp_path / 'r120', rate=120.0)
    demo = load_demonstration(bag, transform=TF, dt=0.02)
    assert not np.isnan(demo.observed).any()
    np.testing.assert_allclose(np.diff(demo.t), 0.02)
    assert abs(demo.duration - MOVE) < 0.2


def test_samples_the_observer_drops_are_missing_when_a_bag_is_loaded(tmp_path):
    """A tracker that jumps 0.6 m away for 2 samples mid-reach: the observer refuses both (no
    hand moves that fast), so training must not see them either."""
    bag, t = _bag(tmp_path / 'glitch')
    clean = load_demonstration(bag, transform=TF)
    from mixture_ip_ros.io.bags import read_bag
    rec = read_bag(bag)
    xyz = rec.wrist_xyz.copy()
    jump = (t > 0.995) & (t < 1.015)
    assert jump.sum() == 2
    xyz[jump] += (0.0, 0.0, -0.6)
    bag2 = write_demonstration_bag(tmp_path / 'glitch2', t, xyz, rec.joint_t, rec.joint_q)
    demo = load_demonstration(bag2, transform=TF)
    assert demo.t.size == clean.t.size
    missing = np.isnan(demo.observed).any(axis=1)
    assert 1 <= missing.sum() <= 3                     # the two samples, seen on a 10 ms grid
    np.testing.assert_allclose(demo.observed[~missing], clean.observed[~missing])


def test_bad_recordings_name_the_bag(tmp_path):
    bag, _ = _bag(tmp_path / 'short_joints', joint_t=np.arange(0, 1.0, 0.01))
    with pytest.raises(BagError, match='joint states cover') as err:
        load_demonstration(bag, transform=TF)
    assert str(bag) in str(err.value)
    jt = np.arange(0, REST0 + MOVE + REST1, 0.01)
    bag, _ = _bag(tmp_path / 'hole', joint_t=jt[(jt < 1.0) | (jt > 1.3)])
    with pytest.raises(BagError, match='hole'):
        load_demonstration(bag, transform=TF)
    t = np.arange(0, 2, 0.01)
    still = write_demonstration_bag(tmp_path / 'still', t, np.tile(START, (t.size, 1)), t,
                                    np.zeros((t.size, 7)))
    with pytest.raises(BagError, match='no movement onset'):
        load_demonstration(still)
    bag, _ = _bag(tmp_path / 'frame', frame_id='camera')
    with pytest.raises(BagError, match="frame 'camera', expected 'world'"):
        load_demonstration(bag, transform=TF, wrist_frame='world')


def test_load_dataset_skips_or_raises_on_a_bad_bag(tmp_path, caplog):
    for i in range(3):
        _bag(tmp_path / f'demo_{i}', label=f'p{i}')
    bad, _ = _bag(tmp_path / 'demo_bad')
    f = next(bad.glob('*.mcap'))
    f.write_bytes(f.read_bytes()[:1000])
    (tmp_path / 'labels.json').write_text('{}')
    (tmp_path / 'plots').mkdir()
    assert [p.name for p in find_bags(tmp_path)] == ['demo_0', 'demo_1', 'demo_2', 'demo_bad']
    with caplog.at_level(logging.WARNING, logger='mixture_ip_ros.io.dataset'):
        demos, skipped = load_dataset(tmp_path, transform=TF)
    assert [d.label for d in demos] == ['p0', 'p1', 'p2']
    assert len(skipped) == 1 and skipped[0].path.name == 'demo_bad'
    assert 'demo_bad' in caplog.text
    with pytest.raises(BagError, match='demo_bad'):
        load_dataset(tmp_path, on_error='raise', transform=TF)
    with pytest.raises(ValueError, match='on_error'):
        load_dataset(tmp_path, on_error='ignore')


def test_load_dataset_empty_or_all_bad(tmp_path):
    (tmp_path / 'empty').mkdir()
    with pytest.raises(ValueError, match='no rosbag2 bags'):
        load_dataset(tmp_path / 'empty')
    with pytest.raises(ValueError, match='does not exist'):
        load_dataset(tmp_path / 'missing')
    (tmp_path / 'bad' / 'x').mkdir(parents=True)
    (tmp_path / 'bad' / 'x' / 'x.mcap').write_bytes(b'junk')
    with pytest.raises(ValueError, match='none of the 1 bags'):
        load_dataset(tmp_path / 'bad')


def test_a_recorded_cut_is_used_where_asked_for_and_required_then(tmp_path):
    """cut='recorded': the bag's own onset and end (its annotator's), not the detector's; the
    rows are the same samples as the detector's cut would give at those times."""
    onset, end = REST0 + 0.1, REST0 + MOVE - 0.2
    bag, _ = _bag(tmp_path / 'cut', segment=(onset, end))
    demo = load_demonstration(bag, transform=TF, cut='recorded')
    assert demo.duration == pytest.approx(end - onset, abs=1e-9)
    np.testing.assert_allclose(demo.observed, truth_wrist(onset + demo.t), atol=1e-9)
    np.testing.assert_allclose(demo.controlled, truth_joints(onset + demo.t), atol=1e-9)
    detected = load_demonstration(bag, transform=TF)
    assert detected.duration == pytest.approx(MOVE, abs=0.06)
    plain, _ = _bag(tmp_path / 'plain')
    with pytest.raises(BagError, match='no recorded movement interval'):
        load_demonstration(plain, transform=TF, cut='recorded')
    with pytest.raises(ValueError, match="cut must be 'detected' or 'recorded'"):
        load_demonstration(bag, transform=TF, cut='annotated')
    with pytest.raises(ValueError, match='onset < end'):
        _bag(tmp_path / 'bad', segment=(end, onset))
