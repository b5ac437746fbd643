"""The V2x board as the loop's plant: records in, guarded commands out, coils at zero at the end.

The port is a stand-in link that hands out V2x records as the firmware writes
them and keeps what the plant writes (decoded by the board's own parser).
"""

import numpy as np
import pytest

from maglev_ros.hardware.packet import CommandParser
from maglev_ros.hardware.serial_link import LinkError
from maglev_ros.hardware.v2x_stream import pack_records
from maglev_ros.loop import BoardPlant, Plant

N_SENSORS = 2


class FakeLink:
    """A serial link: each read returns the next chunk of records; writes are parsed."""

    port = '/dev/fake'

    def __init__(self, chunks, fail_after=None):
        self.chunks = list(chunks)
        self.fail_after = fail_after
        self.is_open = False
        self.parser = CommandParser()
        self.commands = []
        self.reads = 0

    def open(self):
        self.is_open = True
        return self

    def close(self):
        self.is_open = False

    def read(self):
        self.reads += 1
        if self.fail_after is not None and self.reads > self.fail_after:
            raise LinkError('read from /dev/fake failed: device disconnected')
        return self.chunks.pop(0) if self.chunks else b''

    def write(self, data):
        self.commands += self.parser.feed(data)


def _records(start, n, pwm=(0, 0, 0, 0)):
    t = 200 * np.arange(start, start + n)
    field = np.zeros((n, N_SENSORS, 3))
    field[:, :, 2] = -9.0 + 0.001 * np.arange(start, start + n)[:, None]  # mT
    return pack_records(t, field, np.tile(pwm, (n, 1)))


def test_reads_wait_for_a_burst_of_samples_in_si_units_and_stamped():
    link = FakeLink([_records(5 * i, 5) for i in range(6)])
    plant = BoardPlant('/dev/fake', N_SENSORS, burst=10, serial=link)
    assert isinstance(plant, Plant) and not plant.lockstep
    first = plant.read()
    second = plant.read()
    assert len(first) == 10 and len(second) == 10
    np.testing.assert_array_equal(np.r_[first.index, second.index], np.arange(20))
    assert np.all(np.diff(np.r_[first.stamps_ns, second.stamps_ns]) > 0)
    assert first.times[0] == 0.0
    assert first.readings.shape == (10, 3 * N_SENSORS)
    np.testing.assert_allclose(first.readings[:, 2], -9e-3 + 1e-6 * np.arange(10), atol=1e-9)
    assert plant.counters['records'] == 20
    assert link.commands[0] == (0, 0, 0, 0)  # opening sends zero currents


def test_commands_pass_the_guard_and_closing_zeroes_the_coils():
    link = FakeLink([_records(0, 5)])
    plant = BoardPlant('/dev/fake', N_SENSORS, burst=5, current_limit=1.0, serial=link)
    block = plant.read()
    plant.write(np.array([0.5, -0.5, 2.0, np.nan]), int(block.stamps_ns[-1]))  # rejected
    plant.write(np.array([0.5, -0.5, 2.0, -0.25]), int(block.stamps_ns[-1]))  # 2 A clamped
    counts = plant.scaling.to_counts(np.array([0.5, -0.5, 1.0, -0.25]))
    assert link.commands[-1] == tuple(int(c) for c in counts)
    assert plant.counters['commands_rejected'] == 1 and plant.counters['commands_clamped'] == 1
    meta = plant.metadata()
    assert meta['maglev_driver.current_limit'] == 1.0 and meta['maglev_driver.n_sensors'] == 2
    plant.close()
    assert link.commands[-1] == (0, 0, 0, 0) and not link.is_open
    plant.close()  # idempotent
    assert plant.read().crashed


def test_the_default_limit_is_the_full_scale_in_the_metadata():
    plant = BoardPlant('/dev/fake', N_SENSORS, serial=FakeLink([]))
    assert plant.metadata()['maglev_driver.current_limit'] == pytest.approx(3.0)  # 12 V / 4 ohm


def test_a_lost_link_ends_the_run_with_the_coils_zeroed():
    link = FakeLink([_records(0, 5)], fail_after=1)
    plant = BoardPlant('/dev/fake', N_SENSORS, burst=5, serial=link)
    assert len(plant.read()) == 5
    plant.write(np.full(4, 0.3), 0)
    block = plant.read()
    assert block.crashed and 'device disconnected' in block.reason and len(block) == 0
    assert link.commands[-1] == (0, 0, 0, 0) and not link.is_open
