"""One replan of the estimator node, from the posterior to the serialized JointTrajectory, against
the way it was built before (same run): OnlineEstimator.predict per phase speed and rclpy
message objects.

Both produce the same message (checked here). Timed back to back ('hot') and each after a
10 ms sleep ('after_sleep'), as in the node, whose thread sleeps between mocap samples: a
freshly woken thread runs Python and numpy several times slower. K = 3 components, M = 50
alpha hypotheses, speed weight 0.2 (what training calibrates for box assembly and the pole:
the plan is the expected path over the phase speeds holding the posterior), 15 basis functions,
3 observed + 7 controlled DOFs, 25 points. Prints one JSON object.
"""

import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from builtin_interfaces.msg import Duration  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.core.online import OnlineEstimator  # noqa: E402
from mixture_ip_ros.io.cdr import JointTrajectoryEncoder  # noqa: E402
from mixture_ip_ros.estimation.plans import build_plan  # noqa: E402
from mixture_ip_ros.robot.description import JOINT_NAMES  # noqa: E402
from mixture_ip_ros.scenarios.synthetic import mixture_demos  # noqa: E402

N_POINTS = 25
LOOKAHEAD = 0.1
ONSET_NS = 1_000_000_000_000


def reference(est, t_now):
    """predict() (means and covariance machinery in numpy) per phase speed, weighted, and rclpy
    message objects."""
    k = est.map_hypothesis()[0]
    speeds, weights = est.speed_hypotheses(k)
    times = np.linspace(t_now + LOOKAHEAD, 1.0 / est.alphas[speeds].min(), N_POINTS)
    ctrl = {f: 0.0 for f in ('position', 'velocity', 'acceleration')}
    for m, w in zip(speeds, weights):
        a = est.alphas[m]
        pred = est.predict(a * times, component=k, alpha=a, covariance=False)['controlled']
        for f in ctrl:
            ctrl[f] = ctrl[f] + w * pred[f]
    vel, acc = ctrl['velocity'].copy(), ctrl['acceleration'].copy()
    vel[-1] = acc[-1] = 0.0
    msg = JointTrajectory()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ONSET_NS, 1_000_000_000)
    msg.joint_names = list(JOINT_NAMES)
    pos, vel, acc = ctrl['position'].tolist(), vel.tolist(), acc.tolist()
    points = []
    for i, t in enumerate(times.tolist()):
        sec, nanosec = divmod(int(round(t * 1e9)), 1_000_000_000)
        points.append(JointTrajectoryPoint(positions=pos[i], velocities=vel[i],
                                           accelerations=acc[i],
                                           time_from_start=Duration(sec=sec, nanosec=nanosec)))
    msg.points = points
    return serialize_message(msg)


def current(est, t_now, encoder):
    """What estimator_node does: planning.build_plan and io.cdr."""
    plan = build_plan(est, t_now, n_points=N_POINTS, lookahead=LOOKAHEAD)
    return encoder.encode(ONSET_NS, np.round(plan.times * 1e9).astype(np.int64),
                          plan.positions, plan.velocities, plan.accelerations)


def timed(fn, reps, sleep):
    out = []
    for _ in range(reps):
        if sleep:
            time.sleep(sleep)
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main():
    demos, _, _, _ = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=15)
    model = MixtureIProMP(3, n_basis=15, speed_weight=0.2).fit(demos)
    est = OnlineEstimator(model, n_alpha=50, min_interval=0.0)
    demo = max(demos, key=lambda d: d.duration)
    n = int(0.4 * len(demo.t))
    for t, y in zip(demo.t[:n], demo.observed[:n]):
        est.update(t, y)
    t_now = float(demo.t[n - 1])
    encoder = JointTrajectoryEncoder(JOINT_NAMES)
    ref = deserialize_message(reference(est, t_now), JointTrajectory)
    new = deserialize_message(current(est, t_now, encoder), JointTrajectory)
    same = [p.time_from_start for p in ref.points] == [p.time_from_start for p in new.points]
    err = max(float(np.max(np.abs(np.array(getattr(a, f)) - np.array(getattr(b, f)))))
              for a, b in zip(ref.points, new.points)
              for f in ('positions', 'velocities', 'accelerations'))
    if not same or err > 1e-9 or ref.header != new.header or ref.joint_names != new.joint_names:
        raise SystemExit(f'the two replans differ (times equal: {same}, max error {err})')
    result = {'max_abs_difference': err, 'n_speeds': int(len(est.speed_hypotheses()[0]))}
    # Interleaved so that both meet the same machine load.
    runs = {('reference', s): [] for s in ('hot', 'after_sleep')}
    runs.update({('current', s): [] for s in ('hot', 'after_sleep')})
    for _ in range(20):
        for state, sleep, reps in (('hot', 0.0, 50), ('after_sleep', 0.01, 10)):
            runs[('reference', state)] += timed(lambda: reference(est, t_now), reps, sleep)
            runs[('current', state)] += timed(lambda: current(est, t_now, encoder), reps, sleep)
    for state in ('hot', 'after_sleep'):
        r = np.median(runs[('reference', state)]) * 1e6
        c = np.median(runs[('current', state)]) * 1e6
        result[f'reference_us_{state}'] = round(float(r), 1)
        result[f'current_us_{state}'] = round(float(c), 1)
        result[f'speedup_{state}'] = round(float(r / c), 2)
    print(json.dumps(result))


if __name__ == '__main__':
    main()
