"""Shared fixtures. ROS tests run on a private DDS domain, discovery limited to localhost."""

import os

from mixture_ip_ros.nodes.launch import set_process_defaults

# The executables' environment (one BLAS thread, numba's cache in the user's cache folder), set
# before any test module imports numpy or numba; the executables the tests start inherit it.
set_process_defaults()
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('MUJOCO_GL', 'osmesa')

import pytest  # noqa: E402


def private_domain_id(offset: int = 0) -> int:
    """A domain id unlikely to collide with another run on this machine: 40 ids from
    MIXTURE_IP_TEST_DOMAIN_BASE (default 100; give parallel checkouts disjoint bases), picked by
    the process id, plus ``offset`` (0 or 1) for a second domain in the same test. Fast DDS
    allows 0-232 only."""
    if offset not in (0, 1):
        raise ValueError('offset must be 0 or 1')
    base = int(os.environ.get('MIXTURE_IP_TEST_DOMAIN_BASE', 100))
    domain = base + (os.getpid() % 20) * 2 + offset
    if not (0 <= base and domain <= 232):
        raise ValueError(f'MIXTURE_IP_TEST_DOMAIN_BASE={base} gives domain {domain}, outside 0-232')
    return domain


@pytest.fixture
def ros_context():
    """A fresh rclpy context on a private domain, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=private_domain_id())
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def harness(ros_context):
    """The node-test harness (test/ros_harness.py) on a fresh context."""
    from ros_harness import RosHarness
    h = RosHarness(ros_context)
    try:
        yield h
    finally:
        h.close()


@pytest.fixture(scope='session')
def box_loop(tmp_path_factory):
    """What the closed-loop tests replay: 48 box-assembly bags (seed 3) and a model trained
    (K = 3) on all but one interaction per pattern, once per session (read only: a test writes
    what it derives to its own folder). {'data', 'labels', 'held', 'model', 'info'}."""
    from mixture_ip_ros.app.demo import split_held_out
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.io.dataset import load_demonstration
    from mixture_ip_ros.scenarios.folders import read_labels, write_scenario_bags
    root = tmp_path_factory.mktemp('box_loop')
    data = root / 'bags'
    write_scenario_bags('box_assembly', data, seed=3)
    labels = read_labels(data)
    train, held = split_held_out(labels, 1, seed=3)
    model = root / 'model.npz'
    _, info = train_to_file([load_demonstration(data / n) for n in train], model,
                            n_components=3)
    return {'data': data, 'labels': labels, 'held': held, 'model': model, 'info': info}


def heldout_loglik(demos, candidates, prior_scales=None, **params):
    """The held-out log-likelihood curve of core.selection.calibrated_heldout_curves alone (no
    completion, no controlled agent's RMS), each K at its calibrated floor."""
    from mixture_ip_ros.core.selection import PRIOR_SCALES, calibrated_heldout_curves
    scales = PRIOR_SCALES if prior_scales is None else prior_scales
    return calibrated_heldout_curves(demos, candidates, (), scales, controlled=False,
                                     **params)['loglik']


@pytest.fixture
def nothing_runs(monkeypatch):
    """Reading data, training or evaluating fails the test: a check must have stopped first."""
    import mixture_ip_ros.app.evaluation as evaluation
    import mixture_ip_ros.app.training as training
    import mixture_ip_ros.io.csv_files as csv_files
    import mixture_ip_ros.io.dataset as dataset

    def forbidden(*args, **kwargs):
        raise AssertionError('reached data loading or training despite contradicting options')
    for module, name in ((training, 'train_to_file'), (evaluation, 'evaluate'),
                         (evaluation, 'evaluate_csv'), (csv_files, 'load_csv_dataset'),
                         (dataset, 'load_dataset')):
        monkeypatch.setattr(module, name, forbidden)
