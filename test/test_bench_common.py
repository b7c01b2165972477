"""What the benches share (bench/_common.py), where a bench's result rests on it."""

import numpy as np
import pytest

from bench._common import segment_rest_deviation, sensor_resolution


def test_rest_deviation_segmentation_is_relative_to_rest_level_and_resolution():
    rng = np.random.default_rng(0)
    step = 0.04                                           # a quantised sensor at rest on 1 g
    t = np.arange(300) / 100.0
    y = np.full(300, 1.0)
    y[100:200] += 0.6 * np.sin(np.pi * (t[100:200] - 1.0))   # the movement: 1.0 s .. 2.0 s
    y[200:] = 0.7                                          # rest again, at another level
    y = np.round((y + rng.normal(0, 0.01, 300)) / step) * step
    assert sensor_resolution(y) == pytest.approx(step)
    on, end = segment_rest_deviation(t, y)
    assert 0.9 <= on <= 1.1 and 1.9 <= end <= 2.1
    # Ten times the scale (another unit): the same times, nothing is a fixed threshold.
    assert segment_rest_deviation(t, 10 * y) == (on, end)
