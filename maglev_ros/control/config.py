"""Settings of the levitation controller (a frozen dataclass built from YAML or ROS parameters)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from ..parameters import NodeParameterError, check_settings, choice, integer, number, setting

__all__ = [
    'MAX_COMMAND_DELAY',
    'MODES',
    'ControllerConfig',
    'ControllerConfigError',
    'load_controller_config',
]

#: ``lqr``: state feedback on the estimate; ``pd``: the firmware's PD on the raw field.
MODES = ('lqr', 'pd')
MAX_COMMAND_DELAY = 20  # samples of command delay the LQR design takes as states


class ControllerConfigError(ValueError):
    """A controller setting is unknown or out of range."""


def _command_delay(name: str, value: int) -> int:
    if isinstance(value, bool) or value not in range(MAX_COMMAND_DELAY + 1):
        raise NodeParameterError(
            f'{name} must be an integer from 0 to {MAX_COMMAND_DELAY}, got {value!r}'
        )
    return value


_command_delay.rule = f'0 .. {MAX_COMMAND_DELAY}'


@dataclass(frozen=True)
class ControllerConfig:
    """Controller settings, SI units. Defaults: ``config/controller.yaml`` documents them.

    LQR weights follow Bryson's rule: each ``*_scale`` is the deviation that
    costs as much as ``current_scale`` of coil current, so the weight of a
    state is ``1 / scale^2``.

    Attributes
    ----------
    mode : {'lqr', 'pd'}
    sample_rate : float
        Control rate, Hz (one command per sample).
    command_delay : int
        Samples before a command takes effect (0 to ``MAX_COMMAND_DELAY``): 1
        on the board (the command computed from sample k drives the coils
        from k+1); more for a loop through separate processes, whose
        commands arrive milliseconds late. The LQR design includes the
        pending commands as states.
    sensor_delay : int
        Samples of reading delay (0 or 1): the PD removes the coils' direct
        field with the currents of the reading's instant. (The LQR gets an
        estimate the estimator already predicted to the sample.)
    coil_dynamics : bool
        Model the coil current's first-order lag (L / R of the parameter set)
        in the LQR design (the coil currents become states).
    current_limit : float
        Largest command per coil, A (default 1.0: the drivers limit each
        solenoid to about 1.1 A and V4 senses about +-1.1 A).
    position_scale, angle_scale, velocity_scale, rate_scale : float
        Bryson scales of x, y, z (m), alpha, beta (rad), vx, vy, vz (m/s),
        wx, wy (rad/s).
    current_scale : float
        Bryson scale of the commands, A.
    integral : bool
        Integral action on x, y, z (for model mismatch), with anti-windup
        (the integrators hold while any coil is at the limit).
    integral_scale : float
        Bryson scale of the integrated position error, m s.
    input_timeout : float
        No estimate (LQR) or sample (PD) for this long: zero currents and an
        ERROR status, s.
    rearm_samples : int
        After a timeout the controller re-arms by itself once this many fresh
        inputs arrived in a row (integrators and pending command cleared).
    loss_distance : float
        LQR: an estimate farther than this from the equilibrium means the
        magnet is lost (no recovery from there: the largest recovered offset is
        0.6-0.8 mm): zero currents and an ERROR, latched until the controller
        is enabled again (or reset), m.
    pd_kp : float
        PD proportional gain, A per T of horizontal field.
    pd_kd : float
        PD derivative gain, A per (T/s).
    pd_cutoff : float
        Cut-off of the first-order filter on the field and its derivative, Hz.
    pd_sensor : int
        Sensor whose Bx, By the PD uses (0: the one under the magnet).
    pd_feedthrough : bool
        Remove the coils' direct field (the model's D times the measured
        currents) from the reading before the PD, as the board does.
    magnet_threshold : float
        PD active only while that sensor's |Bz - Bz without magnet| exceeds
        this, T (the firmware's magnet-present test).
    """

    mode: str = setting(
        'lqr',
        'lqr (state feedback on the estimate) or pd (firmware PD on the field)',
        choice(*MODES),
    )
    sample_rate: float = setting(
        5000.0, 'control rate, Hz (one command per sample)', number(0, above=True)
    )
    command_delay: int = setting(
        1,
        f'samples before a command drives the coils (0 to {MAX_COMMAND_DELAY}; 1: the board; '
        'the LQR designs for it)',
        _command_delay,
    )
    sensor_delay: int = setting(1, 'samples of reading delay (0 or 1)', integer(0, 1))
    coil_dynamics: bool = setting(True, "LQR models the coils' L/R lag")
    current_limit: float = setting(1.0, 'largest command per coil, A', number(0, above=True))
    position_scale: float = setting(1.0e-4, 'Bryson scale of x y z, m', number(0, above=True))
    angle_scale: float = setting(0.003, 'Bryson scale of alpha beta, rad', number(0, above=True))
    velocity_scale: float = setting(
        0.02, 'Bryson scale of the velocity, m/s', number(0, above=True)
    )
    rate_scale: float = setting(0.5, 'Bryson scale of wx wy, rad/s', number(0, above=True))
    current_scale: float = setting(1.0, 'Bryson scale of the commands, A', number(0, above=True))
    integral: bool = setting(False, 'integral action on x y z (anti-windup at the limit)')
    integral_scale: float = setting(
        2.0e-5, 'Bryson scale of the integrated error, m s', number(0, above=True)
    )
    input_timeout: float = setting(
        0.005, 's without input -> zero currents, ERROR', number(0, above=True)
    )
    rearm_samples: int = setting(
        10, 'fresh inputs in a row that re-arm after a timeout', integer(1)
    )
    loss_distance: float = setting(
        3.0e-3,
        'LQR: estimate this far from the equilibrium = magnet lost: zero currents, '
        'ERROR, latched until enabled again, m',
        number(0, above=True),
    )
    pd_kp: float = setting(15000.0, 'PD proportional gain, A/T', number(0))
    pd_kd: float = setting(250.0, 'PD derivative gain, A/(T/s)', number(0))
    pd_cutoff: float = setting(30.0, 'PD field filter cut-off, Hz', number(0, above=True))
    pd_sensor: int = setting(0, 'sensor the PD reads', integer(0))
    pd_feedthrough: bool = setting(True, "PD removes the coils' direct field")
    magnet_threshold: float = setting(
        2.0e-3, 'PD active while |Bz - Bz without magnet| exceeds it, T', number(0)
    )

    def __post_init__(self):
        check_settings(self, ControllerConfigError)
        if self.pd_cutoff >= self.sample_rate / 2:
            raise ControllerConfigError(
                f'pd_cutoff must be below the Nyquist frequency {self.sample_rate / 2} Hz, '
                f'got {self.pd_cutoff!r}'
            )

    @property
    def dt(self) -> float:
        """Control period, s."""
        return 1.0 / self.sample_rate

    @classmethod
    def from_mapping(cls, values: dict) -> ControllerConfig:
        """Build from a mapping (YAML or ROS parameters), naming unknown keys.

        Integers are accepted where floats are expected (YAML ``1`` for 1.0).

        Parameters
        ----------
        values : dict
            Setting name to value.

        Raises
        ------
        ControllerConfigError
            On an unknown key or a bad value.
        """
        known = {f.name: f for f in fields(cls)}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ControllerConfigError(
                f'unknown controller setting(s) {", ".join(unknown)}; '
                f'known: {", ".join(sorted(known))}'
            )
        converted = {}
        for key, value in values.items():
            default = known[key].default
            if (
                isinstance(default, float)
                and isinstance(value, int)
                and not isinstance(value, bool)
            ):
                value = float(value)
            converted[key] = value
        return cls(**converted)


def load_controller_config(path: str | Path, **overrides) -> ControllerConfig:
    """Read a controller YAML file (a flat mapping, or under ``controller:``).

    Parameters
    ----------
    path : str or Path
        The file.
    **overrides
        Settings that replace the file's.

    Raises
    ------
    ControllerConfigError
        When the file is missing, not a mapping, or has a bad setting (the
        message names the file).
    """
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ControllerConfigError(f'{p}: cannot read controller settings: {exc}') from None
    if isinstance(data, dict) and 'controller' in data:
        data = data['controller']
    if not isinstance(data, dict):
        raise ControllerConfigError(f'{p}: expected a mapping of controller settings')
    data = {**data, **overrides}
    try:
        return ControllerConfig.from_mapping(data)
    except ControllerConfigError as exc:
        raise ControllerConfigError(f'{p}: {exc}') from None
