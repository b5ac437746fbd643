"""The runs of a study: every grid point times ``repeats``, each with its seed and draws.

Run ``i`` draws from ``numpy.random.default_rng(SeedSequence([seed, i]))``:
first the loop's noise seed, then the random parameters in file order. A
run's values therefore depend only on the study and its index, never on
where or in which order the runs are done.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from .parameters import StudyError, check_value
from .spec import StudySpec, SuccessCriterion

__all__ = ['RunTask', 'plan_runs']


@dataclass(frozen=True)
class RunTask:
    """One closed-loop run of a study (small and picklable: it travels to the workers).

    Attributes
    ----------
    index : int
        Run number, from 0.
    seed : int
        The loop's noise seed.
    values : tuple of (str, object)
        The study's parameters for this run, in column order.
    duration : float
        s of simulated time.
    success : SuccessCriterion
    """

    index: int
    seed: int
    values: tuple[tuple[str, Any], ...]
    duration: float
    success: SuccessCriterion

    def as_dict(self) -> dict[str, Any]:
        """Return the parameters as a mapping."""
        return dict(self.values)


def plan_runs(spec: StudySpec) -> list[RunTask]:
    """Return every run of a study, in index order.

    Parameters
    ----------
    spec : StudySpec

    Raises
    ------
    StudyError
        A drawn value out of its parameter's range, or a combination the loop
        cannot be built from (names the keys and the run).
    """
    from .loop_adapter import check_setup

    tasks = []
    grid_keys = list(spec.grid)
    points = itertools.product(*spec.grid.values())
    index = 0
    for point in points:
        for _ in range(spec.repeats):
            rng = np.random.default_rng(np.random.SeedSequence([spec.seed, index]))
            seed = int(rng.integers(2**31 - 1))
            values = dict(spec.fixed)
            values.update(zip(grid_keys, point, strict=True))
            for key, dist in spec.random.items():
                drawn = dist.draw(rng)
                try:
                    values[key] = check_value(key, drawn)
                except StudyError as exc:
                    problem = str(exc)[len(key) + 2 :].split(', got ')[0]
                    raise StudyError(
                        f'{spec.source}: random.{key}: run {index} drew {drawn:.6g}, but it '
                        f'{problem}: narrow the distribution'
                    ) from None
            try:
                check_setup(values)
            except ValueError as exc:
                raise StudyError(
                    f'{spec.source}: run {index} ({_describe(values)}): {exc}'
                ) from None
            tasks.append(RunTask(index, seed, tuple(values.items()), spec.duration, spec.success))
            index += 1
    return tasks


def _describe(values: dict[str, Any]) -> str:
    return ', '.join(f'{k}={v}' for k, v in values.items())
