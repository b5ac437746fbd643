"""The main job: ``maglev-lab`` closed loop (the default), end to end in one process.

A short record (2000 samples after 0.4 s of levitation) of the whole chain:
simulator (lockstep, noise, quantisation, delay, coil dynamics), KF, LQR with
its PRBS, identifier, recorder; then the seed's models, the physics check and
the online identifier beside the batch ARX. The long record (25 000 samples)
is the README's main job.
"""

import json
import re

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from maglev_ros import topics
from maglev_ros.bags import read_bag
from maglev_ros.cli import lab
from maglev_ros.control.excitation import CommandExcitation, ExcitationSchedule

SAMPLES = 2000
SEED = 2
#: s of levitation before the record: past V2's settling time from an offset (0.34 s,
#: docs/benchmarks.md), so the settling check judges the noise-driven motion only
SETTLE = '0.4'


def test_closed_loop_session_records_exact_samples_and_identifies_the_seed_models(
    domain, tmp_path, capfd
):
    out = tmp_path / 'lab'
    argv = ['--duration', '0.4', '--settle', SETTLE, '--seed', str(SEED), '--out', str(out)]
    status = lab.main([*argv, '--quiet'])
    printed = capfd.readouterr().out
    summary = json.loads((out / 'models.json').read_text())
    assert status == summary['exit_status'] and status in (0, 1), printed
    run = summary['run']
    # exactly the samples asked for, after settling, each with its command and excitation
    assert f'recorded {SAMPLES} samples' in printed and f'settled after {SETTLE} s' in printed
    assert summary['data'] == {'N': SAMPLES, 'n_estimation': 1000, 'n_validation': 1000}
    assert run['timeouts'] == 0 and not run['crashed'] and run['settled']
    with Reader(out / 'bag') as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    channels = [topics.command_channel(k) for k in range(4)]
    channels += [topics.excitation_channel(k) for k in range(4)]
    u = np.asarray(read_bag(out / 'bag', [topics.field_channel(0, 'x')], channels).data.u)
    commands, excitations = u[:, :4], u[:, 4:]
    assert set(counts.values()) == {SAMPLES}, counts
    # the recorded excitation is the core's signal from its first sample on (seeded)
    cfg = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=SEED, length=SAMPLES)
    np.testing.assert_array_equal(excitations, ExcitationSchedule(cfg, 5000.0).sequence(SAMPLES))
    controller_part = commands - excitations
    assert np.abs(controller_part).max() <= 1.0 + 1e-12  # the LQR's limit
    # the magnet within 0.5 mm of its set-point during the excitation
    assert max(run['largest_excursion_m']) < 0.5e-3, run['largest_excursion_m']
    # the seed's models: x, y (ARX, IV on the excitation, ARMAX) and MIMO (ARX, ARMAX)
    models = summary['models']
    assert [(m['group'], m['label']) for m in models] == [
        ('x', 'ARX 7 9 1'), ('x', 'IV4 7 9 1'), ('x', 'ARMAX 5 5 3 1'),
        ('y', 'ARX 6 6 1'), ('y', 'IV4 6 6 1'), ('y', 'ARMAX 6 6 5 1'),
        ('mimo', 'ARX'), ('mimo', 'ARMAX'),
    ]  # fmt: skip
    iv = [m for m in models if m['structure'] == 'iv']
    assert [m['instruments'] for m in iv] == [['r_x'], ['r_y']]
    for m in models:
        assert m['model'] is not None and len(m['fit_validation']) == len(m['outputs'])
        if m['group'] != 'mimo':  # the physics check of every SISO model, in dB and degrees
            check = m['physics_check']
            assert check['band_hz'] == [10.0, 300.0] and np.isfinite(check['max_db'])
            assert re.search(rf'{re.escape(m["label"])}.*\d+\.\d\d dB +\d+\.\d deg', printed)
    # every model is fitted and validated; closed-loop data: the residual tests are strict
    # (ARX/ARMAX on the loop's coloured noise fail whiteness), each row says which test
    # failed, and the IV models are judged against their instruments
    assert all(m['status'] != 'failed' for m in models), [
        (m['label'], m['reason']) for m in models
    ]
    assert all(m['reason'] for m in models if m['status'] != 'ok')
    # the identifier node ran on the same samples: its ARX is the batch ARX of them
    assert summary['online']['samples'] == SAMPLES
    differences = [float(d) for d in re.findall(r'largest difference (\S+) of', printed)]
    assert len(differences) == 2 and max(differences) < 1e-5, printed
    for name in ('compare_x', 'compare_y', 'compare_mimo', 'physics_x', 'physics_y'):
        assert (out / f'{name}.png').stat().st_size > 10_000


@pytest.mark.parametrize(
    'argv, match',
    [
        (['--realtime', '--control-rate', '3000'], '--control-rate must divide --sample-rate'),
        (['--board', '/nonexistent/ttyACM0', '--magnet', 'free'], 'no such device'),
        (['--virtual-board', '--magnet', 'free', '--sample-rate', '4000'], "the board's 5000 Hz"),
        (['--virtual-board', '--magnet', 'free', '--delay', '0'], '--delay must be >= 1 on a'),
        (['--sensors', '0', '1'], 'the closed-loop session records and identifies sensor 0'),
        (['--check-band', '300', '10'], '--check-band must be LOW HIGH'),
        (['--amplitude', '0'], '--amplitude must be > 0'),
    ],
)  # fmt: skip
def test_what_the_closed_loop_does_not_run_is_a_usage_error(argv, match, tmp_path, capfd):
    out = tmp_path / 'lab'
    assert lab.main([*argv, '--out', str(out)]) == 2
    err = capfd.readouterr().err
    assert match in err and err.count('\n') == 1, err
    assert not out.exists()


def test_realtime_session_records_the_window_and_matches_its_online_arx(domain, tmp_path, capfd):
    """``--realtime``: the same outputs on the wall clock, the loop composed in one process.

    A loaded machine slows the simulation, not the loop (it is closed in the
    simulator's thread), so nothing here depends on keeping up with the clock.
    """
    out = tmp_path / 'lab'
    argv = ['--realtime', '--duration', '0.4', '--settle', SETTLE, '--seed', str(SEED)]
    status = lab.main([*argv, '--out', str(out), '--quiet', '--no-plots'])
    printed = capfd.readouterr().out
    summary = json.loads((out / 'models.json').read_text())
    assert status == summary['exit_status'] and status in (0, 1), printed
    run = summary['run']
    assert 'closed loop in real time (composed, control at 1000 Hz)' in printed
    assert run['clock'] == 'realtime' and not run['crashed'] and run['settled'], run
    assert summary['data']['N'] == SAMPLES  # exactly the window: every sample has its input
    with Reader(out / 'bag') as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    per_sample = [topics.field_topic(0), topics.CURRENTS_TOPIC, topics.TRUE_STATE_TOPIC]
    assert all(counts['/' + t] == SAMPLES for t in per_sample), counts
    # one command per 1 ms burst (5 samples), and the one in force at the start
    assert SAMPLES // 5 <= counts['/' + topics.COMMAND_TOPIC] <= SAMPLES // 5 + 2, counts
    assert max(run['largest_excursion_m']) < 0.5e-3, run['largest_excursion_m']
    # the identifier took the same samples, each command the input of the sample it answers
    assert summary['online']['samples'] == SAMPLES
    differences = [float(d) for d in re.findall(r'largest difference (\S+) of', printed)]
    assert len(differences) == 2 and max(differences) < 1e-5, printed


def test_virtual_board_session_levitates_records_the_window_and_matches_its_online_arx(
    domain, tmp_path, capfd
):
    """``--virtual-board --magnet free``: the closed loop against a board in a child process.

    The driver, estimator, controller, identifier and recorder are composed in
    this process; the board (physics plant, noise, quantisation, sensor delay)
    runs on the wall clock in its own. Exactly the window's records are in the
    bag and in the identifier, whose ARX is the batch ARX of them, with the
    currents the board applied as inputs; the magnet stays levitated.
    """
    out = tmp_path / 'lab'
    samples = 5000
    argv = ['--virtual-board', '--magnet', 'free', '--samples', str(samples), '--settle', '0.5']
    argv += ['--seed', str(SEED), '--out', str(out), '--quiet']  # control at 500 Hz
    status = lab.main([*argv, '--no-plots'])
    captured = capfd.readouterr()
    printed = captured.out
    assert (out / 'models.json').is_file(), captured.out + captured.err
    summary = json.loads((out / 'models.json').read_text())
    assert status == summary['exit_status'] and status in (0, 1), printed
    run = summary['run']
    assert 'closed loop in real time on a virtual board' in printed
    assert 'control at 500 Hz' in printed  # a board's default
    assert run['clock'] == 'virtual board' and run['state'] == 'estimated'
    assert not run['crashed'] and run['settled'], (run, captured.err)
    assert max(run['largest_excursion_m']) < 0.5e-3, run['largest_excursion_m']
    assert summary['data']['N'] == samples  # exactly the window, every record has its input
    with Reader(out / 'bag') as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/' + topics.field_topic(0)] == counts['/' + topics.CURRENTS_TOPIC] == samples
    # every command the loop wrote in the window is in the bag: at most one per 10 board
    # samples (500 Hz); fewer when the loop's process gets less than a core (it then
    # answers the newest sample of each read), never none
    # (the window's first record carries the command in force when it was read)
    commands = counts['/' + topics.COMMAND_TOPIC]
    assert commands - run['controller']['commands'] in (0, 1), (counts, run['controller'])
    assert samples // 40 < commands <= samples // 10 + 1, counts
    # the board plant's settings, the current limit in force (the scaling's full scale)
    assert summary['metadata']['maglev_driver.current_limit'] == pytest.approx(3.0)
    # the identifier took the same records: its ARX is the batch ARX of them
    assert summary['online']['samples'] == samples
    differences = [float(d) for d in re.findall(r'largest difference (\S+) of', printed)]
    assert len(differences) == 2 and max(differences) < 1e-5, printed


def test_the_online_comparison_survives_data_without_a_batch_arx(capsys):
    """A lost magnet leaves constant data: the batch ARX fails, the rest is still printed."""
    from maglev_ros.cli.closed_loop_lab import LabRun, _print_online
    from maglev_ros.loop import OnlineEstimate
    from maglev_ros.sysid import IdData
    from maglev_ros.sysid.online import OnlineArx

    rng = np.random.default_rng(1)
    arx = OnlineArx([[2, 0], [0, 2]], [[2, 0], [0, 2]], 1, ny=2, nu=2)
    arx.update_many(rng.standard_normal((200, 2)), rng.standard_normal((200, 2)))
    online = OnlineEstimate(arx.model(2e-4), 200, 1.0, np.zeros(2), 1.0)
    run = LabRun(200, 1.0, np.zeros(3), 0.5, True, 1.0, 1.0, 0, True, 'lost', {}, online)
    y, u = rng.standard_normal((200, 2)), np.zeros((200, 2))  # the coils at zero: no input
    _print_online(run, IdData(y, u, 2e-4, ['Bx_0', 'By_0'], ['u_x', 'u_y']))
    printed = capsys.readouterr().out
    assert printed.count('no batch ARX to compare') == 2, printed
    assert printed.startswith('online ARX (identifier node, 200 samples')
