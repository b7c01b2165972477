"""Offscreen rendering of a recorded interaction (real MuJoCo through OSMesa, real simulation)."""

import mujoco
import numpy as np
import pytest
from PIL import Image

from mixture_ip_ros.scenarios.human_motion import reach
from mixture_ip_ros.io.records import InteractionRecord
from mixture_ip_ros.viz import human_model as human
from mixture_ip_ros.robot.description import shipped_robots
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import points_from_arrays
from mixture_ip_ros.viz.animation import render_interaction
from mixture_ip_ros.viz.frames import TARGET_MARKER, InteractionRenderer, render_frames
from mixture_ip_ros.viz.offscreen import rendering_available
from mixture_ip_ros.viz.overlays import PALETTE

REST = np.array([1.05, 0.12, 0.18])
GOAL = np.array([0.80, 0.02, 0.32])
ROBOT_HAND_GOAL = np.array([0.70, 0.02, 0.32])


def make_record(duration=2.0, onset=0.3, move=1.2, commit=0.7, robot_move=None, rate=100.0,
                gap=(0.9, 1.1), robot=None):
    """A handover replayed without ROS: the person reaches from REST to GOAL, the robot (the
    real simulation and controller at 1 kHz) moves its hand from its home posture to
    ROBOT_HAND_GOAL after `commit`, and a made-up belief moves from uniform to 'plate'.
    Positions in the scene's world frame here, in the record in the robot's base frame."""
    sim = RobotSimulation(robot=robot)
    to_base = sim.description.world_to_base()
    HOME = sim.description.home_array()
    q_goal = sim.kinematics.ik(to_base.apply_array(ROBOT_HAND_GOAL), HOME)
    if robot_move is None:     # 1 s, or as long as the joints' speed limits need (the sim checks)
        robot_move = max(1.0, 1.1 * 1.875 * np.max(np.abs(q_goal - HOME)
                                                    / sim.kinematics.velocity_limit))
    s = np.linspace(0.0, 1.0, 11)
    pos = HOME + np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, q_goal - HOME)
    vel = np.outer((30 * s**2 - 60 * s**3 + 30 * s**4) / robot_move, q_goal - HOME)
    steps_per_sample = int(round(1.0 / (rate * sim.dt)))
    t, q, flange = [], [], []
    started = False
    while sim.time < duration - 1e-9:
        if not started and sim.time >= commit - 1e-9:
            points = points_from_arrays(s * robot_move, pos, vel)
            assert sim.set_trajectory(sim.joint_names, points) is None
            started = True
        t.append(sim.time)
        q.append(sim.q)
        flange.append(sim.flange_pose()[0])
        sim.step(steps_per_sample)
    t = np.array(t)
    wrist = to_base.apply_array(reach(t, onset, move, REST, GOAL, via_offset=(0.0, 0.0, 0.05)))
    wrist[(t >= gap[0]) & (t < gap[1])] = np.nan
    post_t = t[t >= onset][::5]
    logit = np.clip((post_t - onset) / (commit - onset), 0, None) * 3.0
    post = np.stack([np.exp(logit), np.ones_like(logit), np.ones_like(logit)], axis=1)
    post /= post.sum(axis=1, keepdims=True)
    phase = np.clip((post_t - onset) / move, 0, 1)
    return InteractionRecord(
        name='test handover', true_pattern='plate',
        component_labels=['plate', 'screw', 'screwdriver'],
        t=t, q=np.array(q), flange=np.array(flange), wrist_t=t, wrist=wrist,
        posterior_t=post_t, posterior=post, phase=phase, alpha=np.full(post_t.size, 1 / move),
        onset_time=onset, commit_time=commit, end_time=onset + move, chosen_pattern='plate',
        commit_fraction=(commit - onset) / move, target=to_base.apply_array(ROBOT_HAND_GOAL),
        extra={'robot': sim.description.source})


@pytest.fixture(scope='module')
def record():
    return make_record()


@pytest.fixture(scope='module')
def available():
    ok, why = rendering_available()
    if not ok:
        pytest.skip(f'offscreen rendering unavailable: {why}')
    return ok


def _project(model, data, camera, point, width, height):
    """Pixel (column, row) of a base-frame point seen by the free camera (pinhole model)."""
    scene = mujoco.MjvScene(model, maxgeom=1000)
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, camera,
                           mujoco.mjtCatBit.mjCAT_ALL.value, scene)
    cam = scene.camera[0]
    forward, up = np.array(cam.forward), np.array(cam.up)
    right = np.cross(forward, up)
    rel = np.asarray(point) - np.array(cam.pos)
    z = rel @ forward
    half_h = np.tan(np.radians(model.vis.global_.fovy) / 2) * z
    half_w = half_h * width / height
    return (width / 2 * (1 + rel @ right / half_w), height / 2 * (1 - rel @ up / half_h))


@pytest.mark.parametrize('robot', shipped_robots())
def test_frames_show_the_robot_moving(robot, available):
    # Only the robot moves in this record: no person, no wrist marker or trail, no target marker.
    robot_only = make_record(robot=robot)
    robot_only.wrist[:] = np.nan
    robot_only.target = None
    w, h = 160, 120
    times = [0.0, 0.5, 1.95]        # commit at 0.7: the robot holds still, then moves
    frames = render_frames(robot_only, times, width=w, height=h, overlay=False,
                           with_human=False)
    assert [f.shape for f in frames] == [(h, w, 3)] * 3
    assert all(f.dtype == np.uint8 and f.std() > 20 for f in frames)    # not blank
    # Where the robot's links are on screen at each time (body origins, projected).
    yy, xx = np.mgrid[0:h, 0:w]
    robot_area = np.zeros((h, w), bool)
    with InteractionRenderer(robot_only, w, h, overlay=False, with_human=False) as r:
        d = r.replay.robot
        assert d.name == robot
        bodies = ([r.model.body(d.base_frame).id]
                  + [r.model.joint(n).bodyid[0] for n in d.joint_names]
                  + [r.model.body(d.flange_frame).id])
        for tk in (times[0], times[2]):
            r.data.qpos[r._qadr] = r.replay.joints(tk)
            mujoco.mj_kinematics(r.model, r.data)
            px = np.array([_project(r.model, r.data, r.camera, r.data.xpos[b], w, h)
                           for b in bodies])
            assert np.all((px >= 0) & (px < [w, h])), 'the robot must be in view'
            pad = 0.1 * w                  # the links' thickness around their origins
            robot_area |= ((xx >= px[:, 0].min() - pad) & (xx <= px[:, 0].max() + pad)
                           & (yy >= px[:, 1].min() - pad) & (yy <= px[:, 1].max() + pad))
    still = np.abs(frames[0].astype(int) - frames[1].astype(int)).sum(axis=2)
    moved = np.abs(frames[0].astype(int) - frames[2].astype(int)).sum(axis=2) > 40
    assert still.max() < 40                 # holding position: the same picture
    assert moved.mean() > 0.005             # the arm moved visibly ...
    assert not moved[~robot_area].any()     # ... and nothing else changed


def test_overlay_bars_show_the_posterior(record, available):
    w, h = 320, 240
    t_query = 0.4       # between onset (0.3) and commit (0.7): no component dominates yet
    before, during = render_frames(record, [0.0, t_query], width=w, height=h,
                                   with_human=False)
    with InteractionRenderer(record, w, h, with_human=False) as r:
        band_h = r.band_height
    assert before.shape == during.shape == (h, w, 3) and 40 < band_h < h // 2
    p = record.posterior[np.searchsorted(record.posterior_t, t_query, side='right') - 1]

    def bar_width(img, k):
        band = img[h - band_h:].astype(int)
        mask = np.all(np.abs(band - np.array(PALETTE[k])) < 3, axis=2)
        return int(mask.sum(axis=1).max())      # the longest run is the bar's length

    assert [bar_width(before, k) for k in range(3)] == [0, 0, 0]    # before onset: no belief
    widths = np.array([bar_width(during, k) for k in range(3)])
    assert widths[0] > 15
    # Bar lengths are proportional to p(k | D) (to a pixel, plus the one-pixel rectangle edge).
    scale = (widths[0] - 1) / p[0]
    assert np.all(np.abs(widths - 1 - scale * p) <= 1.5), (widths, p)


def test_human_wrist_follows_the_record(record, available):
    with InteractionRenderer(record, 64, 48, overlay=False) as r:
        for tk in (0.0, 0.8, 1.0, 1.6):     # 1.0 is inside the occlusion gap: interpolated
            r.frame(tk)
            goal = r.replay.wrist_path(tk)
            assert np.linalg.norm(r.poser.wrist(r.data) - goal) < 0.01
        seen = r.model.site_rgba[r.model.site('human_wrist').id, 3]
        # Out of reach (2 m in front of the person): the IK reports the distance it is left at.
        far = np.array([-0.5, 0.0, 0.3])
        err = r.poser.reach(r.data, far)
        assert err > 0.5 and abs(err - np.linalg.norm(r.poser.wrist(r.data) - far)) < 1e-9
    assert seen > 0    # 1.6 s is observed, the marker shows
    assert r.replay.wrist_observed(1.0) is None and r.replay.wrist_observed(0.8) is not None


def test_a_partner_marker_follows_the_partners_hand_and_the_person_stands_where_told(
        record, available):
    """The interactions demo's record: the green marker at the partner's hand over time (hidden
    where the tracker lost it), the human model's collar where the person's was."""
    from dataclasses import replace
    t = np.array([0.0, 0.5, 1.0, 1.5])
    partner = np.array([[0.5, 0.0, 0.2], [0.6, 0.1, 0.3], [np.nan] * 3, [0.7, 0.1, 0.3]])
    collar = (1.3, 0.2, 0.35, np.pi)
    rec = replace(record, extra={**record.extra, 'partner': {'t': t.tolist(),
                                                             'xyz': partner.tolist()},
                                 'person1': list(collar), 'scene': {'table': False}})
    with InteractionRenderer(rec, 64, 48, overlay=False) as r:
        to_world = r.replay.robot.base_to_world()
        marker = r.model.body(TARGET_MARKER).mocapid[0]
        r.frame(0.6)
        np.testing.assert_allclose(r.data.mocap_pos[marker],
                                   to_world.apply_array(partner[1:2])[0])
        r.frame(1.1)
        assert r.data.mocap_pos[marker][2] < -10          # lost: out of sight
        r.poser.relax(r.data)
        mujoco.mj_kinematics(r.model, r.data)
        np.testing.assert_allclose(r.data.xpos[r.model.body('human_right_clavicle').id],
                                   collar[:3], atol=1e-6)
        assert r.model.geom('floor').pos[2] == pytest.approx(collar[2] - human.collar_height())


def test_render_interaction_writes_files(record, available, tmp_path):
    short = make_record(duration=1.0, onset=0.1, move=0.6, commit=0.3, robot_move=0.6,
                        gap=(0.4, 0.5))
    paths = render_interaction(short, tmp_path / 'out', fps=10, width=160, height=120)
    gif, sheet = paths['animation'], paths['contact_sheet']
    assert gif.is_file() and sheet.is_file()
    with Image.open(gif) as im:
        assert im.size == (160, 120)
        assert im.n_frames == 11              # 0.0 .. 1.0 s at 10 frames per second
        assert im.info['duration'] == 100
        first = np.asarray(im.convert('RGB')).astype(int)
        im.seek(im.n_frames - 1)
        last = np.asarray(im.convert('RGB')).astype(int)
    assert (np.abs(first - last).sum(axis=2) > 40).mean() > 0.01     # it is animated
    with Image.open(sheet) as im:
        # onset, commit, movement end, handover: four key frames side by side
        assert im.size[0] == 4 * 160
        assert np.asarray(im.convert('L')).std() > 20


def test_bad_record_is_rejected(record, available):
    bad = make_record(duration=0.2)
    bad.q = bad.q[:, :6]     # the iiwa has 7 joints
    with pytest.raises(ValueError, match='record.q'):
        render_frames(bad, [0.0], width=32, height=32)


def test_human_model_stands_on_the_floor():
    # The pelvis height comes from the meshes; an adult's pelvis is about 0.9-1.1 m up.
    assert 0.9 < human.pelvis_height() < 1.15


def test_record_without_estimate_or_wrist_still_renders(available, tmp_path):
    rec = make_record(duration=0.6, onset=0.1, move=0.4, commit=0.3, gap=(0, 0))
    rec.wrist[:] = np.nan                       # the person was never seen
    rec.posterior_t = np.zeros(0)
    rec.posterior = np.zeros((0, 3))
    rec.phase = np.zeros(0)
    rec.alpha = np.zeros(0)
    rec.onset_time = rec.commit_time = rec.end_time = rec.chosen_pattern = None
    rec.commit_fraction = rec.target = None
    paths = render_interaction(rec, tmp_path, fps=5, width=160, height=120)
    with Image.open(paths['contact_sheet']) as im:
        assert im.size[0] == 2 * 160            # start and last frame only
    with InteractionRenderer(rec, 64, 48, overlay=False) as r:
        r.frame(0.3)
        # No wrist: the person stands relaxed and the wrist marker is hidden.
        assert r.model.site_rgba[r.model.site('human_wrist').id, 3] == 0
        assert np.allclose(r.data.qpos[r.poser._qadr], r.poser.relaxed[r.poser._qadr])


def test_unavailable_rendering_raises_runtime_error(tmp_path):
    # A real unavailable backend: PyOpenGL bound to another platform refuses OSMesa.
    import os
    import subprocess
    import sys
    code = (
        'import sys; sys.path.insert(0, %r)\n'
        'from test_render import make_record\n'
        'from mixture_ip_ros.viz.animation import render_interaction\n'
        'from mixture_ip_ros.viz.offscreen import rendering_available\n'
        'ok, why = rendering_available()\n'
        'assert not ok and "PYOPENGL_PLATFORM" in why, why\n'
        'try:\n'
        '    render_interaction(make_record(duration=0.2), %r)\n'
        'except RuntimeError as err:\n'
        '    assert "unavailable" in str(err); print("raised")\n'
    ) % (os.path.dirname(__file__), str(tmp_path))
    env = dict(os.environ, PYOPENGL_PLATFORM='egl', OPENBLAS_NUM_THREADS='1')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'raised'
    assert not any(tmp_path.iterdir())          # nothing half-written


def test_the_band_says_whether_the_robot_waits_or_hedges_before_it_commits(record):
    """Between the onset and the commit the band tells a robot at rest from one on hedged
    plans (the record's interaction counts them: PlannerSettings.hedge)."""
    import copy
    from mixture_ip_ros.viz.overlays import _status
    from mixture_ip_ros.viz.replay import Replay
    before = 0.5 * (record.onset_time + record.commit_time)
    assert _status(Replay(record), before) == ('observing, robot waits', False)
    hedged = copy.copy(record)
    hedged.extra = {**record.extra, 'interaction': {'hedged_plans': 3}}
    assert _status(Replay(hedged), before) == ('observing, robot hedges', False)
    assert _status(Replay(hedged), record.commit_time)[1]
