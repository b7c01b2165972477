"""`mixture-ip train --csv --arm-in-partner-place`: recordings of two people's hands become a
model of an arm in the partner's place, which the estimator node takes for that arm; the
placement is the NuiSI scenario's, read from one schema."""

import math

import numpy as np
import pytest
import yaml

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.io.csv_files import write_csv_demonstration
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.robot import partner_place
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.scenarios import interactions

RATE = 30.0
# The recordings' frame (one mocap system for both people): the partner faces +y, person 1
# stands across from them at y = 1 facing -y. Hands are made in the partner's forward frame
# (x forward, y left) and turned by +90 deg into the recordings' frame.
TO_RECORDING = partner_place.rz(math.pi / 2)
SHOULDER_FORWARD = np.array([0.0, -0.2, 1.4])
IIWA_SHOULDER = np.array([0.0, 0.0, 0.36])        # test_retarget: the iiwa's shoulder


def _min_jerk(n):
    s = np.linspace(0.0, 1.0, n)
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def _recording(height, lean, n=61):
    """Two hands meeting in front of the partner at ``height`` (m above the shoulder's -0.2),
    in the partner's forward frame: (person 1's hand, the partner's hand), (n, 3) each."""
    s = _min_jerk(n)[:, None]
    partner = np.array([0.15, -0.25, 0.95]) + s * np.array([0.3 + lean, 0.15, 0.25 + height])
    person1 = np.array([0.95, 0.1, 1.0]) + s * np.array([-0.42 + lean, -0.18, 0.22 + height])
    return person1, partner


@pytest.fixture(scope='module')
def placement_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('placement') / 'placement.yaml'
    shoulder = TO_RECORDING @ SHOULDER_FORWARD
    path.write_text(yaml.safe_dump({
        'person1_to_partner': {'xyz': [0.0, 0.0, 0.0], 'yaw': 0.0},
        'partner': {'shoulder': shoulder.tolist(), 'yaw': -math.pi / 2},
        'reach_margin': 0.9, 'lowpass_hz': 6.0, 'posture_weight': 0.05, 'limit_margin': 0.1,
        'speed_fraction': 0.9}))
    return path


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """Four recordings, two of each meeting height; person 1's hand in m, the partner's in
    cm (the option takes any unit of length)."""
    folder = tmp_path_factory.mktemp('csv')
    layout = Layout(('hx', 'hy', 'hz'), ('px', 'py', 'pz'))
    made = {}
    for i, (height, lean) in enumerate([(0.0, 0.0), (0.02, 0.03), (0.2, 0.0), (0.22, -0.03)]):
        person1, partner = _recording(height, lean)
        t = np.arange(len(partner)) / RATE
        write_csv_demonstration(folder / f'rec_{i}.csv', Demonstration(
            t, person1 @ TO_RECORDING.T, 100 * partner @ TO_RECORDING.T), layout)
        made[f'rec_{i}.csv'] = (person1, partner)
    return folder, made


@pytest.fixture(scope='module')
def trained(recordings, placement_file, tmp_path_factory):
    folder, _ = recordings
    out = tmp_path_factory.mktemp('model') / 'model.npz'
    code = main(['train', '--csv', str(folder), '--observed', 'hx,hy,hz', '--controlled',
                 'px,py,pz', '--controlled-units', 'cm', '--arm-in-partner-place',
                 str(placement_file), '--robot', 'iiwa14', '--components', '2', '--jobs', '1',
                 '--out', str(out)])
    assert code == 0
    return out


def test_the_model_controls_the_arms_joints_from_the_hand_in_its_base_frame(trained):
    kin = RobotKinematics('iiwa14')
    # what estimator_node checks of a model for its robot
    model, meta = load_model(trained, controlled_names=kin.joint_names)
    assert model.n_observed_ == 3 and meta['observed_units'] == ['m'] * 3
    assert meta['observed_frame'] == kin.description.base_frame
    assert meta['controlled_units'] == ['rad'] * kin.dof


def test_estimator_node_takes_the_model_for_its_arm_and_refuses_it_for_another(harness,
                                                                             trained):
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.parameter import Parameter
    from mixture_ip_ros.nodes.estimator_node import EstimatorNode

    def configure(robot):
        node = harness.add(EstimatorNode(context=harness.context, parameter_overrides=[
            Parameter('robot', value=robot), Parameter('model_path', value=str(trained))]),
            start=False)
        return node.trigger_configure(), node.refusal
    assert configure('iiwa14')[0] == TransitionCallbackReturn.SUCCESS
    result, refusal = configure('panda')
    assert result == TransitionCallbackReturn.FAILURE and 'do not match' in refusal


def test_the_model_file_records_the_placement(trained, placement_file):
    _, meta = load_model(trained)
    record = meta['extra']['partner_place']
    assert record['robot'] == 'iiwa14' and record['reach_scale'] == 1.0   # all within reach
    settings = yaml.safe_load(placement_file.read_text())
    for key, value in settings.items():
        assert record[key] == value, key
    np.testing.assert_allclose(record['arm_shoulder'], IIWA_SHOULDER, atol=1e-9)
    # where person 1's frame (here the recordings') lies in the mocap frame: its origin and
    # its x axis, the partner's right (-y of their forward frame), the base's -y
    kin = RobotKinematics('iiwa14')
    origin = kin.description.base_to_world().apply_array(
        (IIWA_SHOULDER - SHOULDER_FORWARD)[None])[0]
    np.testing.assert_allclose(record['person1_in_world']['xyz'], origin, atol=1e-9)
    assert record['person1_in_world']['yaw'] == pytest.approx(-math.pi / 2, abs=1e-9)
    place = partner_place.PartnerPlace.from_metadata(record)
    assert place.placement.scale == 1.0 and place.config.partner_yaw == -math.pi / 2
    # and mixture-ip info says so
    from mixture_ip_ros.app.inspect_model import model_summary
    text = model_summary(trained)
    assert "the arm (iiwa14) in the partner's place, from" in text
    assert 'reach scale 1.000' in text and 'facing -90 deg, in the mocap frame' in text


def test_the_arms_joints_reach_the_placed_partners_hand(recordings, placement_file):
    """The training demonstrations the option makes: the flange (FK) within 2 mm of the
    partner's hand placed on the arm (shoulder on shoulder, the partner's forward the base's
    x), person 1's hand placed the same way."""
    folder, made = recordings
    from mixture_ip_ros.io.csv_files import load_csv_dataset
    from mixture_ip_ros.app.arm_in_partner_place import arm_demonstrations
    layout = Layout(('hx', 'hy', 'hz'), ('px', 'py', 'pz'), None, ('cm',))
    demos, extra = arm_demonstrations(load_csv_dataset(folder, layout), layout, placement_file,
                                      'iiwa14')
    kin = RobotKinematics('iiwa14')
    for demo in demos:
        person1, partner = made[demo.name]
        np.testing.assert_allclose(demo.observed, IIWA_SHOULDER + person1 - SHOULDER_FORWARD,
                                   atol=1e-9)
        flange = kin.fk_positions(demo.controlled)
        gap = np.linalg.norm(flange - (IIWA_SHOULDER + partner - SHOULDER_FORWARD), axis=1)
        assert gap.max() < 0.002, (demo.name, gap.max())
        assert np.all(demo.controlled >= kin.lower + 0.1 - 1e-9)
        assert np.all(demo.controlled <= kin.upper - 0.1 + 1e-9)
    assert extra['partner_place']['flange_to_partner_cm']['p95'] < 0.5


def test_the_model_predicts_the_arm_to_the_partners_hand(trained, recordings):
    """Each recording's person 1 seen whole: the arm's predicted end within 1 cm of where
    the partner's hand ended."""
    model, _ = load_model(trained)
    kin = RobotKinematics('iiwa14')
    _, made = recordings
    for person1, partner in made.values():
        observed = IIWA_SHOULDER + person1 - SHOULDER_FORWARD
        z = np.linspace(0.0, 1.0, len(observed))
        q_end = model.predict_controlled(z, observed, np.array([1.0]))['position'][-1]
        end = kin.fk_positions(q_end[None])[0]
        assert np.linalg.norm(end - (IIWA_SHOULDER + partner[-1] - SHOULDER_FORWARD)) < 0.01


def test_a_trackers_glitch_and_dropped_samples_are_never_targets(placement_file):
    """The partner's hand jumps 0.6 m away for three samples (a lost marker) and two samples
    are not in the file: the arm keeps to the hand's path through both."""
    person1, partner = _recording(0.1, 0.0)
    true_path = IIWA_SHOULDER + partner - SHOULDER_FORWARD
    recorded = partner.copy()
    recorded[30:33] += [0.0, 0.6, -0.3]
    keep = np.setdiff1d(np.arange(len(partner)), [40, 41])
    t = np.arange(len(partner)) / RATE
    demo = Demonstration(t[keep], person1[keep] @ TO_RECORDING.T,
                         recorded[keep] @ TO_RECORDING.T, name='glitch')
    arm = partner_place.place('iiwa14', partner_place.load_placement(placement_file),
                              [partner @ TO_RECORDING.T])
    made, lag = partner_place.arm_demonstration(arm, demo)
    np.testing.assert_array_equal(made.t, t[keep])
    assert np.isnan(lag[30:33]).all() and np.nanmax(lag) < 0.002
    flange = RobotKinematics('iiwa14').fk_positions(made.controlled)
    assert np.linalg.norm(flange - true_path[keep], axis=1).max() < 0.01


def test_recordings_off_one_sample_rate_are_refused_naming_the_sample():
    t = np.r_[np.arange(10) / RATE, 0.5, 0.52]
    demo = Demonstration(t, np.ones((12, 3)), np.ones((12, 3)), name='uneven.csv')
    arm = partner_place.place('iiwa14', partner_place.load_placement(
        config_path('partner_placement.yaml')), [np.array([[0.5, 0.0, 0.0]])])
    with pytest.raises(ValueError, match=r"'uneven.csv': sample 1\d at 0.5\d* s is off the rate"):
        partner_place.arm_demonstration(arm, demo)


@pytest.mark.parametrize('change, message', [
    (['--controlled', 'px,py'], 'the controlled columns are the partner'),
    (['--observed-units', 'rad'], "in m, cm or mm, not 'rad'"),
    (['--translation', 'shared'], '--translation: not with --arm-in-partner-place'),
])
def test_what_cannot_be_two_hands_is_refused_before_anything_is_read(recordings,
                                                                  placement_file, tmp_path,
                                                                  capsys, change, message):
    folder, _ = recordings
    args = {'--observed': 'hx,hy,hz', '--controlled': 'px,py,pz'}
    args.update(dict(zip(change[::2], change[1::2])))
    with pytest.raises(SystemExit) as info:
        main(['train', '--csv', str(folder), *sum(args.items(), ()), '--arm-in-partner-place',
              str(placement_file), '--out', str(tmp_path / 'm.npz')])
    assert info.value.code == 2 and message in capsys.readouterr().err


def test_a_bad_placement_file_is_refused_in_one_line(recordings, tmp_path, capsys):
    folder, _ = recordings
    bad = tmp_path / 'placement.yaml'
    bad.write_text(yaml.safe_dump({**yaml.safe_load(
        config_path('partner_placement.yaml').read_text()), 'reach_margin': 2}))
    code = main(['train', '--csv', str(folder), '--observed', 'hx,hy,hz', '--controlled',
                 'px,py,pz', '--arm-in-partner-place', str(bad), '--out',
                 str(tmp_path / 'm.npz')])
    err = capsys.readouterr().err.strip()
    assert code == 1 and f'{bad}: reach_margin must be a finite number in (0, 1]' in err
    assert not (tmp_path / 'm.npz').exists()


def test_the_shipped_placement_is_the_interactions_scenarios():
    shipped = partner_place.load_placement(config_path('partner_placement.yaml'))
    scenario = interactions.load_config()
    for field in ('person1_xyz', 'person1_yaw', 'partner_shoulder', 'partner_yaw',
                  *partner_place.SCALARS):
        assert getattr(shipped, field) == getattr(scenario, field), field
