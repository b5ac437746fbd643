"""What the board driver reports on ``/diagnostics``, ROS-free: counters, rates, state."""

from __future__ import annotations

from ..health import ERROR, OK, WARN, Health
from .board_link import BoardLink
from .command_guard import CommandGuard
from .v4x_pc_poller import V4xPcPoller

__all__ = ['COUNTERS', 'FIELD_KINDS', 'RESYNC_WARN_PER_S', 'DriverHealth', 'driver_counters']

#: resynchronisations per second above which the link is reported WARN: a healthy
#: link has none; at this rate (one damaged spot every 100 ms) the V2x decoder
#: drops well under 1 % of the records, but the cable, hub or noise needs a look.
RESYNC_WARN_PER_S = 10.0

#: What each firmware's field messages hold (the driver states it at start and in
#: /diagnostics): V2x the raw sensor field the model predicts, V4x the board's processed one.
FIELD_KINDS = {
    'v2x': 'raw',
    'v4x': 'baseline and feedthrough removed (V4x)',
    'v4x_pc': (
        'processed, in T: baseline and coil feedthrough removed, x and y low-pass filtered '
        '(V4x PC control)'
    ),
}

COUNTERS = (  # as /diagnostics lists them
    'records',
    'commands_sent',
    'commands_rejected',
    'commands_clamped',
    'commands_unsent',
    'commands_ignored',
    'timeouts',
    'reconnects',
    'io_errors',
    'info_messages',
    'resyncs',
    'dropped_bytes',
)


def driver_counters(link: BoardLink | V4xPcPoller, guard: CommandGuard) -> dict[str, int]:
    """Every driver counter by name, in ``COUNTERS`` order.

    Parameters
    ----------
    link : BoardLink or V4xPcPoller
        Records, packets sent and unsent, link events.
    guard : CommandGuard
        Commands rejected, clamped, ignored; timeouts.

    Returns
    -------
    dict of str to int
        The link's, the guard's and the stream's counters (resyncs, dropped bytes).
    """
    merged = link.counts | guard.counters
    merged['resyncs'], merged['dropped_bytes'] = link.resyncs, link.dropped_bytes
    return {name: merged[name] for name in COUNTERS}


class DriverHealth:
    """The driver's ``/diagnostics`` status, with rates over the interval between reports.

    Parameters
    ----------
    firmware : str
        ``'v2x'``, ``'v4x'`` or ``'v4x_pc'`` (``FIELD_KINDS``: what the fields are).
    now : float
        Monotonic time, s: the start of the first rate interval.
    """

    def __init__(self, firmware: str, now: float) -> None:
        self.firmware = firmware
        self._mark = (now, 0, 0, 0, 0)

    def report(self, link: BoardLink | V4xPcPoller, guard: CommandGuard, now: float) -> Health:
        """Link state, rates and counters since the previous report.

        Parameters
        ----------
        link : BoardLink or V4xPcPoller
            The board link.
        guard : CommandGuard
            The command guard.
        now : float
            Monotonic time, s.

        Returns
        -------
        Health
            ERROR while the link is not connected; WARN during a command
            timeout (zero currents) or above ``RESYNC_WARN_PER_S``
            resynchronisations per second; else OK.
        """
        counters = driver_counters(link, guard)
        then, records, sent, resyncs, dropped = self._mark
        span = max(now - then, 1e-9)
        self._mark = (
            now,
            counters['records'],
            counters['commands_sent'],
            counters['resyncs'],
            counters['dropped_bytes'],
        )
        resync_rate = (counters['resyncs'] - resyncs) / span
        drop_rate = (counters['dropped_bytes'] - dropped) / span
        if link.state != 'connected':
            level, message = ERROR, f'board link {link.state}'
        elif guard.timed_out:
            level, message = WARN, 'command timeout: zero currents'
        elif resync_rate > RESYNC_WARN_PER_S:
            level, message = (
                WARN,
                (
                    f'corrupted link: {resync_rate:.0f} resyncs/s, '
                    f'{drop_rate:.0f} bytes/s dropped (damaged records are dropped, '
                    'not published); check the USB cable and hub'
                ),
            )
        else:
            level, message = OK, 'connected'
        values = {
            'link state': link.state,
            'firmware': self.firmware,
            'field kind': FIELD_KINDS[self.firmware],
            'enabled': str(guard.enabled),
            'records/s': f'{(counters["records"] - records) / span:.1f}',
            'command rate (1/s)': f'{(counters["commands_sent"] - sent) / span:.1f}',
            'resyncs/s': f'{resync_rate:.1f}',
            'dropped bytes/s': f'{drop_rate:.1f}',
            'applied PWM (counts)': ' '.join(str(int(c)) for c in link.applied),
            'last board message': link.last_info,
        }
        values.update({name.replace('_', ' '): str(v) for name, v in counters.items()})
        values.update(link.health_values())
        return Health(level, message, values)
