"""The closed-loop lab's loop, plan and observers, built from plain settings (ROS-free).

What ``maglev-lab`` runs (and a node hosting the lab session can run): the
believed model's estimator (``filter``) and LQR with the command excitation,
on one of three plants:

* **lockstep** (default): the simulator stepped once per command
  (:class:`~maglev_ros.loop.SimulatedPlant`), the LQR at the sample rate and
  the command written one sample late (the board's one sample of command
  latency, which the LQR is designed for): exact and deterministic;
* **real time** (``realtime``): the simulator paced by the wall clock
  (:class:`~maglev_ros.loop.PacedSimulatedPlant`), one estimate and command
  per burst of ``sample_rate / control_rate`` samples; the LQR at the control
  rate, designed for one period of latency (a command drives the coils from
  the next burst); a loop that falls behind the clock gets one burst a read
  all the same (the simulation slows down, the overruns are counted), so a
  recording has one command every burst;
* **a board** (:class:`~maglev_ros.loop.BoardPlant`, the plant given): the
  board's stream paces the loop at the control rate; the LQR designed for
  :data:`BOARD_COMMAND_DELAY` periods (the period, the read and the link).

The session (:func:`~maglev_ros.loop.run_session`) then settles for
``settle`` s, excites from then on and records exactly ``samples`` samples
into the bag (:class:`~maglev_ros.loop.BagRecorder`) and the online
identifier (:class:`~maglev_ros.loop.OnlineIdentifier`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..control.excitation import CommandExcitation, ExcitationSchedule
from .control_loop import ControlLoop
from .session import SessionPlan

__all__ = [
    'BOARD_COMMAND_DELAY',
    'BOARD_SETTLED_RMS_M',
    'SETTLE_SHARE',
    'SETTLE_WINDOW_S',
    'SETTLED_RMS_M',
    'LabSettings',
    'build_lab_loop',
    'lab_excitation',
    'lab_plan',
    'loop_metadata',
    'settle_window',
    'simulator_metadata',
]

SETTLE_WINDOW_S = 0.1  # s: the settling check's shortest RMS window
#: Share of the levitation before the record over which the settling check's RMS runs
#: (at least SETTLE_WINDOW_S): the noise-driven motion (about 50 um RMS, time constant
#: 20-35 ms) has a few independent values in 0.1 s, whose RMS reached 0.1 mm in 2 of
#: 10 seeds of a magnet held for 1 s
SETTLE_SHARE = 0.5
SETTLED_RMS_M = 1e-4  # m: settled (true state) below this RMS on every axis
#: On a board, of the estimate: a 0.1 mT-noise estimate wanders ~50 um rms by itself.
BOARD_SETTLED_RMS_M = 2e-4
#: Control periods between an estimate and its command's effect on a board: the
#: period itself, and about 1 ms for the read, the link's round trip and the board's
#: next sample (1 period at 1 kHz loses a virtual board's magnet within 2 s).
BOARD_COMMAND_DELAY = 2
REALTIME_INPUT_TIMEOUT_S = 0.02  # s without an estimate before the LQR zeroes the coils
#: On a board: a stall of the loop's thread holds the last command meanwhile; zeroing
#: after a short one loses a magnet the loop would have caught again.
BOARD_INPUT_TIMEOUT_S = 0.1


@dataclass(frozen=True)
class LabSettings:
    """What the closed-loop lab runs.

    Attributes
    ----------
    params : str
        Parameter set (plant, estimator and controller).
    samples : int
        Samples to record after settling.
    settle : float
        s of plant time before the recording.
    sample_rate : float
        Hz.
    noise, quantization : float
        Sensor noise (T rms) and resolution (T per LSB).
    sensor_delay : int
        Samples.
    coil_dynamics : bool
        Coil L/R electrics (plant and LQR).
    field_model : str
        The simulator's field model.
    seed : int
        Seed of the sensor noise.
    sensors : tuple of int
        Sensors whose fields are recorded.
    storage : str
        ``mcap`` or ``sqlite3``.
    filter : str
        The estimator's filter.
    excitation : CommandExcitation
        Added to the commands from the settling's end (its ``start`` is not used).
    identifier_orders : tuple
        ``(na, nb, nk)`` of the online identifier, ny*ny and ny*nu values row
        by row (default: x 7 9 1 and y 6 6 1, decoupled).
    initial_covariance : float
        The identifier's ``P0 = p0 I`` (fields in T: large).
    realtime : bool
        The simulator paced by the wall clock.
    control_rate : float
        Real time and boards: estimates and commands per second, Hz (divides
        ``sample_rate``).
    mode : str
        ``lqr`` (with the estimator) or ``pd`` (the firmware's PD on the raw
        fields, no estimator).
    bias_states : bool
        The estimator estimates a field offset per sensor axis (a static
        field error, such as a magnet other than the believed one, is then
        not taken for a tilt).
    plant_polarization, plant_mass : float
        The simulated magnet's polarisation and mass as factors of the
        believed set's (1: no model mismatch).
    command_delay : int or None
        Control periods a command waits in the loop, and the LQR's design for
        them (None: the plant's own latency: one sample in lockstep, one
        period in real time, the board's).
    skip_ahead : bool
        Real time: a loop far behind the clock skips ahead (counted as
        overruns) instead of taking one burst a read (the lab: no gaps in a
        recording).
    """

    params: str = 'maggy_v2'
    samples: int = 25000
    settle: float = 1.0
    sample_rate: float = 5000.0
    noise: float = 1e-4
    quantization: float = 0.098e-3
    sensor_delay: int = 1
    coil_dynamics: bool = True
    field_model: str = 'fast'
    seed: int = 0
    sensors: tuple[int, ...] = (0,)
    storage: str = 'mcap'
    filter: str = 'kf'
    excitation: CommandExcitation = field(
        default_factory=lambda: CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs')
    )
    identifier_orders: tuple = ((7, 0, 0, 6), (9, 0, 0, 6), (1, 1, 1, 1))
    initial_covariance: float = 1e10
    realtime: bool = False
    control_rate: float = 1000.0
    mode: str = 'lqr'
    bias_states: bool = False
    plant_polarization: float = 1.0
    plant_mass: float = 1.0
    command_delay: int | None = None
    skip_ahead: bool = False

    @property
    def burst(self) -> int:
        """Samples per control period in real time (1 in lockstep)."""
        return max(1, int(round(self.sample_rate / self.control_rate))) if self.realtime else 1

    @property
    def control_excitation(self) -> CommandExcitation:
        """The excitation in the controller's samples (real time: at ``control_rate``).

        Its band (fractions of Nyquist) and length (samples) are given at
        ``sample_rate``; at the control rate the same frequencies are a
        ``sample_rate / control_rate`` times larger fraction (at most 1).
        """
        e = self.excitation
        if not self.realtime:
            return replace(e, start=0.0)
        ratio = self.sample_rate / self.control_rate
        band = (min(e.band[0] * ratio, 1.0), min(e.band[1] * ratio, 1.0))
        return replace(e, band=band, length=max(1, int(round(e.length / ratio))), start=0.0)

    @property
    def settle_samples(self) -> int:
        """Ordinal of the last sample before the recording (the settling's samples)."""
        return max(1, int(round(self.settle * self.sample_rate)))


def lab_excitation(s: LabSettings) -> np.ndarray:
    """Return the excitation of each sample from the settling's end on, shape (M, 4), A.

    Lockstep: one value a sample. Real time: one value a control period, held
    over its ``burst`` samples (the loop adds the row of the newest sample of
    each read).

    Parameters
    ----------
    s : LabSettings
    """
    e = s.control_excitation
    burst = s.burst
    periods = -(-(s.samples + 1) // burst) + 1
    values = ExcitationSchedule(e, s.sample_rate / burst).sequence(periods)
    return np.repeat(values, burst, axis=0)


def settle_window(s: LabSettings) -> int:
    """Return the settling check's RMS window, samples: the levitation's last half, >= 0.1 s.

    Parameters
    ----------
    s : LabSettings
    """
    seconds = max(SETTLE_WINDOW_S, SETTLE_SHARE * s.settle_samples / s.sample_rate)
    return max(1, int(round(seconds * s.sample_rate)))


def lab_plan(s: LabSettings, board: bool = False) -> SessionPlan:
    """Return the lab's session: settle, excite, record ``samples``.

    Parameters
    ----------
    s : LabSettings
    board : bool
        Settling judged on the estimate (no true state), with its looser bound.
    """
    from ..physics import make_model
    from ..physics.equilibria import find_equilibria

    z_eq = find_equilibria(make_model(s.params))[0].z
    return SessionPlan(
        samples=s.samples,
        settle_samples=s.settle_samples,
        settle_window=settle_window(s),
        set_point=np.array([0.0, 0.0, z_eq]),
        settled_rms=BOARD_SETTLED_RMS_M if board else SETTLED_RMS_M,
        position='estimate' if board else 'state',
        excitation=lab_excitation(s),
    )


def build_lab_loop(s: LabSettings, plant=None, observers=(), **timing) -> ControlLoop:
    """Build the lab's loop: estimator, LQR and plant (see the module docstring).

    Parameters
    ----------
    s : LabSettings
    plant : Plant, optional
        A board (:class:`~maglev_ros.loop.BoardPlant`); default the simulator
        of the settings, lockstep or paced (``realtime``).
    observers : iterable
        The loop's observers (:class:`~maglev_ros.loop.ControlLoop`).
    **timing
        ``clock``, ``sleep`` of a paced simulator (default the wall clock).

    Returns
    -------
    ControlLoop
        Reset; warmed up (its kernels loaded) unless lockstep.

    Raises
    ------
    ValueError
        If the control rate does not divide the sample rate, or a board's
        sensors are not the set's.
    """
    from ..control import ControllerConfig, make_controller
    from ..estimation import EstimatorConfig, make_estimator
    from ..physics import CoilDynamics, SensorEffects, Simulator, linearize, make_model
    from .paced import PacedSimulatedPlant
    from .simulated import SimulatedPlant

    ratio = s.sample_rate / s.control_rate
    if (s.realtime or plant is not None) and (ratio < 1 or abs(ratio - round(ratio)) > 1e-9):
        raise ValueError(
            f'control_rate must divide sample_rate ({s.sample_rate:g} Hz), '
            f'got {s.control_rate:g} Hz'
        )
    model = make_model(s.params)
    linear = linearize(model)
    if plant is None:
        plant_model = _plant_model(s, model)
        simulator = Simulator(
            plant_model,
            s.sample_rate,
            coil=CoilDynamics.from_parameters(plant_model.params) if s.coil_dynamics else None,
            sensor=SensorEffects(
                noise_rms=s.noise, quantization=s.quantization, delay_samples=s.sensor_delay
            ),
            seed=s.seed,
            magnet='free',
        )
        if s.realtime:  # behind the clock it slows down, one burst a command: no gaps
            plant = PacedSimulatedPlant(
                simulator, s.burst, max_burst=None if s.skip_ahead else s.burst, **timing
            )
        else:
            plant = SimulatedPlant(simulator)
    elif getattr(plant, 'n_sensors', None) not in (None, model.n_outputs // 3):
        raise ValueError(
            f'the board sends {plant.n_sensors} sensors a record, {s.params} has '
            f'{model.n_outputs // 3}: choose the parameter set of this board'
        )
    board = not isinstance(plant, (SimulatedPlant, PacedSimulatedPlant))
    lockstep = not (s.realtime or board)
    if lockstep:  # one command a sample, written one sample late (the board's latency)
        control = dict(sample_rate=s.sample_rate, command_delay=1)
    elif board:
        control = dict(
            sample_rate=s.control_rate,
            command_delay=BOARD_COMMAND_DELAY,
            input_timeout=BOARD_INPUT_TIMEOUT_S,
        )
    else:
        control = dict(
            sample_rate=s.control_rate, command_delay=1, input_timeout=REALTIME_INPUT_TIMEOUT_S
        )
    loop_delay = 1 if lockstep else 0
    if s.command_delay is not None:  # designed for and applied in the loop
        control['command_delay'] = loop_delay = s.command_delay
    controller = make_controller(
        model,
        ControllerConfig(mode=s.mode, coil_dynamics=s.coil_dynamics, **control),
        linear=linear,
    )
    estimator = None
    if s.mode == 'lqr':
        estimator = make_estimator(
            model,
            EstimatorConfig(
                filter=s.filter,
                sample_rate=s.sample_rate,
                sensor_delay=s.sensor_delay,
                sensor_noise=max(s.noise, 1e-6),
                quantization=s.quantization,
                bias_states=s.bias_states,
            ),
            linear=linear,
        )
    loop = ControlLoop(plant, controller, estimator, loop_delay, observers=observers)
    if board:  # the kernels load now, not in the first control period
        _warm_up(loop, Simulator(model, s.sample_rate).reset())
    elif not lockstep:
        loop.warm_up()
    return loop


def _plant_model(s: LabSettings, model):
    """Return the simulated plant's model: the believed set, its magnet scaled."""
    import dataclasses

    from ..physics import make_model

    if s.plant_polarization == 1.0 and s.plant_mass == 1.0:
        return make_model(s.params, field=s.field_model)
    p = model.params
    magnet = dataclasses.replace(
        p.magnet,
        polarization=p.magnet.polarization * s.plant_polarization,
        mass=p.magnet.mass * s.plant_mass,
    )
    params = p.replace(magnet=magnet, solenoid_radius_correction=model.correction)
    return make_model(params, field=s.field_model)


def _warm_up(loop: ControlLoop, reading: np.ndarray) -> None:
    """Call the estimator and the controller once on ``reading``, then reset the loop."""
    from ..physics.kernels import odometry_round_trip

    zero = np.zeros(loop.plant.n_inputs)
    if loop.estimator is None:  # the PD reads the fields
        loop.controller.command(0.0, reading, zero)
    else:
        x_hat = loop.estimator.step(reading, zero)
        loop.controller.command(0.0, odometry_round_trip(x_hat), zero)
    loop.reset()


def simulator_metadata(s: LabSettings, prefix: str = 'maglev_simulator') -> dict[str, object]:
    """Return the simulated plant's settings as flat bag metadata (``<prefix>.<name>``).

    Parameters
    ----------
    s : LabSettings
    prefix : str
        Key prefix (the simulator node's name, which bag readers know).
    """
    items = {
        'params': s.params,
        'field_model': s.field_model,
        'magnet': 'free',
        'sample_rate': s.sample_rate,
        'coil_dynamics': s.coil_dynamics,
        'sensor_delay': s.sensor_delay,
        'sensor_noise': s.noise,
        'sensor_quantization': s.quantization,
        'seed': s.seed,
        'mode': 'realtime' if s.realtime else 'lockstep',
        'sensors': ' '.join(str(k) for k in s.sensors),
    }
    return {f'{prefix}.{k}': v for k, v in items.items()}


def loop_metadata(s: LabSettings, loop: ControlLoop) -> dict[str, object]:
    """Return the estimator's, controller's and excitation's settings as bag metadata.

    Parameters
    ----------
    s : LabSettings
    loop : ControlLoop
        The lab's loop.
    """
    c = loop.controller.config
    e = s.excitation
    return {
        'maglev_estimator.filter': s.filter,
        'maglev_estimator.sample_rate': s.sample_rate,
        'maglev_controller.mode': c.mode,
        'maglev_controller.sample_rate': c.sample_rate,
        'maglev_controller.command_delay': c.command_delay,
        'maglev_controller.current_limit': c.current_limit,
        'maglev_controller.excitation_signal': e.signal,
        'maglev_controller.excitation_amplitude': e.amplitude,
        'maglev_controller.excitation_band': f'{e.band[0]:g} {e.band[1]:g}',
        'maglev_controller.excitation_pattern': e.pattern,
        'maglev_controller.excitation_seed': e.seed,
        'maglev_controller.excitation_length': e.length,
        'loop.command_delay': loop.command_delay,
    }
