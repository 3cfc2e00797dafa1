"""The fit report's summary figure thins each curve to its blocks' extremes (`fitting.report._thinned`)."""

import math

import numpy as np

from fitting.report import _thinned


def test_thinning_keeps_every_blocks_minimum_and_maximum_in_time_order():
    rng = np.random.default_rng(4)
    n, points = 12_001, 1500  # a block of 17 samples; the last block is short
    time = np.arange(n) * 1e-6
    data = rng.normal(size=n)
    data[7_777] = 40.0  # a spike inside a block
    other = 2.0 * data
    t, d, o = _thinned(time, data, other, points=points)
    block = math.ceil(2 * n / points)
    assert np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(o, 2.0 * d)  # the other curves follow the same samples
    for start in range(0, n, block):
        segment = data[start:start + block]
        kept = d[(t >= time[start]) & (t <= time[min(start + block, n) - 1])]
        assert kept.min() == segment.min() and kept.max() == segment.max(), start
        assert kept.size <= 2
    assert 40.0 in d
    assert len(t) <= 2 * math.ceil(n / block)


def test_short_curves_are_not_thinned():
    time = np.arange(10.0)
    t, d = _thinned(time, time**2, points=1500)
    np.testing.assert_array_equal(d, time**2)
