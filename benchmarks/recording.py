"""Benchmark of the recording core: messages per second into a bag, against the bare writer.

The recorder node hands every message's CDR bytes to
:meth:`maglev_ros.bags.recording.Recording.write` (log time, window, counts,
write). This measures that call against the floor of the same bag written
with :meth:`maglev_ros.bags.BagWriter.write` directly (log times known), in
one run on the same messages: a 5 kHz sample of three fields, the currents and
a command (``log_clock: stamp``), first with an open window, then with a
window that ends (the held-command rules on). The ratio is the core's cost;
the absolute rate says how far a recorder process is from 5 kHz x 5 topics
(25 000 messages/s), before the middleware's own cost.

Run: ``python benchmarks/recording.py [--samples N] [--repeats R]`` (the best
of ``R`` runs of each; a shared machine adds noise to both alike).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from maglev_ros.bags import BagWriter
from maglev_ros.bags.recording import Recording
from maglev_ros.bags.typestore import jazzy_typestore

STORE = jazzy_typestore()
T = STORE.types
PERIOD_NS = 200_000
FIELDS = [f'/maglev/sensor_{k}/field' for k in range(3)]
CURRENTS, COMMAND = '/maglev/currents', '/maglev/currents/command'


def _header(t_ns: int):
    sec, nanosec = divmod(t_ns, 1_000_000_000)
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id='maglev'
    )


def _messages(n: int) -> list[tuple[str, int, bytes]]:
    """``(topic, stamp, bytes)`` of ``n`` samples: 3 fields, currents, a command each."""
    out = []
    for k in range(n):
        t = 1_000_000_000 + k * PERIOD_NS
        for topic in FIELDS:
            msg = T['sensor_msgs/msg/MagneticField'](
                header=_header(t),
                magnetic_field=T['geometry_msgs/msg/Vector3'](x=1e-3, y=2e-3, z=5e-2),
                magnetic_field_covariance=np.zeros(9),
            )
            out.append((topic, t, bytes(STORE.serialize_cdr(msg, msg.__msgtype__))))
        for topic in (CURRENTS, COMMAND):
            msg = T['sensor_msgs/msg/JointState'](
                header=_header(t),
                name=['x+', 'x-', 'y+', 'y-'],
                position=np.zeros(0),
                velocity=np.zeros(0),
                effort=np.array([0.1, -0.1, 0.2, -0.2]),
            )
            out.append((topic, t, bytes(STORE.serialize_cdr(msg, msg.__msgtype__))))
    return out


def _bare(path: Path, messages) -> float:
    with BagWriter(path) as writer:
        handles = {t: writer.add_topic(t, _type(t)) for t in [*FIELDS, CURRENTS, COMMAND]}
        start = time.perf_counter()
        for topic, stamp, data in messages:
            writer.write(handles[topic], stamp, data)
        return time.perf_counter() - start


def _type(topic: str) -> str:
    return 'sensor_msgs/msg/MagneticField' if 'field' in topic else 'sensor_msgs/msg/JointState'


def _core(path: Path, messages, end_ns: int | None) -> float:
    writer = BagWriter(path).open()
    recording = Recording(writer, 'stamp', time.time_ns, 0, end_ns)
    for topic in [*FIELDS, CURRENTS, COMMAND]:
        recording.add_topic(topic, _type(topic), stamped=True)
    write = recording.write
    start = time.perf_counter()
    for topic, _, data in messages:
        write(topic, data)
    elapsed = time.perf_counter() - start
    recording.close()
    return elapsed


def main() -> None:
    """Print messages/s of the bare writer and of the recording core, and their ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=10_000)
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    messages = _messages(args.samples)
    end = 1_000_000_000 + (args.samples - 10) * PERIOD_NS
    best = {'bare writer': np.inf, 'core, open window': np.inf, 'core, window with end': np.inf}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            best['bare writer'] = min(best['bare writer'], _bare(Path(tmp) / f'a{r}', messages))
            t = _core(Path(tmp) / f'b{r}', messages, None)
            best['core, open window'] = min(best['core, open window'], t)
            t = _core(Path(tmp) / f'c{r}', messages, end)
            best['core, window with end'] = min(best['core, window with end'], t)
    n = len(messages)
    floor = best['bare writer']
    print(f'{n} messages ({args.samples} samples x 5 topics), best of {args.repeats}')
    for name, seconds in best.items():
        print(
            f'  {name:<22} {n / seconds:>10,.0f} messages/s   {seconds / floor:5.2f} x the writer'
        )


if __name__ == '__main__':
    main()
