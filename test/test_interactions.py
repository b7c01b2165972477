"""The interactions scenario: its settings file and their one-line errors, the frames derived
from the data, the arm in the partner's place for every shipped arm, and training and the
observer sharing time zero on the replayed streams."""

import math

import numpy as np
import pytest
import yaml

from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.io.cache import cache_dir
from mixture_ip_ros.robot.description import shipped_robots
from mixture_ip_ros.scenarios import interactions, nuisi


@pytest.fixture(scope='module')
def data():
    """The NuiSI v2 recordings, where the user cache has them (./dev seeds it)."""
    if not (cache_dir() / 'nuisi' / nuisi.VERSIONS['v2'].file).is_file():
        pytest.skip('NuiSI is not in the user cache (./dev seeds it from ../shared/data/nuisi)')
    return {split: nuisi.recordings('v2', split) for split in ('train', 'test')}


def _shipped():
    return yaml.safe_load(config_path(interactions.CONFIG_FILE).read_text())


def _write(tmp_path, change):
    settings = _shipped()
    change(settings)
    path = tmp_path / 'interactions.yaml'
    path.write_text(yaml.safe_dump(settings))
    return path


def test_the_shipped_settings_load():
    c = interactions.load_config()
    assert c.data == 'v2' and c.person1_yaw == pytest.approx(math.pi)
    assert c.rest_after >= c.observer['end_hold']
    assert interactions.segmentation(c) == {'end_hold': 1.0}
    assert interactions.estimator_settings(c) == {'hedge': True}


@pytest.mark.parametrize('change, message', [
    (lambda s: s.update(speed=1), "unknown keys ['speed']"),
    (lambda s: s.pop('rest_before'), "missing keys ['rest_before']"),
    (lambda s: s.update(reach_margin=1.5), 'reach_margin must be a finite number in (0, 1]'),
    (lambda s: s.update(posture_weight=-0.1), 'posture_weight must be a finite number >= 0'),
    (lambda s: s.update(lowpass_hz='fast'), 'lowpass_hz must be a finite number'),
    (lambda s: s['partner'].update(shoulder=[0, 0]), 'partner.shoulder must be 3 numbers'),
    (lambda s: s['person1_to_partner'].pop('yaw'),
     "person1_to_partner must be a mapping with exactly ['xyz', 'yaw']"),
    (lambda s: s.update(data='v3'), "data must be a NuiSI version ['v1', 'v2']"),
    (lambda s: s['observer'].update(end_wait=1.0), "observer: unknown settings ['end_wait']"),
    (lambda s: s['observer'].update(end_hold=-1.0), 'observer: MotionSegmenter: end_hold'),
    (lambda s: s.update(rest_after=0.5), 'rest_after (0.5 s) must be at least observer.end_hold'),
    (lambda s: s['estimator'].update(n_alpha=20), 'estimator: only lookahead and hedge are set'),
    (lambda s: s['estimator'].update(hedge='yes'), 'estimator.hedge must be true or false'),
    (lambda s: s['estimator'].update(lookahead=0), 'estimator.lookahead must be a finite number'),
])
def test_bad_settings_are_refused_in_one_line_naming_the_file_and_the_field(tmp_path, change,
                                                                          message):
    path = _write(tmp_path, change)
    with pytest.raises(ValueError) as info:
        interactions.load_config(path)
    text = str(info.value)
    assert text.startswith(str(path)) and message in text and '\n' not in text


def test_an_unreadable_settings_file_is_refused_in_one_line(tmp_path):
    path = tmp_path / 'broken.yaml'
    path.write_text('data: [v2\n')
    with pytest.raises(ValueError, match='cannot read') as info:
        interactions.load_config(path)
    assert '\n' not in str(info.value)
    with pytest.raises(ValueError, match='cannot read'):
        interactions.load_config(tmp_path / 'missing.yaml')


def test_the_stated_frames_are_the_ones_the_training_data_gives(data):
    c = interactions.load_config()
    xyz, gaps = interactions.derive_person1_to_partner(data['train'], yaw=c.person1_yaw)
    np.testing.assert_allclose(c.person1_xyz, xyz, atol=1e-3)
    assert len(gaps) == 24 and np.median(gaps) < 0.03          # the hands meet
    np.testing.assert_allclose(c.partner_shoulder,
                               interactions.derive_partner_shoulder(data['train']), atol=1e-3)


@pytest.fixture(scope='module', params=shipped_robots())
def scene(request, data):
    return interactions.scene(request.param, train=data['train'])


def test_each_arm_takes_the_partners_place_and_the_hands_still_meet(scene, data):
    """The partner's shoulder on the arm's, person 1 facing the robot across it, and at the
    handshakes' closest approach the two hands (each mapped its own way) within a few cm."""
    expected_scale = {'iiwa14': (1.05, 1.15), 'panda': (1.0, 1.0), 'ur5': (1.0, 1.0)}
    lo, hi = expected_scale[scene.robot.name]
    assert lo <= scene.placement.scale <= hi            # the iiwa's elbow folds less than ours
    origin, yaw = scene.person1_pose()
    assert abs(abs(yaw) - math.pi) < 1e-9
    to_base = scene.robot.world_to_base()
    assert 0.9 < to_base.apply_array(origin[None])[0][0] < 1.3     # in front of the robot
    for r in data['train']:
        if r.label != 'handshake':
            continue
        gap = np.linalg.norm(scene.person1_to_base(r.person1[:, 3])
                             - scene.partner_to_base(r.person2[:, 3]), axis=1)
        assert gap.min() < 0.06, r.name


def test_one_recording_per_interaction_becomes_a_feasible_arm_path(scene, data):
    kin = scene.kin
    picked = {}
    for r in data['train']:
        picked.setdefault(r.label, r)
    margin = scene.config.limit_margin
    for r in picked.values():
        made = interactions.arm_interaction(r, scene)
        q, t = made.joint_q, made.joint_t
        assert np.all(q >= kin.lower + margin - 1e-9) and np.all(q <= kin.upper - margin + 1e-9)
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        assert np.all(speed <= scene.config.speed_fraction * kin.velocity_limit + 1e-9)
        lag = made.extra['lag']
        before, after = interactions.replay_frames(r, scene.config)
        assert len(t) == before + len(r.t) + after and t[before] == made.onset
        # The arm keeps up with the hand but where the hand is faster or out of its reach.
        assert np.nanmedian(lag) < 0.05, (scene.robot.name, r.name)
        np.testing.assert_allclose(made.wrist_xyz[:before], np.repeat(made.wrist_xyz[:1],
                                                                      before, axis=0))


def test_glitches_of_the_partner_are_never_targets(data):
    """v2_train_018: the tracker drops the partner's hand to the hip for five samples; they are
    missing in the partner's path and the arm keeps on its way through them."""
    scene = interactions.scene('panda', train=data['train'])
    r = next(x for x in data['train'] if x.name == 'v2_train_018')
    made = interactions.arm_interaction(r, scene)
    before, _ = interactions.replay_frames(r, scene.config)
    glitch = before + np.arange(151, 156)
    assert np.isnan(made.extra['partner'][glitch]).all()
    flange = scene.kin.fk_positions(made.joint_q[glitch])
    assert flange[:, 2].min() > scene.partner_to_base(r.person2[140:150, 3])[:, 2].min() - 0.1


def test_training_and_the_observer_find_the_same_time_zero(data, tmp_path):
    """The replayed bag, loaded as training loads it, and the observer's logic fed the same
    stream as the nodes get it: the same onset and end, with the scenario's settings."""
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import WristObserver
    from mixture_ip_ros.io.bags import read_bag
    from mixture_ip_ros.io.dataset import segment_recording
    scene = interactions.scene('iiwa14', train=data['train'])
    r = next(x for x in data['test'] if x.label == 'handshake')
    made = interactions.write_bags(scene, 'test', tmp_path / 'bags', recordings=[r])[0]
    rec = read_bag(tmp_path / 'bags' / r.name, joint_names=scene.robot.joint_names)
    settings = interactions.segmentation(scene.config)
    _, onset, end = segment_recording(rec, transform=scene.robot.world_to_base(),
                                      segmentation=settings)
    observer = WristObserver(MotionSegmenter(**settings), scene.robot.world_to_base(),
                             max_clock_offset=0.0)
    events = []
    for t, p in zip(made.wrist_t, made.wrist_xyz):
        ns = int(round(t * 1e9))
        events += observer.on_pose(ns, 'world', p, (0, 0, 0, 1), now_ns=ns).events
    kinds = [k for k, _ in events if k != 'gap']
    assert kinds == ['onset', 'end']
    times = {k: ns * 1e-9 for k, ns in events}
    assert times['onset'] == pytest.approx(onset, abs=1e-6)
    assert times['end'] == pytest.approx(end, abs=1e-6)
    assert abs(onset - made.onset) < 0.3 and abs(end - made.end) < 1.0


def test_training_cuts_the_recordings_where_their_authors_did(data, tmp_path):
    """The scenario's bags record each recording's own interval and the demo trains on it;
    bags written before they recorded it are refused with what to do."""
    from mixture_ip_ros.app import interactions as app
    from mixture_ip_ros.io.bags import END_KEY, ONSET_KEY
    from mixture_ip_ros.io.dataset import load_demonstration
    scene = interactions.scene('iiwa14', train=data['train'])
    for split in ('train', 'test'):
        r = next(x for x in data[split] if x.label == 'rocket_fistbump')
        made = interactions.write_bags(scene, split, tmp_path / 'bags' / split, recordings=[r])[0]
    demo = load_demonstration(tmp_path / 'bags' / 'test' / r.name, **app.loading(scene))
    assert demo.duration == pytest.approx(made.end - made.onset, abs=1.5 / r.rate)
    assert made.end - made.onset == pytest.approx(r.t[-1], abs=1e-9)
    for path in (tmp_path / 'bags' / 'train').glob('*/metadata.yaml'):
        meta = yaml.safe_load(path.read_text())
        custom = meta['rosbag2_bagfile_information']['custom_data']
        del custom[ONSET_KEY], custom[END_KEY]
        path.write_text(yaml.safe_dump(meta))
    with pytest.raises(ValueError, match='remove .* to write them again'):
        app.prepare_interactions_demo(tmp_path / 'bags', tmp_path / 'out', 'iiwa14')
