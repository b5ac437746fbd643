"""Coil current <-> PWM counts (V2x: 12-bit, V4x PC control: 8-bit).

Each board applies a signed PWM duty to an H-bridge across each coil. In the
quasi-static (resistive) limit the coil current is

    I = duty * V_supply / R_coil,   duty = counts / full_scale,

so ``counts = round(full_scale * I * R_coil / V_supply)``, clamped to
+-``full_scale``: 4096 for the V2x firmware (12-bit PWM), 255 for the V4x
PC-control firmware (8-bit PWM in slow decay: pin 1 at ``255 - |p|``, pin 2
high, so the bridge drives for ``|p| / 255`` of each period and brakes for
the rest). The same relation can be given directly as counts per ampere
(from a calibration with the shunt or a clamp meter). The coil inductance
only delays the current (time constant L / R); the scaling describes the
steady state. The largest current a scaling can ask for is its full scale,
``full_scale / counts_per_ampere`` (3 A at 12 V and 4 ohm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .packet import PWM_FULL_SCALE

__all__ = [
    'BOARD_COIL_RESISTANCE',
    'BOARD_SUPPLY_VOLTAGE',
    'V4X_PWM_FULL_SCALE',
    'CurrentScaling',
    'ScalingError',
]

#: V, the board's H-bridge rail: 12 V over USB-C power delivery (docs/maggy-model.md,
#: hardware limits; 9 V if the charger cannot give 12 V).
BOARD_SUPPLY_VOLTAGE = 12.0
#: ohm, the driver's default coil resistance: the hardware description's "about
#: 4 ohm", wiring and bridge included, because the PWM scaling needs the whole
#: circuit's resistance. The physics parameter sets (config/maggy_v*.yaml) use 3 ohm
#: as an order-of-magnitude L/R model, not a measurement; for a real board measure
#: the current (shunt, clamp meter) and set ``coil_resistance`` or ``counts_per_ampere``.
BOARD_COIL_RESISTANCE = 4.0
#: counts: the V4x PC-control firmware's largest |PWM| (8-bit ``analogWrite``).
V4X_PWM_FULL_SCALE = 255


class ScalingError(ValueError):
    """Invalid scaling parameter or current value."""


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ScalingError(f'{name} must be a positive finite number, got {value!r}')
    return value


@dataclass(frozen=True)
class CurrentScaling:
    """Linear map between coil current (A) and PWM counts.

    Parameters
    ----------
    counts_per_ampere : float
        PWM counts per ampere of steady-state coil current (> 0); equals
        ``full_scale * R_coil / V_supply`` for a resistive coil.
    full_scale : int, optional
        Counts at full duty: 4096 (V2x, default) or 255 (V4x PC control).
    """

    counts_per_ampere: float
    full_scale: int = PWM_FULL_SCALE

    def __post_init__(self) -> None:
        _positive('counts_per_ampere', self.counts_per_ampere)
        if isinstance(self.full_scale, bool) or not isinstance(self.full_scale, int):
            raise ScalingError(f'full_scale must be an int, got {self.full_scale!r}')
        if self.full_scale < 1:
            raise ScalingError(f'full_scale must be >= 1 count, got {self.full_scale}')

    @classmethod
    def from_supply(
        cls, supply_voltage: float, coil_resistance: float, full_scale: int = PWM_FULL_SCALE
    ) -> CurrentScaling:
        """Build the scaling from the H-bridge supply and the coil resistance.

        Parameters
        ----------
        supply_voltage : float
            H-bridge supply voltage in volt (> 0).
        coil_resistance : float
            Coil resistance in ohm, wiring and bridge included (> 0).
        full_scale : int, optional
            Counts at full duty (4096: V2x; 255: V4x PC control).

        Returns
        -------
        CurrentScaling
            ``counts_per_ampere = full_scale * coil_resistance / supply_voltage``.
        """
        volts = _positive('supply_voltage', supply_voltage)
        ohms = _positive('coil_resistance', coil_resistance)
        return cls(full_scale * ohms / volts, full_scale)

    @property
    def max_current(self) -> float:
        """Current at full duty, in ampere (``full_scale`` counts)."""
        return self.full_scale / self.counts_per_ampere

    def to_counts(self, current: ArrayLike) -> NDArray[np.int64]:
        """Convert coil currents to PWM counts.

        Parameters
        ----------
        current : array_like of float, any shape
            Coil currents in ampere; must be finite.

        Returns
        -------
        ndarray of int64, same shape
            ``rint(counts_per_ampere * current)`` (round half to even),
            clamped to -full_scale .. full_scale.

        Raises
        ------
        ScalingError
            If a current is NaN or infinite.
        """
        amps = np.asarray(current, dtype=float)
        if not np.all(np.isfinite(amps)):
            raise ScalingError(f'current must be finite, got {amps.tolist()}')
        counts = np.rint(amps * self.counts_per_ampere)
        return np.clip(counts, -self.full_scale, self.full_scale).astype(np.int64)

    def to_current(
        self, counts: ArrayLike, out: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Convert PWM counts to the steady-state coil currents they imply.

        Parameters
        ----------
        counts : array_like of int, any shape
            PWM counts.
        out : ndarray of float64, same shape, optional
            Where to write the result.

        Returns
        -------
        ndarray of float64, same shape
            Currents in ampere (``out`` if given).
        """
        return np.divide(counts, self.counts_per_ampere, out=out, dtype=np.float64)
