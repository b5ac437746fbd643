"""A node process spins with its start-up objects out of the garbage collector's way."""

import gc

import rclpy
from rclpy.node import Node

from maglev_ros.nodes.runtime import run_nodes


def test_the_nodes_spin_on_a_frozen_heap_and_leave_it_unfrozen(domain):
    seen = []

    def factory():
        node = Node('maglev_runtime_probe')

        def once():
            seen.append(gc.get_freeze_count())
            rclpy.try_shutdown()  # ends the spin as a stop would, without a signal

        node.create_timer(0.05, once)
        return node

    gc.unfreeze()  # whatever an earlier test in this process left frozen
    assert run_nodes([factory], [], 'maglev_runtime_probe', errors=(ValueError,)) == 0
    # the node, rclpy and the rest of start-up were frozen while the callbacks ran
    assert seen and seen[0] > 10_000, seen
    assert gc.get_freeze_count() == 0  # and unfrozen after
