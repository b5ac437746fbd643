"""``ros2 run maglev_ros calibrate``: the calibration command through the real ROS 2 CLI."""

from __future__ import annotations

import numpy as np


def _bag(path):
    """A short simulated bag of the nominal V2 board, magnet absent, 3 sensors."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.bags import BagWriter
    from maglev_ros.physics import SensorEffects, Simulator, make_model

    rng = np.random.default_rng(2)
    drives = np.repeat(rng.uniform(-1, 1, (80, 4)), 25, axis=0)
    sim = Simulator(
        make_model('maggy_v2'),
        sensor=SensorEffects(noise_rms=1e-4, delay_samples=1),
        seed=2,
        magnet='absent',
    )
    run = sim.run(drives)
    with BagWriter(path, metadata={'maglev_simulator.magnet': 'absent'}) as bag:
        fields = [
            bag.add_topic(f'/maglev/sensor_{k}/field', 'sensor_msgs/msg/MagneticField')
            for k in range(3)
        ]
        currents = bag.add_topic('/maglev/currents', 'sensor_msgs/msg/JointState')
        for i in range(run.y.shape[0]):
            stamp = 1_000_000_000 + i * 200_000
            sec, nsec = divmod(stamp, 1_000_000_000)
            for k, topic in enumerate(fields):
                msg = MagneticField()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
                b = run.y[i, 3 * k : 3 * k + 3]
                msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = map(float, b)
                bag.write(topic, stamp, bytes(serialize_message(msg)))
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
            msg.effort = [float(v) for v in run.currents[i]]
            bag.write(currents, stamp, bytes(serialize_message(msg)))
    return path


def test_ros2_run_calibrate(ros2_env, domain, tmp_path):
    bag = _bag(tmp_path / 'absent')
    out = tmp_path / 'myboard.yaml'
    args = ['run', 'maglev_ros', 'calibrate', str(bag), '--free', 'coil*.gain']
    proc = ros2_env.run([*args, '--out', str(out)], domain, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'iteration 1:' in proc.stdout and out.is_file()
    from maglev_ros.physics import load_parameters

    gains = load_parameters(out).solenoids.turns / 480.0
    assert np.all(np.abs(gains - 1.0) < 0.03), gains  # the nominal board: gains near 1

    bad = ros2_env.run([*args[:4], '--free', 'coil9.gain'], domain, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "maglev-calibrate: error: no parameter matches 'coil9.gain' (e.g. magnet.polarization, "
        'magnet.mass, pm0.polarization, pm1.polarization, pm2.polarization, pm3.polarization, '
        '...; --list shows all)'
    ]
