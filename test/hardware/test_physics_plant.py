import numpy as np
import pytest

from maglev_ros import physics
from maglev_ros.hardware.firmware import V2xFirmware
from maglev_ros.hardware.physics_plant import SimulatorPlant, make_simulator_plant
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v2x_stream import RecordDecoder

SCALING = CurrentScaling(1000.0)  # counts per A


@pytest.fixture(scope='module')
def model():
    return physics.make_model('maggy_v2')


@pytest.mark.parametrize('magnet', ['fixed', 'absent'])
def test_readings_are_the_model_measurement_in_mt(model, magnet):
    plant = SimulatorPlant(physics.Simulator(model, magnet=magnet), SCALING)
    assert plant.n_sensors == model.n_outputs // 3
    pose = plant.simulator.state
    for pwm in ([0, 0, 0, 0], [500, -500, 250, -250], [4096, 4096, -4096, -4096]):
        field = plant(np.array(pwm), 0.0)
        current = np.array(pwm) / 1000.0
        expected = model.measurement(pose, current, with_magnet=(magnet == 'fixed')) * 1e3
        np.testing.assert_allclose(field, expected.reshape(-1, 3), rtol=1e-9, atol=1e-12)


def test_free_magnet_falls_and_stays(model):
    plant = SimulatorPlant(physics.Simulator(model, magnet='free'), SCALING)
    for _ in range(5000):  # 1 s of a small push without control: it falls or flies off
        plant(np.array([100, 0, 0, 0]), 0.0)
    assert plant.crashed
    rest = plant(np.zeros(4, dtype=int), 0.0)
    pushed = plant(np.array([2000, 2000, 2000, 2000]), 0.0)
    assert np.all(np.isfinite(rest)) and not np.allclose(rest, pushed)  # the coils still act
    plant.reset()
    assert not plant.crashed


def test_sample_rate_must_match_the_board(model):
    with pytest.raises(ValueError, match='simulator must sample every 200 us, got 1000 us'):
        SimulatorPlant(physics.Simulator(model, sample_rate=1000.0), SCALING)
    with pytest.raises(ValueError, match='magnet must be one of free, fixed, absent'):
        make_simulator_plant('floating')


def test_firmware_streams_physics_fields(model):
    plant = make_simulator_plant('fixed', scaling=SCALING)
    board = V2xFirmware(plant, plant.n_sensors, startup_delay=0.0)
    decoder = RecordDecoder(plant.n_sensors, confirm=False)
    batch = decoder.feed(board.advance_to(10_000))
    assert len(batch) == 50 and decoder.stats.dropped_bytes == 0
    expected = model.measurement(plant.simulator.state, np.zeros(4)) * 1e3
    np.testing.assert_array_equal(batch.field_mT[-1], expected.reshape(-1, 3).astype(np.float32))


def test_sensor_effects_reach_the_readings(model):
    """The sensors of maglev-virtual-board --noise --quantization --sensor-delay --seed."""
    lsb = 0.098e-3  # T
    sensor = physics.SensorEffects(noise_rms=1e-4, quantization=lsb, delay_samples=1)
    plants = [
        make_simulator_plant('fixed', 'maggy_v2', SCALING, sensor, seed) for seed in (3, 3, 4)
    ]
    readings = [np.array([p(np.zeros(4), 0.0) for _ in range(4000)]) for p in plants]
    ideal = model.measurement(plants[0].simulator.state, np.zeros(4)).reshape(-1, 3) * 1e3
    error = readings[0] - ideal  # mT
    assert 0.09 < error.std() < 0.11  # 0.1 mT rms (plus the LSB's 0.028 mT), per axis
    steps = readings[0] / (lsb * 1e3)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # whole LSBs
    np.testing.assert_array_equal(readings[0], readings[1])  # the seed fixes the noise
    assert not np.array_equal(readings[0], readings[2])


def test_a_crashed_magnet_is_still_read_through_the_sensor_noise():
    """A noiseless reading repeated 20 times trips the V4x firmware's freeze reset.

    After a crash the readings were the model's noiseless measurement: the
    virtual V4x board then reset its sensor (160 ms without replies) every 20
    samples, and a host's loop crawled at about 30 samples per second.
    """
    from maglev_ros.hardware.scaling import V4X_PWM_FULL_SCALE
    from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware
    from maglev_ros.hardware.v4x_pc_protocol import set_pwm_request

    scaling = CurrentScaling.from_supply(12.0, 4.0, V4X_PWM_FULL_SCALE)
    sensor = physics.SensorEffects(noise_rms=1e-4, quantization=0.098e-3)
    plant = make_simulator_plant('free', scaling=scaling, sensor=sensor, seed=3)
    firmware = V4xPcFirmware(plant, scaling=scaling, init_delay=0.0)
    firmware.advance_to(firmware.setup_us)
    firmware.receive(set_pwm_request(70, 0))  # x+ at 70 counts, no control: it crashes
    firmware.advance_to(firmware.setup_us + 1_500_000)
    assert plant.crashed
    readings = np.array([plant(np.zeros(4, dtype=int), 0.0) for _ in range(200)])
    assert np.std(readings[:, 0, 0]) > 0.05  # mT: the sensor's 0.1 mT of noise
    assert firmware.freeze_resets == 0
