import numpy as np
import pytest

from maglev_ros.hardware.scaling import CurrentScaling, ScalingError


def test_from_supply_is_4096_r_over_v():
    scaling = CurrentScaling.from_supply(supply_voltage=12.0, coil_resistance=4.0)
    assert scaling.counts_per_ampere == pytest.approx(4096 * 4.0 / 12.0)
    assert scaling.max_current == pytest.approx(3.0)  # V / R at full duty
    assert scaling.to_counts(1.5) == 2048  # half of the full-duty current


def test_clamps_to_full_scale():
    scaling = CurrentScaling(1000.0)
    np.testing.assert_array_equal(
        scaling.to_counts([-10.0, -4.0, 4.0, 10.0]), [-4096, -4000, 4000, 4096]
    )


def test_every_count_round_trips_through_current():
    scaling = CurrentScaling.from_supply(12.0, 3.3)
    counts = np.arange(-4096, 4097)
    np.testing.assert_array_equal(scaling.to_counts(scaling.to_current(counts)), counts)


def test_rounding_error_at_most_half_a_count():
    scaling = CurrentScaling(1234.5)
    amps = np.linspace(-3.3, 3.3, 10001)
    counts = scaling.to_counts(amps)
    assert np.abs(counts - amps * scaling.counts_per_ampere).max() <= 0.5


@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf])
def test_rejects_non_finite_current(value):
    with pytest.raises(ScalingError, match='current must be finite'):
        CurrentScaling(100.0).to_counts([0.0, value, 0.0, 0.0])


@pytest.mark.parametrize(
    'kwargs, match',
    [
        ({'supply_voltage': 0.0, 'coil_resistance': 4.0}, 'supply_voltage must be a positive'),
        ({'supply_voltage': 12.0, 'coil_resistance': -1.0}, 'coil_resistance must be a positive'),
        ({'supply_voltage': np.nan, 'coil_resistance': 4.0}, 'supply_voltage'),
    ],
)
def test_rejects_bad_supply(kwargs, match):
    with pytest.raises(ScalingError, match=match):
        CurrentScaling.from_supply(**kwargs)


def test_rejects_bad_counts_per_ampere():
    with pytest.raises(
        ScalingError, match='counts_per_ampere must be a positive finite number, got 0.0'
    ):
        CurrentScaling(0.0)


def test_v4x_full_scale_is_8_bit():
    from maglev_ros.hardware.scaling import V4X_PWM_FULL_SCALE

    scaling = CurrentScaling.from_supply(12.0, 4.0, full_scale=V4X_PWM_FULL_SCALE)
    assert scaling.counts_per_ampere == pytest.approx(85.0)  # 255 * 4 ohm / 12 V
    assert scaling.max_current == pytest.approx(3.0)
    assert scaling.to_counts([1.0, -3.0, 5.0, -0.0059]).tolist() == [85, -255, 255, -1]
    assert scaling.to_counts([0.0058]).tolist() == [0]  # 0.49 counts
    with pytest.raises(ScalingError, match='full_scale must be >= 1'):
        CurrentScaling(85.0, 0)
