"""Shared fixtures of the node tests: one ROS domain and one rclpy Context per test.

Domain ids come from the ranges whose DDS ports stay out of Linux's ephemeral
port range (32768-60999), 1-101 and 215-232, so a test's discovery ports never
collide with a random socket; every test of a session gets its own id.
"""

import itertools
import os

import pytest
import rclpy
from rclpy.context import Context

SAFE_DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
_NEXT = itertools.count(os.getpid() % len(SAFE_DOMAIN_IDS))


def next_domain_id() -> int:
    """A domain id not used yet in this session (wraps after 119 tests)."""
    return SAFE_DOMAIN_IDS[next(_NEXT) % len(SAFE_DOMAIN_IDS)]


@pytest.fixture
def domain(monkeypatch):
    domain_id = next_domain_id()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain_id))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return domain_id


@pytest.fixture
def ctx(domain):
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    yield context
    rclpy.try_shutdown(context=context)
