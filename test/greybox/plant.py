"""A perturbed Maggy V2 plant for the calibration tests: simulated static runs and their bags.

The plant differs from the nominal set in several parameters at once (a few
percent, a few tenths of a millimetre); the data come from the physics
package's :class:`Simulator` (sensor noise 0.1 mT, one sample of sensor delay),
not from the calibration code's own model path.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from maglev_ros.greybox import StaticExperiment, parameter_vector
from maglev_ros.physics import MaggyModel, SensorEffects, Simulator, load_parameters

NOISE = 1e-4  # T rms per axis
TS = 2e-4  # s (5 kHz)
T0_NS = 1_700_000_000_000_000_000


@lru_cache(maxsize=1)
def nominal_vector():
    return parameter_vector(load_parameters('maggy_v2'))


def truth() -> dict[str, float]:
    """The plant's parameters that differ from nominal."""
    v = nominal_vector()
    return {
        'coil0.gain': 1.03,
        'coil1.gain': 0.97,
        'coil2.gain': 1.02,
        'coil3.gain': 0.985,
        'sensor1.x': v['sensor1.x'].nominal + 3e-4,
        'sensor2.y': v['sensor2.y'].nominal - 2e-4,
        'sensor0.z': v['sensor0.z'].nominal + 1e-4,
        'sensor0.offset_z': 5e-4,
        'sensor2.offset_x': -3e-4,
        'sensor1.gain_z': 1.02,
        'pm0.polarization': 1.1 * 1.03,
        'magnet.polarization': -1.0 * 0.98,
        'magnet.mass': 0.077 * 1.05,
    }


@lru_cache(maxsize=1)
def plant_model() -> MaggyModel:
    return MaggyModel(nominal_vector().apply(truth()))


def excitation(n: int, seed: int, hold: int = 25) -> np.ndarray:
    """Random current levels in [-1, 1] A per coil, each held ``hold`` samples, (n, 4)."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-1.0, 1.0, (n // hold + 1, 4))
    return np.repeat(levels, hold, axis=0)[:n]


@lru_cache(maxsize=4)
def simulate(magnet: str, n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Currents (n + 1, 4) and readings (n + 1, 9) of the plant, magnet absent or fixed."""
    seed = seed + (1000 if magnet == 'fixed' else 0)  # independent runs: own noise, own input
    sim = Simulator(
        plant_model(),
        sensor=SensorEffects(noise_rms=NOISE, delay_samples=1),
        seed=seed,
        magnet=magnet,
    )
    run = sim.run(excitation(n, seed + 100))
    return run.currents, run.y


def experiment(magnet: str, n: int = 12_500, seed: int = 1) -> StaticExperiment:
    u, y = simulate(magnet, n, seed)
    return StaticExperiment(u, y, magnet, f'plant, magnet {magnet}', TS)


def write_bag(
    path: Path, magnet: str | None, n: int = 6_000, seed: int = 1, key: str = 'magnet'
) -> Path:
    """Write a simulated run as a bag: three sensor topics and the currents, lockstep stamps.

    ``magnet`` None leaves where the magnet was out of the metadata; ``key`` is
    its metadata key.
    """
    u, y = simulate(magnet or 'absent', n, seed)
    metadata = {'params': 'maggy_v2', 'seed': seed}
    if magnet is not None:
        metadata[key] = magnet
    return write_record(path, u, y, metadata)


def write_record(path: Path, u: np.ndarray, y: np.ndarray, metadata: dict) -> Path:
    """Write currents (N, 4) and fields (N, 9) as a bag with lockstep stamps at 5 kHz."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.bags import BagWriter

    with BagWriter(path, storage='mcap', metadata=metadata) as bag:
        sensors = [
            bag.add_topic(f'/maglev/sensor_{k}/field', 'sensor_msgs/msg/MagneticField')
            for k in range(3)
        ]
        currents = bag.add_topic('/maglev/currents', 'sensor_msgs/msg/JointState')
        for i in range(u.shape[0]):
            stamp = T0_NS + i * 200_000
            sec, nanosec = divmod(stamp, 1_000_000_000)
            for k, handle in enumerate(sensors):
                msg = MagneticField()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                msg.header.frame_id = f'maglev_sensor_{k}'
                b = y[i, 3 * k : 3 * k + 3]
                msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = map(float, b)
                bag.write(handle, stamp + 30_000, serialize_message(msg))
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            msg.name = ['x+', 'x-', 'y+', 'y-']
            msg.effort = [float(v) for v in u[i]]
            bag.write(currents, stamp + 40_000, serialize_message(msg))
    return path
