"""Every parameter of another node, fetched one at a time through its parameter services."""

import rclpy
from rclpy.parameter import Parameter
from waiting import wait_for

from maglev_ros.nodes.remote_parameters import RemoteParameters
from maglev_ros.nodes.runtime import Spinner


def test_every_parameter_arrives_past_an_unset_one(ctx):
    other = rclpy.create_node(
        'remote_other',
        context=ctx,
        parameter_overrides=[Parameter('seed', value=3), Parameter('rates', value=[1.5, 2.0])],
        automatically_declare_parameters_from_overrides=True,
    )
    other.declare_parameter('unset', Parameter.Type.STRING)  # answered with nothing
    asker = rclpy.create_node('remote_asker', context=ctx)
    done = []
    remote = RemoteParameters(asker, 'remote_other', done.append, timeout=0.3)
    asker.create_timer(0.05, remote.poll)
    spinner = Spinner(ctx, [other, asker])
    try:
        wait_for(lambda: remote.done, what='the parameters')
    finally:
        spinner.close()
        other.destroy_node()
        asker.destroy_node()
    assert done == [remote.items]
    assert remote.items['remote_other.seed'] == 3
    assert remote.items['remote_other.rates'] == '1.5 2.0'
    assert 'remote_other.use_sim_time' in remote.items
    assert remote.items.get('remote_other.unset', '') == ''  # no answer, or an empty one


def test_a_node_that_is_not_there_is_waited_for(ctx):
    asker = rclpy.create_node('remote_lonely', context=ctx)
    try:
        remote = RemoteParameters(asker, 'nobody_here', lambda items: None)
        remote.poll()
        assert not remote.done and remote.items == {}
    finally:
        asker.destroy_node()
