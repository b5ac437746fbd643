"""Bringup: nodes composed on one spinning executor, waits that name what they wait for."""

import threading

import pytest
from rclpy.node import Node
from sensor_msgs.msg import JointState

from maglev_ros.nodes.bringup import Bringup
from maglev_ros.nodes.contract import LOCKSTEP_COMMAND_QOS
from maglev_ros.nodes.excitation import ExcitationNode
from maglev_ros.stop_signals import StopSignals
from maglev_ros.topics import COMMAND_TOPIC


class Listener(Node):
    """Counts commands; records its destruction in ``destroyed``."""

    def __init__(self, name, destroyed, **kwargs):
        super().__init__(name, **kwargs)
        self.destroyed = destroyed
        self.received = 0
        self.create_subscription(JointState, COMMAND_TOPIC, self._on_command, LOCKSTEP_COMMAND_QOS)

    def _on_command(self, _msg):
        self.received += 1

    def destroy_node(self):
        self.destroyed.append(self.get_name())
        return super().destroy_node()


def test_spins_the_nodes_then_destroys_them_last_added_first_and_shuts_down(ctx):
    destroyed = []
    with Bringup(ctx) as bringup:
        first = bringup.add(Listener('first', destroyed, context=ctx))
        last = bringup.add(Listener('last', destroyed, context=ctx), destroy_last=True)
        bringup.start()
        excite = bringup.add(ExcitationNode(context=ctx))  # added while spinning
        bringup.wait_until(lambda: excite.command_subscribers >= 2, 'discovery', timeout=30.0)
        excite.publish_next()
        bringup.wait_until(
            lambda: first.received == 1 and last.received == 1, 'the command', timeout=30.0
        )
        assert ctx.ok()
    assert destroyed == ['first', 'last']
    assert not ctx.ok()
    bringup.close()  # idempotent


def test_a_timeout_names_what_was_waited_for(ctx):
    with Bringup(ctx) as bringup:
        bringup.start()
        with pytest.raises(RuntimeError, match=r'timed out after 0\.05 s waiting for the moon'):
            bringup.wait_until(lambda: False, 'the moon', timeout=0.05)


def test_a_stop_request_or_a_shut_down_context_ends_the_wait(ctx):
    with Bringup(ctx) as bringup:
        event = threading.Event()
        event.set()
        with pytest.raises(KeyboardInterrupt):
            bringup.wait_until(lambda: False, 'nothing', stop=event)
        stop = StopSignals(signals=())
        stop.request()
        with pytest.raises(KeyboardInterrupt):
            bringup.wait_until(lambda: False, 'nothing', stop=stop)
        bringup.close()
        with pytest.raises(KeyboardInterrupt):
            bringup.wait_until(lambda: False, 'nothing')
