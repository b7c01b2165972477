"""What the benches and experiments share; not a bench itself. They run as
``python bench/NAME.py`` or ``python experiments/NAME.py`` and import this module as
``bench._common`` (an experiment puts the checkout's root on sys.path first).

- The replayed wrist stream and the nodes' parameters of experiments/latency.py, which
  experiments/node_profile.py replays and profiles in one thread.
- The rest-deviation cut of experiments/gesture_representation.py: where a recording's movement
  starts and ends when its signal rests at a level (an accelerometer reads gravity at rest).
"""

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import Parameter
import yaml

from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.scenarios.recording import MOCAP_NOISE

# ---------------------------------------------------------------------------- node streams
# Stamp and wall pause between replayed interactions: a silence (the observer's 'gap'). Longer
# than the observer's max_backdate (2 s), so that the dating of the next onset sees none of the
# previous interaction's samples, which end elsewhere (core.segmentation fits the positions of
# the last max_backdate seconds, across a gap too).
GAP_S = 2.5
REST_PAD_S = 0.3                    # extra rest after each demo so every end is confirmed
# The estimator's settings of the latency headline: every pose used, a replan on each.
EVERY_POSE = {'min_interval': 0.0, 'replan_rate_hz': 200.0}
OBSERVER_YAML = config_path('observer.yaml')
ESTIMATOR_YAML = config_path('estimator.yaml')


def yaml_params(path, node):
    with open(path) as f:
        return yaml.safe_load(f)[node]['ros__parameters']


OBSERVER_PARAMS = yaml_params(OBSERVER_YAML, 'observer_node')
ESTIMATOR_PARAMS = yaml_params(ESTIMATOR_YAML, 'estimator_node')


def as_parameters(d):
    return [Parameter(k, value=v) for k, v in d.items()]


class Stream:
    """Poses to publish: wall offsets (s) and positions (stamped when published)."""

    def __init__(self):
        self.offsets, self.xyz = [], []

    def add(self, t, xyz):
        """One interaction's samples, ``t`` seconds from its first sample, after a pause."""
        start = self.offsets[-1] + GAP_S if self.offsets else 0.0
        for ti, p in zip(t.tolist(), xyz.tolist()):
            self.offsets.append(start + ti)
            self.xyz.append(p)

    def messages(self):
        msgs = []
        for x, y, z in self.xyz:
            m = PoseStamped()
            m.header.frame_id = 'world'
            m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, z
            m.pose.orientation.w = 1.0
            msgs.append(m)
        return msgs


def padded_wrist(g, seed, rate=None):
    """A demo's wrist samples (from its recording start) plus REST_PAD_S of rest (noise seeded
    by ``seed``); resampled to ``rate`` Hz (linear interpolation) if given."""
    rng = np.random.default_rng(seed)
    t, xyz = g.wrist_t, g.wrist_xyz
    dt = float(np.median(np.diff(t)))
    n = int(round(REST_PAD_S / dt))
    t = np.concatenate([t, t[-1] + dt * np.arange(1, n + 1)])
    xyz = np.vstack([xyz, xyz[-10:].mean(axis=0) + rng.normal(0.0, MOCAP_NOISE, (n, 3))])
    if rate is not None:
        tr = np.arange(0.0, t[-1], 1.0 / rate)
        xyz = np.column_stack([np.interp(tr, t, xyz[:, j]) for j in range(3)])
        t = tr
    return t, xyz


# ---------------------------------------------------------------------------- gesture cuts
def sensor_resolution(values) -> float:
    """The smallest step between distinct values of a recorded signal (its quantisation), NaN
    ignored; 0 for fewer than two distinct values."""
    v = np.unique(np.asarray(values, dtype=float)[~np.isnan(values)])
    d = np.diff(v)
    d = d[d > 1e-12 * max(1.0, float(np.max(np.abs(v))) if v.size else 1.0)]
    return float(d.min()) if d.size else 0.0


def segment_rest_deviation(t, Y, rest_window: float = 0.1, noise_factor: float = 4.0,
                           hold: float = 0.05):
    """Onset and end of a movement recorded between two rests, for signals whose rest is a
    level (an accelerometer at rest reads gravity) rather than a position at rest with zero
    speed (core.segmentation.MotionSegmenter). Any number of DOFs; (onset time, end time).

    Relative to the recording's own rest and sensor, never a fixed threshold: per DOF the rest
    level is the median of the first ``rest_window`` seconds, its noise the larger of their
    robust spread (1.4826 MAD) and the sensor's quantisation noise (resolution / sqrt(12), the
    resolution read off the recorded values). The onset is the first sample that starts
    ``hold`` seconds of deviation above ``noise_factor`` noise levels (in any DOF), dated back to
    the last sample within one noise level of rest; it uses only samples up to the confirming
    one, so an online detector finds the same onset. The end is the same rule on the reversed
    recording with the rest level of its last ``rest_window`` seconds. A recording without
    such a deviation at either end is taken whole there (it starts or ends mid-movement).
    """
    t = np.asarray(t, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if t.ndim != 1 or Y.shape[0] != t.size or t.size < 4:
        raise ValueError(f'segment_rest_deviation: need at least 4 samples and one row per time, '
                         f'got t {t.shape}, Y {Y.shape}')
    if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise ValueError('segment_rest_deviation: t must be finite and strictly increasing')
    if not np.all(np.isfinite(Y)):
        raise ValueError('segment_rest_deviation: Y contains NaN or Inf')
    floor = np.array([sensor_resolution(Y[:, j]) for j in range(Y.shape[1])]) / np.sqrt(12.0)
    period = float(np.median(np.diff(t)))
    n_rest = max(3, int(round(rest_window / period)))
    n_hold = max(1, int(round(hold / period)))

    def first_onset(Z):
        head = Z[:n_rest]
        level = np.median(head, axis=0)
        noise = np.maximum(1.4826 * np.median(np.abs(head - level), axis=0), floor)
        noise = np.where(noise > 0, noise, 1e-12 * np.maximum(1.0, np.abs(level)))
        dev = np.max(np.abs(Z - level) / noise, axis=1)
        above = dev > noise_factor
        run = np.convolve(above, np.ones(n_hold), mode='valid') >= n_hold   # run starting at i
        if not run.any():
            return 0
        i = int(np.argmax(run))
        calm = np.flatnonzero(dev[:i] <= 1.0)
        return int(calm[-1]) if calm.size else 0
    on = first_onset(Y)
    end = Y.shape[0] - 1 - first_onset(Y[::-1])
    if end <= on:
        return float(t[0]), float(t[-1])
    return float(t[on]), float(t[end])
