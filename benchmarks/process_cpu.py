"""Processes of a real-time benchmark: start them in their own sessions, stop them, their CPU.

Shared by ``closed_loop_realtime.py`` and ``closed_loop.py`` (run as
scripts: ``benchmarks/`` is then on ``sys.path``). CPU times come from
``/proc/<pid>/stat`` (user + system, clock ticks) and, per thread, from
``/proc/<pid>/task/<tid>/stat``; ``psutil`` lists a process's descendants.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
from pathlib import Path

__all__ = [
    'Processes',
    'benchmark_environment',
    'cpu_seconds',
    'process_names',
    'thread_cpu_seconds',
]

_TICK = os.sysconf('SC_CLK_TCK')


def benchmark_environment(domain: int) -> dict[str, str]:
    """Return the environment of a benchmark's processes, and set its ROS part here too.

    Parameters
    ----------
    domain : int
        ``ROS_DOMAIN_ID`` of the run (discovery stays on localhost).
    """
    env = os.environ | {
        'ROS_DOMAIN_ID': str(domain),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'PYTHONUNBUFFERED': '1',
        'RCUTILS_COLORIZED_OUTPUT': '0',
    }
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    return env


def _stat_cpu(path: Path) -> float:
    try:
        fields = path.read_text().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / _TICK


def cpu_seconds(pid: int) -> float:
    """Return the CPU time (user + system) of a process, s (0 once it is gone).

    Parameters
    ----------
    pid : int
        Process id.
    """
    return _stat_cpu(Path(f'/proc/{pid}/stat'))


def thread_cpu_seconds(pid: int) -> dict[str, float]:
    """Return the CPU time of each thread of a process, s, summed per thread name.

    Parameters
    ----------
    pid : int
        Process id.
    """
    out: dict[str, float] = {}
    try:
        tasks = list(Path(f'/proc/{pid}/task').iterdir())
    except OSError:
        return out
    for task in tasks:
        try:
            name = (task / 'comm').read_text().strip()
        except OSError:
            continue
        out[name] = out.get(name, 0.0) + _stat_cpu(task / 'stat')
    return out


def process_names(root: int) -> dict[int, str]:
    """Return ``root`` and its descendants: pid -> short name.

    The name is the node name of a ``__node:=`` remapping, else the word after
    ``--child`` (a benchmark's child), else the module of ``python -m MODULE``,
    else the first three words of the command line.

    Parameters
    ----------
    root : int
        Process id.
    """
    import psutil

    out = {}
    try:
        procs = [psutil.Process(root), *psutil.Process(root).children(recursive=True)]
    except psutil.NoSuchProcess:
        return out
    for p in procs:
        try:
            cmd = p.cmdline()
        except psutil.Error:
            continue
        name = next((a.split(':=')[1] for a in cmd if a.startswith('__node:=')), None)
        if name is None and '--child' in cmd[:-1]:
            name = cmd[cmd.index('--child') + 1]
        if name is None and '-m' in cmd[:-1]:
            name = cmd[cmd.index('-m') + 1].rsplit('.', 1)[-1]
        out[p.pid] = name or ' '.join(Path(a).name for a in cmd[:3])
    return out


class Processes:
    """Commands started each in its own session, their output kept, stopped with SIGINT.

    Parameters
    ----------
    commands : sequence of list of str
        The argv of each process.
    env : dict
        Their environment.
    """

    def __init__(self, commands, env: dict) -> None:
        self.lines: list[str] = []
        self.procs: list[subprocess.Popen] = []
        for argv in commands:
            proc = subprocess.Popen(
                argv, env=env, start_new_session=True, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True,
            )  # fmt: skip
            self.procs.append(proc)
            threading.Thread(
                target=lambda p=proc: self.lines.extend(p.stdout), daemon=True
            ).start()

    def running(self) -> bool:
        """Whether every process is still running."""
        return all(p.poll() is None for p in self.procs)

    def names(self) -> dict[int, str]:
        """Every process and its descendants: pid -> short name (:func:`process_names`)."""
        out: dict[int, str] = {}
        for proc in self.procs:
            out.update(process_names(proc.pid))
        return out

    def stop(self, timeout: float = 30.0) -> None:
        """SIGINT each process group, wait up to ``timeout`` s each, then SIGKILL.

        Parameters
        ----------
        timeout : float
            s to wait for each process.
        """
        for proc in self.procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
        for proc in self.procs:
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()

    def tail(self, n: int = 40) -> str:
        """Return the last ``n`` lines of output of all the processes.

        Parameters
        ----------
        n : int
            Lines.
        """
        return ''.join(self.lines[-n:])
