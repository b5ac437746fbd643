"""What the simulator reports about its session, without ROS: levels, messages, values."""

import numpy as np

from maglev_ros.health import ERROR, OK
from maglev_ros.physics import Simulator
from maglev_ros.physics.session import SimulationSession
from maglev_ros.physics.session_health import crash_line, session_health, timeout_line

FALLING = [0.001, 0.0, 0.0365] + [0.0] * 9  # free magnet just above the base


def test_levels_and_messages_follow_the_run_state(v2):
    session = SimulationSession(Simulator(v2, 5000.0, magnet='fixed'), 'lockstep', now=0.0)
    health = session_health(session, 'fixed')
    assert (health.level, health.message) == (OK, 'waiting for the command publisher')
    session.start(now=0.0)
    session.command(np.zeros(4), now=0.0)
    health = session_health(session, 'fixed')
    assert (health.level, health.message) == (OK, 'running (lockstep)')
    assert health.values['mode'] == 'lockstep' and health.values['magnet'] == 'fixed'
    assert health.values['parameter set'] == v2.params.name
    assert health.values['simulated time (s)'] == '0.000200'
    assert health.values['samples'] == 2 and health.values['commands'] == 1
    assert health.values['crash reason'] == '' and health.values['crash time (s)'] == ''
    session.set_paused(True, now=0.0)
    assert session_health(session, 'fixed').message == 'paused'


def test_a_crash_is_an_error_until_reset(v2):
    sim = Simulator(v2, 5000.0, magnet='free', x0=FALLING)
    session = SimulationSession(sim, 'lockstep', now=0.0)
    session.start(now=0.0)
    for _ in range(5000):
        batch = session.command(np.zeros(4), now=0.0)
        if batch.crashed:
            break
    assert sim.crashed
    health = session_health(session, 'free')
    assert health.level == ERROR
    assert health.message.startswith(f'crashed at t = {sim.crash_time:.4f} s: {sim.reason}')
    assert health.values['crash state'].count(' ') == 11
    line = crash_line(session)
    assert f'({sim.reason})' in line and line.endswith('call maglev/simulator/reset')
    session.reset(now=0.0)
    assert session_health(session, 'free').level == OK


def test_timeout_line_names_the_wait_and_the_time(v2):
    session = SimulationSession(
        Simulator(v2, 5000.0, magnet='fixed'), 'lockstep', command_timeout=0.5, now=0.0
    )
    assert timeout_line(session, 0.75) == (
        'no command for 0.750 s > 0.5 s at t = 0.000000 s: holding the last command'
    )


def test_command_lag_is_reported_once_a_stamped_command_came(v2):
    session = SimulationSession(Simulator(v2, 5000.0, magnet='fixed'), 'lockstep', now=0.0)
    session.start(now=0.0)
    assert session_health(session, 'fixed').values['command lag (samples)'] == ''
    session.command(np.zeros(4), now=0.0, stamp_ns=0)  # answers sample 0, the newest
    assert session_health(session, 'fixed').values['command lag (samples)'] == 0
