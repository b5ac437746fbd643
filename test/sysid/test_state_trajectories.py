"""States from a bag: Odometry back to the 12-state, with the coil currents."""

import numpy as np
import pytest

from maglev_ros.sysid.state_trajectories import bag_states

pytest.importorskip('rclpy')


def test_true_state_round_trip(tmp_path):
    from rclpy.serialization import serialize_message

    from maglev_ros.bags import BagWriter
    from maglev_ros.nodes.messages import currents_message, odometry_message

    rng = np.random.default_rng(0)
    n, t0, step = 200, 1_700_000_000_000_000_000, 200_000
    x = np.zeros((n, 12))
    x[:, :3] = rng.normal(0.0, 1e-3, (n, 3)) + [0.0, 0.0, 0.03]
    x[:, 3:6] = rng.normal(0.0, 0.02, (n, 3))
    x[:, 6:] = rng.normal(0.0, 0.05, (n, 6))
    currents = rng.uniform(-1.0, 1.0, (n, 4))
    with BagWriter(tmp_path / 'bag') as bag:
        state = bag.add_topic('/maglev/state/true', 'nav_msgs/msg/Odometry')
        coils = bag.add_topic('/maglev/currents', 'sensor_msgs/msg/JointState')
        for k in range(n):
            stamp = t0 + k * step
            bag.write(state, stamp, serialize_message(odometry_message(stamp, x[k])))
            bag.write(coils, stamp, serialize_message(currents_message(stamp, currents[k])))
    trajectory = bag_states(tmp_path / 'bag')
    assert trajectory.dt == pytest.approx(2e-4)
    np.testing.assert_allclose(trajectory.x, x, atol=1e-12)
    np.testing.assert_allclose(trajectory.u, currents, atol=1e-12)
