"""What the nonlinear filters (EKF, UKF) share: the fast model's compiled f and h."""

from __future__ import annotations

__all__ = ['compiled_arguments', 'require_fast_field']


def require_fast_field(model, filter_name: str) -> None:
    """Refuse a model whose field is not the fast (compiled) one.

    Parameters
    ----------
    model : MaggyModel
        The model the filter would run.
    filter_name : str
        The filter's short name for the message (``'EKF'``, ``'UKF'``).

    Raises
    ------
    ValueError
        The model's field option is not ``'fast'``.
    """
    if model.options.field != 'fast':
        raise ValueError(
            f'the {filter_name} needs the fast field model, got {model.options.field!r}'
        )


def compiled_arguments(model) -> tuple[tuple, tuple]:
    """Arguments of the compiled dynamics f and measurement h of the fast model.

    Parameters
    ----------
    model : MaggyModel
        A model with the fast field.

    Returns
    -------
    f_args : tuple
        ``(sources, coils, rim, parameters, work)`` for ``rk4_sample``.
    h_args : tuple
        ``(sources, coils, sensors, magnet, work)`` for ``fast_measurement``.
    """
    src, coil, rim, par, work = model.fast_arguments()
    _, _, sens, mag, _ = model.measurement_arguments()
    return (src, coil, rim, par, work), (src, coil, sens, mag, work)
