"""Whether a calibration can be trusted: the checks behind "calibrated".

A fit always returns numbers; these checks say whether they mean anything:

* a parameter at a bound of its range (the data pull it outside: a wrong
  measurement model, a wrong fixed parameter, or too narrow a range);
* a calibrated set that predicts the validation data worse than the nominal
  set (the fit describes the estimation part's noise or a model error);
* an undetermined sensor delay (every tried delay predicts equally well, so the
  reported one is arbitrary);
* two estimates correlated above 0.99 (only their combination is well
  determined; their standard deviations say how badly each one is);
* a diverging nonlinear predictor.

Parameters the data do not identify at all are held at their nominal values
and listed by the calibration itself (:mod:`.identifiability`); they do not
change the status.  The status is ``calibrated`` when no check fires; ``not
calibrated`` when the calibrated set validates worse than nominal or every
estimated parameter sits at a bound; otherwise ``partly calibrated``.
``maglev-calibrate`` writes a parameter file only for ``calibrated`` and exits
1 otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['BOUND_TOLERANCE', 'CORRELATION_LIMIT', 'Verdict', 'assess']

BOUND_TOLERANCE = 1e-3  # a parameter within this fraction of its range from a bound is at it
CORRELATION_LIMIT = 0.99
WORSE_TOLERANCE = 1e-3  # relative validation RMS increase that counts as worse
DELAY_SPREAD = 1e-3  # relative spread of the delay costs below which the delay is undetermined


@dataclass(frozen=True)
class Verdict:
    """Outcome of :func:`assess`.

    Attributes
    ----------
    status : str
        ``calibrated``, ``partly calibrated`` or ``not calibrated``.
    warnings : tuple of str
        One line per failed check, saying what to do.
    undetermined : tuple of str
        Estimated parameters at a bound of their range.
    """

    status: str
    warnings: tuple[str, ...]
    undetermined: tuple[str, ...]

    @property
    def exit_status(self) -> int:
        """0 for ``calibrated``, 1 otherwise."""
        return 0 if self.status == 'calibrated' else 1

    def as_dict(self) -> dict:
        """JSON-ready form."""
        return {
            'status': self.status,
            'warnings': list(self.warnings),
            'undetermined': list(self.undetermined),
        }


def assess(cal) -> Verdict:
    """Check a static or dynamic calibration result.

    Parameters
    ----------
    cal : StaticCalibration or DynamicCalibration
        The result.

    Returns
    -------
    Verdict
        Status and warnings.
    """
    warnings: list[str] = []
    undetermined: set[str] = set()
    for name in cal.names:
        spec = cal.vector[name]
        value = float(cal.estimate[name])
        span = float(spec.upper - spec.lower)
        for side, bound in (('lower', spec.lower), ('upper', spec.upper)):
            if np.isfinite(bound) and abs(value - bound) <= BOUND_TOLERANCE * span:
                undetermined.add(name)
                warnings.append(
                    f'{name} = {spec.display(value)} sits at its {side} bound: the data pull '
                    'it out of its range; check the measurement model (--measurement), the '
                    'fixed parameters and --bounds before trusting any estimate'
                )
    worse = [
        (nom, new)
        for nom, new in zip(cal.validation_nominal, cal.validation_calibrated, strict=True)
        if new.total_rms > nom.total_rms * (1 + WORSE_TOLERANCE)
    ]
    for nom, new in worse:
        warnings.append(
            f'{nom.experiment}: the calibrated set predicts the validation data worse than '
            f'the nominal one (RMS {1e3 * new.total_rms:.4g} mT against '
            f'{1e3 * nom.total_rms:.4g} mT): the fit does not generalise; the model or the '
            'data are wrong'
        )
    for k, record in enumerate(getattr(cal, 'delay_costs', ())):
        costs = np.asarray(record, dtype=float)
        if costs.size < 2 or not np.all(np.isfinite(costs)):
            continue
        spread = (costs.max() - costs.min()) / max(costs.min(), 1e-300)
        if spread < DELAY_SPREAD:
            delay = cal.delays[min(k, len(cal.delays) - 1)]
            warnings.append(
                f'the sensor delay is not determined: every tried delay predicts equally well '
                f'(costs {", ".join(f"{c:.4g}" for c in costs)}); the reported '
                f"{delay} is arbitrary: give --delay SAMPLES from the board's documentation"
            )
    for a, b, r in cal.correlated:
        if abs(r) > CORRELATION_LIMIT:
            warnings.append(
                f'{a} and {b} are correlated (r = {r:+.4f}): only their combination is '
                'determined; free only one of them, or add data that separate them'
            )
    for note in getattr(cal, 'notes', ()):
        warnings.append(note)
    if worse or (cal.names and undetermined >= set(cal.names)):
        status = 'not calibrated'
    elif warnings or undetermined:
        status = 'partly calibrated'
    else:
        status = 'calibrated'
    return Verdict(status, tuple(warnings), tuple(sorted(undetermined)))
