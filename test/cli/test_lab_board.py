"""``maglev-lab`` against a board: the driver node on a virtual board instead of the simulator.

``domain``: ``conftest.py``.
"""

import json
import math

import pytest

from maglev_ros.cli import lab


def test_virtual_board_session_is_identified_from_the_bag(domain, tmp_path, capfd):
    # physics plant, magnet fixed, no noise: the field is a static linear function of the
    # applied currents (same record), so ARX 1 1 0 (nk 0 is the board default) fits it;
    # higher orders are not identifiable on such noise-free data
    out = tmp_path / 'lab'
    status = lab.main(
        [
            '--virtual-board',
            '--magnet',
            'fixed',
            '--duration',
            '2',
            '--amplitude',
            '0.2',
            '--excitation',
            'prbs',
            '--seed',
            '3',
            '--na',
            '1',
            '--nb',
            '1',
            '--out',
            str(out),
        ]
    )
    captured = capfd.readouterr()
    printed = captured.out
    print(printed)
    assert status == 0, captured.err
    assert 'on a virtual board (maggy_v2, magnet fixed' in printed and 'fit val. %' in printed
    summary = json.loads((out / 'models.json').read_text())
    fits = {m['output']: m.get('fit_validation') for m in summary['models']}
    assert all(math.isfinite(fits[k]) for k in ('Bx_0', 'By_0')), printed
    assert fits['Bx_0'] >= 90.0 and fits['By_0'] >= 90.0, printed
    assert summary['args']['nk'] == 0
    # every record taken unchanged: the driver's stamps are uniform and shared
    assert summary['alignment']['base'] == 'stamps', printed
    assert set(summary['alignment']['methods'].values()) == {'exact'}, printed
    run = summary['run']
    assert run['samples'] >= 0.5 * 2 * 5000  # real time: the board sets the pace
    assert run['driver']['resyncs'] == 0 and run['driver']['dropped_bytes'] == 0
    meta = summary['metadata']
    assert meta['maglev_driver.n_sensors'] == 3 and meta['maglev_driver.start_enabled'] is True
    assert meta['maglev_driver.read_interval'] == lab.BOARD_READ_INTERVAL  # open loop: batched
    assert (out / 'compare_Bx_0.png').stat().st_size > 1000
    assert (out / 'bag' / 'metadata.yaml').is_file()


@pytest.mark.parametrize(
    'argv, match',
    [
        (['--board', '/dev/null', '--virtual-board'], 'not allowed with argument'),
        (['--virtual-board', '--sensors', '5'], '--sensors must be in 0 .. 2'),
        (['--board', '/dev/null', '--board-sensors', '0'], '--board-sensors must be >= 1'),
    ],
)
def test_bad_board_input_is_one_line_and_status_2(argv, match, tmp_path, capfd):
    assert lab.main(argv + ['--out', str(tmp_path / 'o')]) == 2
    err = capfd.readouterr().err
    assert match in err and err.count('\n') == 1


def _board_args(path, **kwargs):
    import argparse

    values = dict(board=path, board_sensors=None, virtual_board=False, sensors=[0])
    return argparse.Namespace(**{**values, **kwargs})


def test_a_board_tells_its_sensor_count():
    from functools import partial

    from maglev_ros.cli.lab_board import board_sensors
    from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
    from maglev_ros.hardware.virtual_board import VirtualBoard

    factory = partial(V2xFirmware, LinearPlant.default(3), 3, startup_delay=0.5)
    with VirtualBoard(factory) as board:
        assert board_sensors(_board_args(board.path)) == 3  # --sensors 0 alone said 1
        assert board_sensors(_board_args(board.path, board_sensors=2)) == 2  # as given


def test_a_silent_board_is_one_clear_line_within_5_s():
    import time
    from functools import partial

    from maglev_ros.cli.lab_board import board_sensors
    from maglev_ros.cli.usage import UsageError
    from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
    from maglev_ros.hardware.virtual_board import VirtualBoard

    factory = partial(V2xFirmware, LinearPlant.default(3), 3, startup_delay=60.0)
    with VirtualBoard(factory) as board:
        start = time.monotonic()
        with pytest.raises(UsageError, match=r'nothing in 4.5 s.*--board-sensors N'):
            board_sensors(_board_args(board.path))
        assert time.monotonic() - start < 5.0
