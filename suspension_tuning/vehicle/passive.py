"""Passive and switched 4S4 settings: what the ride-handling comparison runs.

The paper's case for the 4S4 (section 3): a suspension that switches between a ride
setting (soft spring, low damping) and a handling setting (stiff spring, high damping)
"has the ability to eliminate the traditional ride comfort vs. handling compromise".
Measuring that needs the suspension it is compared against, defined in our model:

* **Passive**: one gas volume and one damper characteristic per axle, the same in every
  situation.  In the 4S4 model that is the setting whose two spring states have the
  same gas volume (the large accumulator empty: ``gas_volume_soft = gas_volume_stiff =
  V``) and whose two damper states have the same scale factor (``dpsf_low = dpsf_high
  = d``).  Every valve state then gives the same strut force (the gas constant of the
  empty accumulator is zero, so connecting it changes neither the connected volume nor
  the pressure), so no valve switch can change anything: the valves may stay in the
  ride state throughout.  The design (V, d) spans the same ranges as either optimised
  state (eqs. 4-8, 0.1-0.6 L, dpsf 0.1-3) with the same damper table, so the passive
  suspension has exactly the freedom of one 4S4 state.
* **Switched**: the ride state set by one design (soft gas volume and low-damping
  dpsf) and the handling state by another (stiff gas volume and high-damping dpsf).

Because the 'ride' scenario runs in the ride state and uses only the soft volume and
the low dpsf, and the 'handling' scenario runs in the handling state and uses only
the stiff volume and the high dpsf (``SuspensionSetting.from_design``), a passive
design x has f_ride(x) of the 'ride' scenario and f_hand(x) of the 'handling' scenario
at the same x: the passive Pareto front is that of the two scenario objectives over
one shared design (checked against runs with :func:`passive_setting` in the tests).
"""

from __future__ import annotations

import numpy as np

from suspension_tuning.vehicle import design
from suspension_tuning.vehicle.full_model import SuspensionSetting


def _axles(x: np.ndarray, n_vars: int | None) -> tuple[np.ndarray, np.ndarray]:
    n = int(np.shape(x)[-1]) if n_vars is None else n_vars
    phys = design.to_physical(design.validate_design(x, n), n)
    if phys.spring_quantity != 'volume':
        raise ValueError('passive and switched 4S4 settings need gas springs; the design '
                         'space (config/design_space.yaml) has a spring stiffness')
    dpsf = np.stack([phys.dpsf_front, phys.dpsf_rear], axis=1)
    gvol = np.stack([phys.gas_volume_front_m3, phys.gas_volume_rear_m3], axis=1)
    return dpsf, gvol


def passive_setting(x: np.ndarray, n_vars: int | None = None) -> SuspensionSetting:
    """The passive suspension of normalised design(s) x: one volume, one damper per axle.

    Parameters
    ----------
    x : ndarray, shape (n_vars,) or (batch, n_vars)
        Normalised designs (eqs. 4-8).
    n_vars : int, optional
        2 or 4 (default: the length of x's last axis).

    Returns
    -------
    SuspensionSetting
        ``gas_volume_soft = gas_volume_stiff`` and ``dpsf_low = dpsf_high`` per axle.
    """
    dpsf, gvol = _axles(x, n_vars)
    return SuspensionSetting(gvol, gvol.copy(), dpsf, dpsf.copy())


def switched_setting(x_ride: np.ndarray, x_handling: np.ndarray, n_vars: int | None = None
                     ) -> tuple[SuspensionSetting, np.ndarray]:
    """The 4S4 with its ride state from ``x_ride`` and its handling state from ``x_handling``.

    The stiff spring is the small accumulator alone, so its gas volume cannot exceed the
    soft one (both accumulators); a handling volume above the ride volume is capped at
    it, as ``SuspensionSetting.from_design`` caps the states it does not optimise.

    Parameters
    ----------
    x_ride, x_handling : ndarray, shape (n_vars,) or (batch, n_vars)
        Normalised designs (eqs. 4-8) of the two states.
    n_vars : int, optional
        2 or 4.

    Returns
    -------
    (SuspensionSetting, ndarray)
        The settings and, per design and axle (batch, 2), whether the stiff volume was
        capped.
    """
    dpsf_r, gvol_r = _axles(x_ride, n_vars)
    dpsf_h, gvol_h = _axles(x_handling, n_vars)
    if gvol_r.shape != gvol_h.shape:
        raise ValueError(f'ride and handling designs differ in shape: {gvol_r.shape} and '
                         f'{gvol_h.shape}')
    capped = gvol_h > gvol_r
    return SuspensionSetting(gvol_r, np.minimum(gvol_h, gvol_r), dpsf_r, dpsf_h), capped

