"""Physics benchmark: force/torque speed-up and simulator real-time factor.

Everything is measured in one run against a plain reference implementation
written below (the structure of the published MATLAB reference code: n = 100
rim points, a Python ``for`` loop over the 8 base sources, each loop's field in
straightforward numpy with ``scipy.special.ellipk/ellipe``):

1. correctness: relative difference of the package's force (n = 32) from the
   reference (n = 100) at the equilibrium and at perturbed states (<= 1e-9);
2. force+torque evaluation speed-up, ``model.wrench(x, u)`` vs the reference
   (target >= 20x);
3. the simulator's real-time factor at 5 kHz with the fast model, no ROS,
   ``Simulator.step`` in a Python loop and ``Simulator.run`` (one compiled
   call), against the same RK4 stepping done with the reference wrench
   (target >= 10x real time).

It reports, it is not a test: the exit code is 0 even when a target is missed.
Nothing is written to disk unless ``--markdown PATH`` is given.

Usage::

    python benchmarks/physics.py [--params maggy_v2|maggy_v4] [--quick] [--markdown PATH]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time

import numpy as np
from scipy.special import ellipe, ellipk

MU0 = 4e-7 * math.pi  # N/A^2, the model's value
GRAVITY = 9.81  # m/s^2
REF_RIM_POINTS = 100
SAMPLE_RATE = 5000.0  # Hz
SPEEDUP_TARGET = 20.0
FORCE_TOLERANCE = 1e-9
RTF_TARGET = 10.0
U_TEST = np.array([0.3, -0.2, 0.1, 0.25])


# ---------------------------------------------------------------------------- reference
def ref_rotation(alpha, beta, gamma):
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cg, -sg, 0], [sg, cg, 0], [0, 0, 1]])
    return rz @ ry @ rx


def ref_loop_field(px, py, pz, a, current):
    """Textbook field of a loop (radius a, axis z, centred at the origin), Cartesian."""
    rho = np.hypot(px, py)
    phi = np.arctan2(py, px)
    k2 = np.clip(4 * a * rho / ((a + rho) ** 2 + pz**2), 0.0, 1.0)
    kk, ee = ellipk(k2), ellipe(k2)
    ck = MU0 * current / (2 * np.pi * np.sqrt((a + rho) ** 2 + pz**2))  # c k, simplified
    den = (rho - a) ** 2 + pz**2
    bz = ck * (kk - (rho**2 - a**2 + pz**2) / den * ee)
    near = rho < 1e-6  # on/near a source axis (V2 centred: rim points exactly over solenoids)
    with np.errstate(divide='ignore', invalid='ignore'):
        brho = -(pz / rho) * ck * (kk - (rho**2 + a**2 + pz**2) / den * ee)
    axis = 3 * MU0 * current * a**2 * pz * rho / (4 * (a**2 + pz**2) ** 2.5)
    brho = np.where(near, axis, brho)
    return brho * np.cos(phi), brho * np.sin(phi), bz


class ReferenceModel:
    """Plain fast model: n rim points, a Python loop over the sources, numpy per source."""

    def __init__(self, params, correction, n=REF_RIM_POINTS):
        self.sources = []  # (cx, cy, cz, radius, fixed current, turns, input index)
        pm = params.permanent_magnets
        for j in range(pm.count):
            cx, cy, cz = pm.centers[j]
            self.sources.append(
                (cx, cy, cz, pm.radius[j], pm.polarization[j] * pm.length[j] / MU0, 0.0, -1)
            )
        sol = params.solenoids
        for j in range(sol.count):
            cx, cy, cz = sol.centers[j]
            self.sources.append((cx, cy, cz, correction * sol.radius[j], 0.0, sol.turns[j], j))
        m = params.magnet
        self.radius, self.thickness = m.radius, m.thickness
        self.k0 = -m.polarization / MU0
        self.mass = m.mass
        self.inertia = np.array(m.inertia, dtype=float)
        self.n = n
        theta = 2 * np.pi * np.arange(n) / n
        self.ring = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)])  # (3, n)
        self.tang = np.stack([-np.sin(theta), np.cos(theta), np.zeros(n)])

    def base_field(self, pts, u):
        """Field of the base at points (3, n), T, shape (3, n)."""
        bx = np.zeros(pts.shape[1])
        by = np.zeros(pts.shape[1])
        bz = np.zeros(pts.shape[1])
        for cx, cy, cz, a, fixed, turns, j in self.sources:
            current = fixed if j < 0 else turns * u[j]
            fx, fy, fz = ref_loop_field(pts[0] - cx, pts[1] - cy, pts[2] - cz, a, current)
            bx += fx
            by += fy
            bz += fz
        return np.stack([bx, by, bz])

    def wrench(self, x, u):
        """Force (N) and true torque (N m), world frame, shape (6,)."""
        r = ref_rotation(x[3], x[4], x[5])
        offsets = self.radius * (r @ self.ring)  # (3, n): p_i - p
        tangents = r @ self.tang
        field = self.base_field(offsets + np.asarray(x[:3])[:, None], u)
        dforce = (
            (self.radius * self.thickness * 2 * np.pi / self.n)
            * self.k0
            * np.cross(tangents, field, axis=0)
        )
        force = dforce.sum(axis=1)
        torque = np.cross(offsets, dforce, axis=0).sum(axis=1)
        return np.concatenate([force, torque])

    def dynamics(self, x, u):
        """f(x, u) with ZYX Euler kinematics and body-frame Euler equations."""
        w = self.wrench(x, u)
        r = ref_rotation(x[3], x[4], x[5])
        tau_body = r.T @ w[3:]
        ca, sa, cb, tb = math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.tan(x[4])
        om = x[9:12]
        i_w = self.inertia * om
        rates = [
            om[0] + (om[1] * sa + om[2] * ca) * tb,
            om[1] * ca - om[2] * sa,
            (om[1] * sa + om[2] * ca) / cb,
        ]
        acc = w[:3] / self.mass - np.array([0.0, 0.0, GRAVITY])
        dw = (tau_body - np.cross(om, i_w)) / self.inertia
        return np.concatenate([x[6:9], rates, acc, dw])

    def rk4_step(self, x, u, h):
        """One classical RK4 step of length h with u held."""
        k1 = self.dynamics(x, u)
        k2 = self.dynamics(x + 0.5 * h * k1, u)
        k3 = self.dynamics(x + 0.5 * h * k2, u)
        k4 = self.dynamics(x + h * k3, u)
        return x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)


# ---------------------------------------------------------------------------- helpers
def best_per_call(fn, calls, repeats):
    """Best over ``repeats`` of the mean time per call of ``calls`` calls, s."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def best_time(fn, repeats):
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def check_states(z_eq):
    """(label, x, u): equilibrium and perturbed states (mm, 0.05-0.1 rad, nonzero u)."""

    def state(dx, dy, dz, al, be, ga):
        x = np.zeros(12)
        x[:6] = [dx, dy, z_eq + dz, al, be, ga]
        return x

    zero = np.zeros(4)
    return [
        ('equilibrium, u = 0', state(0, 0, 0, 0, 0, 0), zero),
        ('equilibrium, u = U', state(0, 0, 0, 0, 0, 0), U_TEST),
        ('+2/-1/+1 mm, .05/-.08/.1 rad, 0', state(2e-3, -1e-3, 1e-3, 0.05, -0.08, 0.1), zero),
        ('-3/+2/-2 mm, -.1/.05/.3 rad, U', state(-3e-3, 2e-3, -2e-3, -0.1, 0.05, 0.3), U_TEST),
        ('+1/+3/+2 mm, .08/.1/-.7 rad, -U', state(1e-3, 3e-3, 2e-3, 0.08, 0.1, -0.7), -U_TEST),
    ]


def prbs_inputs(samples, hold, seed, mode):
    """+-0.05 A PRBS, held ``hold`` samples: antisymmetric x/y pairs or common mode."""
    rng = np.random.default_rng(seed)
    blocks = -(-samples // hold)
    if mode == 'pairs':
        a = 0.05 * np.repeat(rng.choice([-1.0, 1.0], size=(blocks, 2)), hold, axis=0)
        u = np.column_stack([a[:, 0], -a[:, 0], a[:, 1], -a[:, 1]])
    else:
        c = 0.05 * np.repeat(rng.choice([-1.0, 1.0], size=blocks), hold)
        u = np.column_stack([c, c, c, c])
    return np.ascontiguousarray(u[:samples])


def verdict(ok):
    return 'PASS' if ok else 'FAIL'


# ---------------------------------------------------------------------------- benchmark
def bench_params(name, quick, load_rows):
    from maglev_ros.physics import kernels
    from maglev_ros.physics.equilibria import find_equilibria
    from maglev_ros.physics.model import make_model
    from maglev_ros.physics.simulation import Simulator

    reps = 3 if quick else 7
    t0 = time.perf_counter()
    model = make_model(name)
    t1 = time.perf_counter()
    correction = model.correction
    t2 = time.perf_counter()
    model.wrench(model.hover_state(0.03), np.zeros(4))
    t3 = time.perf_counter()
    z_eq = find_equilibria(model)[0].z
    t4 = time.perf_counter()
    load_rows.append((name, t1 - t0, t2 - t1, t3 - t2, t4 - t3))
    ref = ReferenceModel(model.params, correction)
    scale = model.params.magnet.radius
    model_100 = make_model(name, rim_points=REF_RIM_POINTS, correction=correction)

    # -- correctness
    checks = []
    for label, x, u in check_states(z_eq):
        w_pkg = model.wrench(x, u)
        w_ref = ref.wrench(x, u)
        f_norm = np.linalg.norm(w_ref[:3])
        rel_f = np.linalg.norm(w_pkg[:3] - w_ref[:3]) / f_norm
        rel_f100 = np.linalg.norm(model_100.wrench(x, u)[:3] - w_ref[:3]) / f_norm
        d_tau = np.linalg.norm(w_pkg[3:] - w_ref[3:])
        t_norm = np.linalg.norm(w_ref[3:])
        rel_t = d_tau / t_norm if t_norm > 1e-9 * scale * f_norm else math.nan
        checks.append((label, f_norm, t_norm, rel_f, rel_t, d_tau / (scale * f_norm), rel_f100))
    max_rel_f = max(c[3] for c in checks)

    # -- force+torque speed
    states = [(x, u) for _, x, u in check_states(z_eq)]
    t_pkg = sum(
        best_per_call(lambda x=x, u=u: model.wrench(x, u), 100 if quick else 400, reps)
        for x, u in states
    ) / len(states)
    t_pkg100 = sum(
        best_per_call(lambda x=x, u=u: model_100.wrench(x, u), 50 if quick else 200, reps)
        for x, u in states
    ) / len(states)
    t_ref = sum(
        best_per_call(lambda x=x, u=u: ref.wrench(x, u), 5 if quick else 20, reps)
        for x, u in states
    ) / len(states)

    # -- simulator
    dt = 1.0 / SAMPLE_RATE
    x_eq = model.hover_state(z_eq)
    sim = Simulator(model, sample_rate=SAMPLE_RATE, x0=x_eq)
    t5 = time.perf_counter()
    sim.step(np.zeros(4))
    sim.run(np.zeros((2, 4)))
    load_rows[-1] += (time.perf_counter() - t5,)
    n_full = int(SAMPLE_RATE)  # 1 s
    pairs = prbs_inputs(n_full, 50, 1, 'pairs')
    probe = sim.run(pairs)
    n_pairs = n_full if not probe.crashed else (len(probe.t) - 1) // 50 * 50 - 50
    crash_note = (
        f'crashed at {probe.crash_time:.3f} s ({probe.reason})'
        if probe.crashed
        else 'no crash in 1 s'
    )
    common = prbs_inputs(n_full, 50, 2, 'common')
    crash = np.concatenate(
        [
            [model.params.base_top, model.params.magnet.radius, model.params.magnet.thickness / 2],
            model.params.workspace.lower,
            model.params.workspace.upper,
        ]
    )
    core_args = model.fast_arguments()
    sens_args = model.measurement_arguments()[2:4]  # sens, mag: the core also reads sensors
    cfg = kernels.simulator_config(dt, 1, kernels.COIL_IDEAL, True, False, np.ones(3), crash)
    sim_rows = []
    sim_reps = 2 if quick else 3
    for label, inputs in (
        (f'pairs {n_pairs * dt:.2f} s', pairs[:n_pairs]),
        ('common 1.00 s', common),
    ):

        def step_loop(inputs=inputs):
            sim.reset(x_eq)
            for u in inputs:
                sim.step(u)

        step_loop()
        if sim.crashed:
            raise RuntimeError(f'{name}: step loop crashed on {label} at {sim.crash_time} s')
        t_step = best_time(step_loop, sim_reps)
        result = sim.run(inputs)
        if result.crashed:
            raise RuntimeError(f'{name}: run crashed on {label} at {result.crash_time} s')
        t_run = best_time(lambda inputs=inputs: sim.run(inputs), sim_reps)
        t_core = best_time(
            lambda inputs=inputs: kernels.rk4_run(
                x_eq.copy(), inputs, cfg, *core_args, *sens_args
            ),
            sim_reps,
        )
        sim_rows.append((label, len(inputs) * dt, t_step, t_run, t_core, result.x[-1]))

    # baseline: the same RK4 (one step per sample) with the reference f(x, u)
    n_base = 50 if quick else 250
    base_inputs = pairs[:n_base]
    t_base = math.inf
    for _ in range(1 if quick else 2):
        x = x_eq.copy()
        t6 = time.perf_counter()
        for u in base_inputs:
            x = ref.rk4_step(x, u, dt)
        t_base = min(t_base, time.perf_counter() - t6)
    pkg_x = sim.run(base_inputs).x[-1]
    traj_err = np.max(np.abs(pkg_x[:3] - x[:3]))
    rtf_base = n_base * dt / t_base
    return dict(
        name=name,
        z_eq=z_eq,
        correction=correction,
        checks=checks,
        max_rel_f=max_rel_f,
        t_pkg=t_pkg,
        t_pkg100=t_pkg100,
        t_ref=t_ref,
        sim_rows=sim_rows,
        crash_note=crash_note,
        n_base=n_base,
        rtf_base=rtf_base,
        traj_err=traj_err,
    )


# ---------------------------------------------------------------------------- report
def machine_line():
    model_name = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    model_name = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    import numba
    import scipy

    cores = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    return (
        f'{model_name}, {cores} cores; Python {platform.python_version()}, numpy '
        f'{np.__version__}, scipy {scipy.__version__}, numba {numba.__version__}'
    )


def result_rows(results):
    """Rows of the main table: (params, metric, package, reference, ratio, target, result)."""
    rows = []
    for r in results:
        n = r['name']
        speed = r['t_ref'] / r['t_pkg']
        ok = speed >= SPEEDUP_TARGET and r['max_rel_f'] <= FORCE_TOLERANCE
        rows.append(
            (
                n,
                'max rel. force diff, 5 states',
                f'{r["max_rel_f"]:.1e}',
                '',
                '',
                f'<= {FORCE_TOLERANCE:.0e}',
                verdict(r['max_rel_f'] <= FORCE_TOLERANCE),
            )
        )
        rows.append(
            (
                n,
                'wrench(x, u), us/call',
                f'{r["t_pkg"] * 1e6:.1f} (n=32)',
                f'{r["t_ref"] * 1e6:.0f} (n=100)',
                f'{speed:.0f}x',
                f'>= {SPEEDUP_TARGET:.0f}x',
                verdict(ok),
            )
        )
        rows.append(
            (
                n,
                '  info: package at n=100',
                f'{r["t_pkg100"] * 1e6:.1f} (n=100)',
                f'{r["t_ref"] * 1e6:.0f} (n=100)',
                f'{r["t_ref"] / r["t_pkg100"]:.0f}x',
                '',
                '',
            )
        )
        base = r['rtf_base']
        rows.append(
            (n, f'RK4 baseline RTF ({r["n_base"]} samples)', '', f'{base:.3f}x', '', '', '')
        )
        for label, sim_t, t_step, t_run, t_core, _ in r['sim_rows']:
            for what, wall in (('step() loop', t_step), ('run()', t_run)):
                rtf = sim_t / wall
                rows.append(
                    (
                        n,
                        f'{what} RTF, {label}',
                        f'{rtf:.1f}x',
                        f'{base:.3f}x',
                        f'{rtf / base:.0f}x',
                        f'>= {RTF_TARGET:.0f}x RT',
                        verdict(rtf >= RTF_TARGET),
                    )
                )
            rtf = sim_t / t_core
            rows.append(
                (
                    n,
                    f'  info: compiled RK4 core only, {label}',
                    f'{rtf:.1f}x',
                    f'{base:.3f}x',
                    f'{rtf / base:.0f}x',
                    '',
                    '',
                )
            )
    return rows


HEADER = ('params', 'metric', 'package', 'reference', 'ratio', 'target', 'result')


def text_table(header, rows):
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=True)]

    def line(values):
        return '  '.join(str(v).ljust(w) for v, w in zip(values, widths, strict=True)).rstrip()

    dashes = ['-' * w for w in widths]
    return '\n'.join(line(values) for values in (header, dashes, *rows))


def markdown_table(header, rows):
    def line(values):
        return '| ' + ' | '.join(str(v).strip().replace('|', '\\|') for v in values) + ' |'

    return '\n'.join(
        [line(header), '|' + '|'.join('---' for _ in header) + '|', *(line(row) for row in rows)]
    )


def summaries(results):
    out = []
    for r in results:
        speed = r['t_ref'] / r['t_pkg']
        ok = speed >= SPEEDUP_TARGET and r['max_rel_f'] <= FORCE_TOLERANCE
        out.append(
            f'SUMMARY {r["name"]} force+torque speed-up >= {SPEEDUP_TARGET:.0f}x at '
            f'rel. force diff <= {FORCE_TOLERANCE:.0e}: {verdict(ok)} '
            f'({speed:.0f}x, max rel. diff {r["max_rel_f"]:.1e})'
        )
        parts = []
        for label, sim_t, t_step, t_run, _, _ in r['sim_rows']:
            parts.append(
                f'step() {sim_t / t_step:.1f}x {verdict(sim_t / t_step >= RTF_TARGET)}'
                f', run() {sim_t / t_run:.1f}x {verdict(sim_t / t_run >= RTF_TARGET)}'
                f' [{label}]'
            )
        out.append(
            f'SUMMARY {r["name"]} simulator >= {RTF_TARGET:.0f}x real time at '
            f'{SAMPLE_RATE / 1000:.0f} kHz (fast model, no ROS): ' + '; '.join(parts)
        )
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument(
        '--params',
        choices=('maggy_v2', 'maggy_v4'),
        action='append',
        help='parameter set (repeatable; default both)',
    )
    parser.add_argument('--quick', action='store_true', help='fewer repeats')
    parser.add_argument('--markdown', metavar='PATH', help='also write the tables as markdown')
    args = parser.parse_args(argv)
    names = args.params or ['maggy_v2', 'maggy_v4']

    t_start = time.perf_counter()
    t0 = time.perf_counter()
    import maglev_ros.physics.simulation  # noqa: F401  (import time, numba included)

    t_import = time.perf_counter() - t0
    load_rows = []
    results = [bench_params(name, args.quick, load_rows) for name in names]

    out = [
        f'Physics benchmark: fast model, {SAMPLE_RATE:.0f} Hz, no ROS'
        f'{" (quick)" if args.quick else ""}',
        f'machine: {machine_line()}',
        f'reference: plain numpy/scipy, n = {REF_RIM_POINTS} rim points, Python loop over '
        'sources; package: model.wrench, n = 32',
        '',
    ]

    out.append(
        'Correctness (package n = 32 vs reference n = 100; U = '
        f'{U_TEST.tolist()} A; torque diff also scaled by R |F|; last column: '
        'the package at n = 100):'
    )
    check_header = (
        'params',
        'state',
        '|F| (N)',
        '|tau| (N m)',
        'rel dF',
        'rel dtau',
        'dtau/(R|F|)',
        'rel dF n=100',
    )
    check_rows = []
    for r in results:
        for label, f_norm, t_norm, rel_f, rel_t, rel_tr, rel_f100 in r['checks']:
            check_rows.append(
                (
                    r['name'],
                    label,
                    f'{f_norm:.4f}',
                    f'{t_norm:.2e}',
                    f'{rel_f:.1e}',
                    '-' if math.isnan(rel_t) else f'{rel_t:.1e}',
                    f'{rel_tr:.1e}',
                    f'{rel_f100:.1e}',
                )
            )
    out += [text_table(check_header, check_rows), '']

    load_header = (
        'params',
        'make_model',
        'correction (+JIT load)',
        'first wrench',
        'find_equilibria',
        'first sim step+run',
    )
    load_table = [(row[0], *(f'{v:.3f} s' for v in row[1:])) for row in load_rows]
    out.append(f'Load/compile times (excluded from the figures; package import {t_import:.3f} s):')
    out += [text_table(load_header, load_table), '']

    notes = []
    for r in results:
        notes.append(
            f'{r["name"]}: z_eq = {r["z_eq"] * 1e3:.3f} mm, solenoid radius factor '
            f'{r["correction"]:.4f}; PRBS +-0.05 A held 10 ms: antisymmetric pairs '
            f'{r["crash_note"]}, common mode (all four coils) 1 s; RK4 trajectory '
            f'package vs reference after {r["n_base"]} samples: '
            f'max |dp| = {r["traj_err"]:.1e} m'
        )
    out += notes + ['']
    rows = result_rows(results)
    out += [text_table(HEADER, rows), '']
    out += summaries(results)
    out.append(f'total wall time {time.perf_counter() - t_start:.1f} s')
    print('\n'.join(out))

    if args.markdown:
        md = [
            'Correctness (package n = 32 vs reference n = 100):',
            '',
            markdown_table(check_header, check_rows),
            '',
            markdown_table(HEADER, rows),
            '',
        ]
        md += [f'- {line}' for line in notes + summaries(results)]
        with open(args.markdown, 'w') as f:
            f.write('\n'.join(md) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
