"""Where the time goes inside observer_node and estimator_node, per pose.

The nodes of experiments/latency.py (its model, and the stream, parameters and every-pose replanning
it takes from bench/_common.py), but their callbacks are called directly in this one thread at
the stream's pace (poses stamped with the node clock when fed): the observer's observation and
event publishers hand their messages straight to the estimator's callbacks, so the time of a
pose is the nodes' own work, without the transport's hops and without other threads. Every
stage listed in STAGES is timed with time.perf_counter around each call (about 1 us of overhead
each); the stages are the nodes' inner methods, private ones included, wrapped by name.

Keys: poses, poses_with_plan (a trajectory sent in the pose's callback);
per_pose_ms_{median,p99} (observer callback, estimator's work included) and to_trajectory_ms_
{median,p99} (from the observer callback's start to the trajectory handed to its publisher),
both over the poses with a plan; stages: per stage the mean microseconds per pose and per call
and the number of calls (nested stages are included in their callers).
Run: .venv/bin/python experiments/node_profile.py [--demos 4]
Timing only, no assertions.
"""

import argparse
import collections
import functools
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # the checkout: bench._common

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402

from bench._common import (ESTIMATOR_PARAMS, EVERY_POSE, OBSERVER_PARAMS, Stream,  # noqa: E402
                     as_parameters, padded_wrist)
from mixture_ip_ros.app.training import train_to_file  # noqa: E402
from mixture_ip_ros.core.stamps import ns_to_parts  # noqa: E402
from mixture_ip_ros.estimation import planner as planner_module  # noqa: E402
from mixture_ip_ros.nodes.estimator_node import EstimatorNode  # noqa: E402
from mixture_ip_ros.nodes.observer_node import ObserverNode  # noqa: E402
from mixture_ip_ros.scenarios.box_assembly import box_assembly  # noqa: E402

# (owner, method) per node: 'observer'/'estimator' is the node, the others attributes of it.
STAGES = {
    'observer': ['on_pose'],
    'observer.observer': ['on_pose'],
    'observer.observer.segmenter': ['update'],
    'observer.observer.plausibility': ['check'],
    'estimator': ['on_observation', 'replan', '_publish', '_publish_path', '_publish_markers'],
    'estimator.planner': ['observe', 'replan', '_checked', '_record_evidence'],
    'estimator.estimator': ['_absorb', 'log_marginal', 'mean_trajectories'],
    'estimator._trajectory_encoder': ['encode'],
    'estimator._path_encoder': ['encode'],
    'estimator._posterior_encoder': ['encode'],
}
MODULE_STAGES = {planner_module: ['posterior_summary', 'build_plan']}


class Spans:
    def __init__(self):
        self.seconds = collections.defaultdict(float)
        self.calls = collections.defaultdict(int)

    def wrap(self, owner, name, label):
        f = getattr(owner, name)

        @functools.wraps(f)
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return f(*args, **kwargs)
            finally:
                self.seconds[label] += time.perf_counter() - t0
                self.calls[label] += 1
        setattr(owner, name, timed)

    def report(self, poses):
        return {k: {'us_per_pose': round(self.seconds[k] / poses * 1e6, 1),
                    'us_per_call': round(self.seconds[k] / self.calls[k] * 1e6, 1),
                    'calls': self.calls[k]}
                for k in sorted(self.seconds, key=lambda k: -self.seconds[k])}


class Handoff:
    """Stands in for a publisher: hands each message to a callback, in this thread."""

    def __init__(self, callback):
        self.callback = callback

    def publish(self, msg):
        self.callback(msg)


class Sent:
    """Wraps the trajectory publisher: when the last trajectory was handed to it."""

    def __init__(self, publisher):
        self.publisher, self.times = publisher, []

    def publish(self, msg):
        self.times.append(time.perf_counter())
        self.publisher.publish(msg)

    def __getattr__(self, name):
        return getattr(self.publisher, name)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--demos', type=int, default=4, help='interactions replayed')
    ap.add_argument('--domain-id', type=int, default=None)
    args = ap.parse_args()
    domain = args.domain_id if args.domain_id is not None else 10 + os.getpid() % 80
    gen = box_assembly(seed=0)
    warm_demo = min(gen, key=lambda g: g.duration)
    chosen = [next(g for g in gen if g.label == label and g is not warm_demo)
              for label in ('plate', 'screw', 'screwdriver')]
    chosen += [g for g in gen if g is not warm_demo and g not in chosen]
    stream = Stream()
    stream.add(*padded_wrist(warm_demo, seed=100))
    for i, g in enumerate(chosen[:args.demos]):
        stream.add(*padded_wrist(g, seed=i))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    with tempfile.TemporaryDirectory(prefix='node_profile_') as tmp:
        model_path = Path(tmp) / 'box_model.npz'
        train_to_file([g.to_demonstration(0.01) for g in gen], model_path, n_components=3)
        observer = ObserverNode(context=ctx,
                                parameter_overrides=as_parameters(OBSERVER_PARAMS))
        estimator = EstimatorNode(context=ctx, parameter_overrides=as_parameters(
            {**ESTIMATOR_PARAMS, 'model_path': str(model_path), **EVERY_POSE}))
        try:
            for node in (observer, estimator):
                if not node.start():
                    raise RuntimeError(f'{node.get_name()}: {node.refusal}')
            spans = Spans()
            nodes = {'observer': observer, 'estimator': estimator}
            for path, names in STAGES.items():
                owner = nodes[path.split('.')[0]]
                for attribute in path.split('.')[1:]:
                    owner = getattr(owner, attribute)
                for name in names:
                    spans.wrap(owner, name, f'{path}.{name}')
            for module, names in MODULE_STAGES.items():
                for name in names:
                    spans.wrap(module, name, f'{module.__name__.split(".")[-1]}.{name}')
            observer.observation_pub = Handoff(estimator.on_observation)
            observer.event_pub = Handoff(estimator.on_event)
            sent = estimator.trajectory_pub = Sent(estimator.trajectory_pub)
            clock = observer.get_clock()
            rows = []
            t0 = time.perf_counter() + 0.02
            for offset, msg in zip(stream.offsets, stream.messages()):
                wait = t0 + offset - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
                msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_parts(
                    clock.now().nanoseconds)
                n_sent = len(sent.times)
                start = time.perf_counter()
                observer.on_pose(msg)
                end = time.perf_counter()
                if len(sent.times) > n_sent:
                    rows.append((end - start, sent.times[n_sent] - start))
            ms = np.array(rows) * 1e3
            result = {'poses': len(stream.offsets), 'poses_with_plan': len(rows)}
            for i, key in enumerate(('per_pose_ms', 'to_trajectory_ms')):
                result[f'{key}_median'] = round(float(np.median(ms[:, i])), 3)
                result[f'{key}_p99'] = round(float(np.percentile(ms[:, i], 99)), 3)
            result['stages'] = spans.report(len(stream.offsets))
        finally:
            estimator.destroy_node()
            observer.destroy_node()
            rclpy.try_shutdown(context=ctx)
    print(json.dumps(result))


if __name__ == '__main__':
    main()
