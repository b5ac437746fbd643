"""When a plant node's run may start: the graph it needs is there.

A simulated magnet falls from its first sample on, so the simulator starts only
once the nodes that act on it and record it are up: a command publisher,
enough readers of the currents, and, when named, a recorder that reads the
topics other nodes publish (it finds topics by polling the graph, so without
the wait its bag could miss the first commands and estimates).
"""

from __future__ import annotations

from rclpy.node import Node

from maglev_ros.topics import COMMAND_TOPIC

__all__ = ['StartGate', 'reads_topics']


def reads_topics(node: Node, reader: str, topics) -> bool:
    """Return whether the node named ``reader`` subscribes to each of ``topics``.

    Parameters
    ----------
    node : rclpy.node.Node
        A node of this process (its view of the graph).
    reader : str
        The reading node's name ('': none, always true).
    topics : iterable of str
        Fully resolved topic names.
    """
    info = node.get_subscriptions_info_by_topic
    return not reader or all(any(i.node_name == reader for i in info(t)) for t in topics)


class StartGate:
    """The start condition, a callable (true once the graph is ready).

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node.
    currents_pub : rclpy.publisher.Publisher
        Its ``maglev/currents`` publisher.
    config : SimulatorConfig
        Its ``start_subscribers`` (matched readers of the currents to wait for),
        ``start_reader`` (a node that must subscribe to the
        ``start_reader_topics``; '' : none) and ``start_reader_topics``.
    """

    def __init__(self, node: Node, currents_pub, config) -> None:
        self.node = node
        self.currents_pub = currents_pub
        self.subscribers = config.start_subscribers
        self.reader = config.start_reader
        self.reader_topics = tuple(node.resolve_topic_name(t) for t in config.start_reader_topics)

    def __call__(self) -> bool:
        """Return whether a command publisher, the currents' readers and the reader are there."""
        return (
            self.node.count_publishers(COMMAND_TOPIC) >= 1
            and self.currents_pub.get_subscription_count() >= self.subscribers
            and reads_topics(self.node, self.reader, self.reader_topics)
        )
