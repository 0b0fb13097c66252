"""Design variables of the 4S4 tuning problem (Thoresson et al. 2009, Part 1, eqs. 4-8).

The optimiser works on normalised variables ``x`` in ``[X_LOWER, X_UPPER]``; the vehicle
model works on physical settings (damper force scale factor ``dpsf`` and static gas
volume in m^3).  Eq. 4 maps a physical value ``v`` in ``[v_low, v_high]`` to
``x = (v - v_low) / (v_high - v_low)``.  Note that the paper's lower bound
``x = 0.001`` (eqs. 6, 8) therefore maps to ``dpsf = 0.1029`` and ``gvol = 0.1005 L``,
not exactly to the range ends 0.1 and 0.1 L: that is the paper's choice and is kept.

Two variable sets exist (section 5.1):

* 2 variables ``(dpsf, gvol)``, identical front and rear (eq. 5);
* 4 variables ``(dpsf_front, gvol_front, dpsf_rear, gvol_rear)`` (eq. 7).

All functions accept a single design of shape ``(n,)`` or a batch of shape
``(batch, n)`` and return batched arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

X_LOWER = 0.001
"""Lower bound of every normalised design variable [P eqs. 6, 8]."""
X_UPPER = 1.0
"""Upper bound of every normalised design variable [P eqs. 6, 8]."""
DPSF_RANGE = (0.1, 3.0)
"""Damper force scale factor range, dimensionless, 4S4 design limits [P section 5.1]."""
GVOL_RANGE_M3 = (0.1e-3, 0.6e-3)
"""Static gas volume range in m^3 (0.1-0.6 L), 4S4 design limits [P section 5.1]."""

VARIABLE_NAMES = {
    2: ('dpsf', 'gvol'),
    4: ('dpsf_front', 'gvol_front', 'dpsf_rear', 'gvol_rear'),
}
"""Names of the normalised variables for the 2- and 4-variable problems [P eqs. 5, 7]."""


@dataclass(frozen=True, eq=False)
class AxleSettings:
    """Physical 4S4 settings per axle for a batch of designs.

    Attributes
    ----------
    dpsf_front, dpsf_rear : np.ndarray
        Damper force scale factors, dimensionless, shape (batch,).
    gas_volume_front_m3, gas_volume_rear_m3 : np.ndarray
        Static gas volumes in m^3, shape (batch,).
    """

    dpsf_front: np.ndarray
    gas_volume_front_m3: np.ndarray
    dpsf_rear: np.ndarray
    gas_volume_rear_m3: np.ndarray

    @property
    def batch_size(self) -> int:
        """Number of designs in the batch."""
        return int(np.shape(self.dpsf_front)[0])


def normalise(value: np.ndarray, low: float, high: float) -> np.ndarray:
    """Map a physical value to the normalised design variable, eq. 4.

    Parameters
    ----------
    value : array_like
        Physical value(s) ``v_current``.
    low, high : float
        Lowest and highest permissible values ``v_low``, ``v_high``.

    Returns
    -------
    np.ndarray
        ``(value - low) / (high - low)``.
    """
    return (np.asarray(value, dtype=float) - low) / (high - low)


def denormalise(x: np.ndarray, low: float, high: float) -> np.ndarray:
    """Inverse of eq. 4: ``v = low + x (high - low)``.

    Parameters
    ----------
    x : array_like
        Normalised design variable(s).
    low, high : float
        Lowest and highest permissible values.

    Returns
    -------
    np.ndarray
        Physical value(s).
    """
    return low + np.asarray(x, dtype=float) * (high - low)


def validate_design(x: np.ndarray, n_vars: int) -> np.ndarray:
    """Check a normalised design (or a batch) and return it as a 2-D float array.

    Parameters
    ----------
    x : array_like
        Shape ``(n_vars,)`` or ``(batch, n_vars)``, normalised variables (eqs. 5, 7).
    n_vars : int
        2 or 4 (section 5.1).

    Returns
    -------
    np.ndarray
        float64 array of shape ``(batch, n_vars)``.

    Raises
    ------
    ValueError
        If ``n_vars`` is not 2 or 4, the shape is wrong, a value is NaN or infinite, or a
        value lies outside ``[X_LOWER, X_UPPER]`` (eqs. 6, 8).  The message names the
        offending design, variable index and value.
    """
    if n_vars not in VARIABLE_NAMES:
        raise ValueError(f'n_vars must be 2 or 4 (paper section 5.1), got {n_vars!r}')
    try:
        arr = np.array(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'design vector is not numeric: {x!r}') from exc
    if arr.ndim == 1:
        arr = arr[np.newaxis, :]
    if arr.ndim != 2 or arr.shape[1] != n_vars:
        raise ValueError(
            f'design must have shape ({n_vars},) or (batch, {n_vars}) for the '
            f'{n_vars}-variable problem {VARIABLE_NAMES[n_vars]}, got shape {np.shape(x)}'
        )
    if arr.shape[0] == 0:
        raise ValueError('design batch is empty')
    names = VARIABLE_NAMES[n_vars]
    bad = ~np.isfinite(arr)
    if bad.any():
        b, i = np.argwhere(bad)[0]
        raise ValueError(f'design {b}: variable x[{i}] ({names[i]}) is not finite: {arr[b, i]!r}')
    out = (arr < X_LOWER) | (arr > X_UPPER)
    if out.any():
        b, i = np.argwhere(out)[0]
        raise ValueError(
            f'design {b}: variable x[{i}] ({names[i]}) = {arr[b, i]!r} is outside the '
            f'bounds [{X_LOWER}, {X_UPPER}] (paper eqs. 6, 8)'
        )
    return arr


def to_physical(x: np.ndarray, n_vars: int | None = None) -> AxleSettings:
    """Convert normalised designs to physical axle settings (inverse of eq. 4).

    Parameters
    ----------
    x : array_like
        Shape ``(n,)`` or ``(batch, n)`` with n = 2 (eq. 5) or 4 (eq. 7).
    n_vars : int, optional
        Expected number of variables; inferred from the last axis when omitted.

    Returns
    -------
    AxleSettings
        Arrays of shape (batch,).  A 2-variable design gives identical front and rear
        settings (eq. 5).

    Raises
    ------
    ValueError
        As :func:`validate_design`.
    """
    if n_vars is None:
        shape = np.shape(x)
        if len(shape) not in (1, 2) or shape[-1] not in VARIABLE_NAMES:
            raise ValueError(
                'design must have shape (n,) or (batch, n) with n = 2 or 4 variables '
                f'(paper eqs. 5, 7), got shape {shape}'
            )
        n_vars = int(shape[-1])
    arr = validate_design(x, n_vars)
    if n_vars == 2:
        dpsf_f = dpsf_r = denormalise(arr[:, 0], *DPSF_RANGE)
        gvol_f = gvol_r = denormalise(arr[:, 1], *GVOL_RANGE_M3)
    else:
        dpsf_f = denormalise(arr[:, 0], *DPSF_RANGE)
        gvol_f = denormalise(arr[:, 1], *GVOL_RANGE_M3)
        dpsf_r = denormalise(arr[:, 2], *DPSF_RANGE)
        gvol_r = denormalise(arr[:, 3], *GVOL_RANGE_M3)
    return AxleSettings(
        dpsf_front=dpsf_f.copy(),
        gas_volume_front_m3=gvol_f.copy(),
        dpsf_rear=dpsf_r.copy(),
        gas_volume_rear_m3=gvol_r.copy(),
    )


def _check_physical(name: str, value: np.ndarray, low: float, high: float) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f'{name} must be a 1-D array over the batch, got shape {arr.shape}')
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f'{name}[{i}] is not finite: {arr[i]!r}')
    out = (arr < low) | (arr > high)
    if out.any():
        i = int(np.argmax(out))
        raise ValueError(
            f'{name}[{i}] = {arr[i]!r} is outside the 4S4 range [{low}, {high}] '
            '(paper section 5.1)'
        )
    return arr


def from_physical(settings: AxleSettings, n_vars: int) -> np.ndarray:
    """Convert physical axle settings to normalised designs, eq. 4.

    Parameters
    ----------
    settings : AxleSettings
        Physical settings, arrays of shape (batch,).
    n_vars : int
        2 (front and rear must then be equal, eq. 5) or 4 (eq. 7).

    Returns
    -------
    np.ndarray
        Shape (batch, n_vars).  Values are not clipped to ``[X_LOWER, X_UPPER]``: the
        physical range end 0.1 maps to x = 0 by eq. 4.

    Raises
    ------
    ValueError
        If n_vars is not 2 or 4, a value is not finite or lies outside the physical
        range, or, for n_vars = 2, front and rear settings differ.
    """
    if n_vars not in VARIABLE_NAMES:
        raise ValueError(f'n_vars must be 2 or 4 (paper section 5.1), got {n_vars!r}')
    df = _check_physical('dpsf_front', settings.dpsf_front, *DPSF_RANGE)
    gf = _check_physical('gas_volume_front_m3', settings.gas_volume_front_m3, *GVOL_RANGE_M3)
    dr = _check_physical('dpsf_rear', settings.dpsf_rear, *DPSF_RANGE)
    gr = _check_physical('gas_volume_rear_m3', settings.gas_volume_rear_m3, *GVOL_RANGE_M3)
    if not (df.shape == gf.shape == dr.shape == gr.shape):
        raise ValueError(
            'AxleSettings arrays must share one batch shape, got '
            f'{df.shape}, {gf.shape}, {dr.shape}, {gr.shape}'
        )
    if n_vars == 2:
        if not (np.array_equal(df, dr) and np.array_equal(gf, gr)):
            raise ValueError(
                'a 2-variable design needs identical front and rear settings (paper eq. 5); '
                'use n_vars=4'
            )
        return np.stack([normalise(df, *DPSF_RANGE), normalise(gf, *GVOL_RANGE_M3)], axis=1)
    return np.stack(
        [
            normalise(df, *DPSF_RANGE),
            normalise(gf, *GVOL_RANGE_M3),
            normalise(dr, *DPSF_RANGE),
            normalise(gr, *GVOL_RANGE_M3),
        ],
        axis=1,
    )


def baseline_design(n_vars: int) -> np.ndarray:
    """The standard vehicle's settings (config/scenarios.yaml) as a normalised design."""
    from suspension_tuning.vehicle.params import load_scenarios_config

    base = load_scenarios_config()['baseline_design']
    gas = float(base['gas_volume_l']) * 1e-3
    settings = AxleSettings(*(np.array([v]) for v in (float(base['dpsf']), gas,
                                                       float(base['dpsf']), gas)))
    return from_physical(settings, n_vars)[0]
