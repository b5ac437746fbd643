"""The coil pairs' feedthrough a V4x PC-control board leaves, measured before the magnet comes.

On the emulated firmware (physics plant, 0.1 mT sensor noise, 0.098 mT resolution):
its own slopes are measured at power-up with that noise, so what each pair leaves
is known exactly from them and from the model's coil field.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from maglev_ros.hardware.v4x_pc_feedthrough import (
    MagnetPresentError,
    PairFeedthrough,
    measure_feedthrough,
    measurement_time,
    wait_for_magnet,
)
from maglev_ros.loop.v4x_pc_setup import board_model
from maglev_ros.physics.board_processing import BoardProcessing

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'loop'))
from test_v4x_pc_plant import SETTINGS, emulated_board  # noqa: E402


def _left_by_the_firmware(firmware) -> np.ndarray:
    """Bx per ampere of the x pair, By per ampere of the y pair, after the board's slopes."""
    model = board_model(SETTINGS.params, SETTINGS.sensor)
    x = model.hover_state(0.03)
    base = model.measurement(x, np.zeros(4), with_magnet=False)
    raw = np.column_stack(
        [model.measurement(x, np.eye(4)[j], with_magnet=False) - base for j in range(4)]
    )
    s = np.asarray(firmware.slopes, float) * 1e-3  # mT/A -> T/A, x+ and y+ negated
    return np.array([raw[0, 0] - raw[0, 1] + s[0] + s[1], raw[1, 2] - raw[1, 3] + s[2] + s[3]])


@pytest.mark.parametrize('seed', [0, 3])
def test_what_each_pair_leaves_is_measured_within_its_std(seed):
    _, firmware, port, link = emulated_board(seed)
    link.open()
    start = port.clock()
    ft = measure_feedthrough(link, clock=port.clock, sleep=port.sleep)
    assert port.clock() - start == pytest.approx(measurement_time(), abs=0.01)
    truth = _left_by_the_firmware(firmware)
    measured = np.array([ft.response[0, 0], ft.response[1, 1]])
    std = np.array([ft.std[0, 0], ft.std[1, 1]])
    assert np.all(np.abs(measured - truth) < 3 * std + 1e-6), (measured, truth, std)
    assert np.all(std < 5e-6)  # 0.005 mT/A: a tenth of what the firmware's slopes leave
    assert np.max(np.abs(truth)) > 2e-5  # these boards leave 0.02-0.04 mT/A on one axis
    assert np.all(np.abs(ft.offset) < 1e-5) and ft.samples == 1200
    assert firmware.pwm.tolist() == [0, 0, 0, 0]  # the coils end at zero
    # the bag's metadata text gives the same numbers back
    meta = ft.metadata()
    assert np.allclose(
        PairFeedthrough.response_from(meta['board_feedthrough']), ft.response, rtol=1e-6, atol=0
    )
    std = PairFeedthrough.response_from(meta['board_feedthrough_std'], 'board_feedthrough_std')
    assert np.allclose(std, ft.std, rtol=1e-6, atol=0)
    assert 'x pair into Bx' in ft.summary()


def test_the_magnet_on_the_board_is_refused_with_the_coils_at_zero():
    _, firmware, port, link = emulated_board(place_after=0.0)  # in place from set-up's end
    link.open()
    with pytest.raises(
        MagnetPresentError,
        match=r'the board reads Bz .* with the coils off: the magnet is in place',
    ):
        measure_feedthrough(link, clock=port.clock, sleep=port.sleep)
    assert firmware.pwm.tolist() == [0, 0, 0, 0]


def test_a_magnet_that_comes_during_the_measurement_is_refused():
    """Placed 0.45 s into it: the x pair's last zero level reads the magnet."""
    _, firmware, port, link = emulated_board(place_after=0.5)
    link.open()
    with pytest.raises(MagnetPresentError, match=r'with the coils off: the magnet is in place'):
        measure_feedthrough(link, clock=port.clock, sleep=port.sleep)
    assert firmware.pwm.tolist() == [0, 0, 0, 0]


class _PassingMagnet:
    """A link whose Bz rises 0.5 mT while the x pair is at its third level (a magnet
    brought near and taken away again: the coils-off levels read nothing)."""

    def __init__(self):
        self.calls = 0
        self.commands = []

    def command_and_sample(self, p_x, p_y):
        from types import SimpleNamespace

        self.calls += 1
        level = (self.calls - 1) // 120  # 20 settle + 100 kept per level
        bz = 0.5 if level == 2 else 0.0
        i = 0.0118 * p_x  # A per count, as the board's ADC reads the pair
        return SimpleNamespace(
            field_mT=np.array([0.0, 0.0, bz]), currents_A=np.array([i, -i, 0.0, 0.0])
        )

    def command(self, p_x, p_y):
        self.commands.append((p_x, p_y))


def test_a_magnet_that_passes_near_during_the_measurement_is_refused():
    link = _PassingMagnet()
    with pytest.raises(MagnetPresentError, match=r'the field moved during the measurement'):
        measure_feedthrough(link, clock=lambda: 0.0, sleep=lambda s: None)
    assert link.commands[-1] == (0, 0)  # the coils end at zero


def test_the_wait_ends_when_the_magnet_is_in_place_and_times_out_without_it():
    sim, firmware, port, link = emulated_board(place_after=1.0)
    link.open()
    field = BoardProcessing.from_model(board_model(SETTINGS.params, SETTINGS.sensor))
    model = board_model(SETTINGS.params, SETTINGS.sensor)
    from maglev_ros.physics import linearize

    bz = (linearize(model).y_eq - field.baseline)[2]
    waited = wait_for_magnet(link, bz, clock=port.clock, sleep=port.sleep)
    assert port.clock() * 1e6 == pytest.approx(firmware.placed_us, abs=2000)  # within 2 ms
    assert 0.5 < waited < 1.1
    _, _, port2, link2 = emulated_board(place_after=5.0)
    link2.open()
    with pytest.raises(TimeoutError, match=r'no magnet in place within 1 s .* hold the magnet'):
        wait_for_magnet(link2, bz, timeout=1.0, clock=port2.clock, sleep=port2.sleep)


def test_bad_metadata_is_named():
    with pytest.raises(ValueError, match='six finite numbers'):
        PairFeedthrough.response_from('1 2 3')
    with pytest.raises(ValueError, match='six numbers'):
        PairFeedthrough.response_from('a b c d e f')
