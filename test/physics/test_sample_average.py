"""Averaging a simulation's samples in groups, across batches."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.physics.sample_average import SampleAverager
from maglev_ros.physics.session import SampleBatch


def _batch(first: int, m: int, rng) -> SampleBatch:
    k = np.arange(first, first + m)
    return SampleBatch(
        k.astype(np.int64),
        (k * 200_000).astype(np.int64),
        rng.normal(size=(m, 9)),
        np.tile(k[:, None], (1, 12)).astype(float),
        np.tile(k[:, None], (1, 4)).astype(float) * 0.01,
    )


def test_groups_are_averaged_across_batches_as_in_one_batch():
    rng = np.random.default_rng(0)
    whole = _batch(0, 23, rng)
    one = SampleAverager(5).add(whole)
    averager = SampleAverager(5)
    parts = [averager.add(SampleBatch(*(getattr(whole, f)[a:b] for f in (
        'indices', 'stamps_ns', 'readings', 'states', 'currents'))))
        for a, b in ((0, 3), (3, 4), (4, 17), (17, 23))]  # fmt: skip
    assert len(one) == 5 and sum(len(p) for p in parts) == 5
    joined = np.concatenate([p.readings for p in parts])
    np.testing.assert_array_equal(joined, one.readings)
    # the run's sample 0 alone, then samples 1-5, 6-10, ...: the 1 kHz grid of a 5 kHz run
    np.testing.assert_array_equal(one.readings[0], whole.readings[0])
    np.testing.assert_allclose(one.readings[1], whole.readings[1:6].mean(axis=0))
    # stamp and state: the group's last sample; the currents: the group's mean
    assert one.stamps_ns.tolist() == [0, 1_000_000, 2_000_000, 3_000_000, 4_000_000]
    assert one.indices.tolist() == [0, 1, 2, 3, 4]
    assert one.states[2, 0] == 10 and one.currents[3, 0] == pytest.approx(0.13)


def test_the_mean_divides_the_noise_by_the_root_of_the_group():
    rng = np.random.default_rng(1)
    noisy = _batch(0, 50_000, rng)
    means = SampleAverager(5).add(noisy)
    assert np.std(means.readings) == pytest.approx(1 / np.sqrt(5), rel=0.03)


def test_one_sample_per_mean_passes_samples_unchanged_and_bad_groups_are_refused():
    batch = _batch(0, 7, np.random.default_rng(2))
    assert SampleAverager(1).add(batch) is batch
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match='samples per mean must be an integer >= 1'):
            SampleAverager(bad)
