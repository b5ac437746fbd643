"""The estimator as a stage of its own: sample parts by stamp in, estimates out.

The estimator node (separate processes) gets each sample as messages on
several topics: every sensor's field and the currents, in any order.
:class:`EstimateStage` is that stage without ROS: it collects a sample's
parts by stamp (:class:`~maglev_ros.loop.sample_assembly.SampleAssembler`),
steps the estimator once per sample in stamp order once it is complete, or
once a sensor is known lost (its field of a later stamp came, a later sample
is complete, or samples more than ``sample_wait`` later came: that sensor is
then missing, NaN, never because of callback order), and says which
estimates to publish (every ``publish_every``-th sample by stamp). A
lockstep graph so estimates exactly as the composed loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sample_assembly import SampleAssembler

__all__ = ['Estimate', 'EstimateStage']


@dataclass(frozen=True)
class Estimate:
    """One estimate to publish.

    Attributes
    ----------
    stamp_ns : int
        Stamp of its sample, ns.
    x : ndarray, shape (12,)
        Estimated state.
    covariance : ndarray, shape (n, n)
        Its covariance over the reduced states (then any bias states).
    """

    stamp_ns: int
    x: np.ndarray
    covariance: np.ndarray


class EstimateStage:
    """Steps an estimator once per sample assembled from its parts (module docstring).

    Parameters
    ----------
    estimator : Estimator
        The filter (:func:`~maglev_ros.estimation.make_estimator`).
    sample_wait : int
        Samples of later stamps a sample waits for a silent sensor.
    publish_every : int
        Samples per published estimate (1: every sample); the published ones
        are those whose stamp is a multiple of ``publish_every`` periods.
    """

    def __init__(self, estimator, sample_wait: int = 10, publish_every: int = 1) -> None:
        self.estimator = est = estimator
        self.n_sensors = est.n_sensors
        self.period_ns = 1e9 / est.config.sample_rate
        self.publish_every = publish_every
        # parts 0 .. k-1: the sensors' fields; part k: the currents
        self.assembler = SampleAssembler(self.n_sensors + 1, round(sample_wait * self.period_ns))
        self.lost_samples = 0  # released without their currents: not estimated
        self.published = 0
        self.last_stamp: int | None = None
        # the compiled kernels load now, not on the first sample, then the prior again
        est.step(est.y_eq, est.u_eq)
        est.reset()

    @property
    def currents_part(self) -> int:
        """The part number of a sample's currents (after the sensors' fields)."""
        return self.n_sensors

    def part(self, part: int, stamp_ns: int, values) -> tuple[list[Estimate], list[str]]:
        """Take one part of a sample; step through the samples it releases.

        Parameters
        ----------
        part : int
            Sensor k's field (3,), T, for k < n_sensors; then the currents
            (n_s,), A.
        stamp_ns : int
            The sample's stamp, ns.
        values : sequence of float
            The part's values.

        Returns
        -------
        estimates : list of Estimate
            Those to publish, in stamp order.
        errors : list of str
            Samples not estimated and why (a reading that is not finite).
        """
        out: list[Estimate] = []
        errors: list[str] = []
        for sample in self.assembler.add(part, stamp_ns, values):
            parts = sample.parts
            if parts[-1] is None:
                self.lost_samples += 1  # no currents: the sample cannot be estimated
                continue
            fields = parts[:-1]
            y = np.full(3 * self.n_sensors, np.nan)
            for k, f in enumerate(fields):
                if f is not None:
                    y[3 * k : 3 * k + 3] = f
            try:
                x = self.estimator.step(y, np.asarray(parts[-1], dtype=float))
            except ValueError as err:
                errors.append(f'sample {sample.stamp} ns not estimated: {err}')
                continue
            self.last_stamp = sample.stamp
            every = self.publish_every
            if every == 1 or round(sample.stamp / self.period_ns) % every == 0:
                self.published += 1
                out.append(Estimate(sample.stamp, x, self.estimator.state_covariance))
        return out, errors

    def diagnostic(self, waiting_for: str) -> tuple[int, str, dict[str, object]]:
        """Return the diagnostic level (0 OK, 1 WARN), message and values.

        Parameters
        ----------
        waiting_for : str
            What the message names while no sample came (the currents' topic).
        """
        s = self.estimator.status()
        if s.samples == 0:
            level, message = 0, f'waiting for samples on {waiting_for}'
        elif s.frozen:
            level = 1
            message = f'frozen: {", ".join(s.frozen_names())} (readings ignored until they change)'
        elif not s.nis_ok:
            level = 1
            message = (
                f'NIS {s.nis_window:.1f} outside its 99 % band '
                f'[{s.nis_band[0]:.1f}, {s.nis_band[1]:.1f}]: check sensor_noise and the model'
            )
        else:
            level, message = 0, f'estimating ({self.estimator.config.filter})'
        values = {
            'samples': s.samples,
            'NIS window': f'{s.nis_window:.6g}',
            'NIS dof': s.nis_dof,
            'NIS 99 % band': f'{s.nis_band[0]:.6g} {s.nis_band[1]:.6g}',
            'rejected per sensor': ' '.join(str(v) for v in s.rejected),
            'missing per sensor': ' '.join(str(v) for v in s.missing),
            'frozen sensors': ' '.join(s.frozen_names()),
            'freeze events per sensor': ' '.join(str(v) for v in s.freeze_events),
            'lost samples (no currents)': self.lost_samples,
            'restarts': s.restarts,
            'estimates published': self.published,
            'late messages': self.assembler.late,
        }
        return level, message, values
