"""bag_player looping a bag into observer_node and estimator_node over real DDS (in-process,
private domain): each pass is a new stream and a new interaction, nothing dropped at the loop,
and stopping the player mid-interaction ends it without an error."""

import numpy as np
import pytest
from rclpy.parameter import Parameter

from mixture_ip_ros.app.training import train_to_file
from mixture_ip_ros.io.bags import write_demonstration_bag
from mixture_ip_ros.nodes.bag_player import BagPlayer
from mixture_ip_ros.nodes.estimator_node import EstimatorNode
from mixture_ip_ros.nodes.observer_node import ObserverNode
from mixture_ip_ros.scenarios.human_motion import reach
from mixture_ip_ros.scenarios.synthetic import mixture_demos


@pytest.fixture(scope='module')
def model_path(tmp_path_factory):
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=6)[0]
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file(demos[:10], path, n_components=1, n_basis=6)
    return path


def _bag(folder):
    """2.5 s at 100 Hz: 0.5 s at rest, a 1.2 s reach of 0.47 m, then rest (the end of the
    reach is confirmed 0.4 s before the bag ends)."""
    t = np.arange(0.0, 2.5, 0.01)
    xyz = reach(t, 0.5, 1.2, (0.9, 0.3, 1.1), (0.7, -0.05, 1.35), via_offset=(0, 0, 0.05))
    xyz += np.random.default_rng(0).normal(0.0, 0.001, xyz.shape)
    return write_demonstration_bag(folder / 'loop', t, xyz, t, np.zeros((len(t), 7)))


@pytest.mark.parametrize('rewrite_stamps', [True, False])
def test_a_looping_replay_starts_one_interaction_per_pass_and_drops_nothing(
        harness, tmp_path, model_path, rewrite_stamps):
    """rewrite_stamps: the stamps continue and the wrist jumps back to the start; without, the
    stamps jump back to the bag's (then on no clock here: the clock checks are off)."""
    # Stamps rewritten are on the nodes' clock; the estimator judges evidence older than 0.5 s
    # stale, and the observer ends an interaction after 1 s of silence (defaults: 1 s, 2 s).
    observer = harness.add(ObserverNode(context=harness.context, parameter_overrides=[
        Parameter('max_clock_offset', value=1.0 if rewrite_stamps else 0.0),
        Parameter('max_gap', value=1.0)]))
    estimator = harness.add(EstimatorNode(context=harness.context, parameter_overrides=[
        Parameter('max_clock_offset', value=0.5 if rewrite_stamps else 0.0),
        Parameter('model_path', value=str(model_path))]))
    player = harness.add(BagPlayer(context=harness.context, parameter_overrides=[
        Parameter('bag', value=str(_bag(tmp_path))), Parameter('loop', value=True),
        Parameter('rewrite_stamps', value=rewrite_stamps), Parameter('start_paused', value=True),
        Parameter('topics', value=['/mocap/wrist'])]))
    harness.spin_until(lambda: all(p.get_subscription_count() > 0 for p in (
        *player._topic_pubs.values(), observer.observation_pub, observer.event_pub)),
        what='discovery')
    player.resume()
    records = estimator.interactions
    harness.spin_until(lambda: len(records) >= 2 and records[1].end_reason is not None,
                       timeout=20.0, what='two passes')
    assert player.loops_completed >= 1
    assert [r.end_reason for r in records[:2]] == ['end', 'end']
    assert all(r.n_observations > 20 for r in records[:2])
    assert observer.observer.counts.stream_restarts >= 1
    assert {k: v for k, v in observer.drop_counts.items() if v} == {}
    assert {k: v for k, v in estimator.planner.counts.rejected.items() if v} == {}
    if not rewrite_stamps:
        return
    # The player stopped mid-movement: the observer's 'end' comes after max_gap of silence,
    # dated at the last pose; the interaction ends without a plan and without an error.
    harness.spin_until(lambda: len(records) >= 3, timeout=10.0, what='a third pass')
    player.pause()
    refusals = dict(estimator.planner.counts.plan_refusals)
    harness.spin_until(lambda: records[2].end_reason is not None, timeout=10.0,
                       what='the interaction to end')
    assert records[2].end_reason == 'stream_stopped'
    assert estimator.planner.counts.plan_refusals == refusals
