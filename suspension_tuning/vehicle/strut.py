"""4S4 semi-active hydropneumatic strut: gas spring, damper packs, bump/rebound stops.

Sign conventions: stroke ``x`` is compression positive (axle and body approach), stroke
rate is d(stroke)/dt, and the strut force is positive when it pushes axle and body apart.
The force includes the static load at zero stroke (the static gas volume is the volume at
static equilibrium, physics-reference 3.2).

Gas spring (polytropic, per accumulator).  Each accumulator j holds a fixed gas mass with
``p V_j^n = C_j``.  Write ``K_j = C_j^(1/n) = V_j p^(1/n)``.  Connected accumulators share
one pressure, so the connected gas volume ``V_c = sum_j V_j`` gives the closed form
``p = (sum_connected K_j / V_c)^n``, with ``V_c = V_ref - A_p x``.  A valve switch only
changes ``V_ref`` (and which K_j are summed): a disconnected accumulator keeps its gas
(volume frozen), and on reconnection the pressures equalise isentropically per gas mass,
which is exactly the closed form above with unchanged K_j.

Coil spring.  A design space whose spring is a stiffness (a coil-sprung vehicle run as
an FMU, config/design_space.yaml) gives the simplified models a linear spring
``F = F_s + k x`` in place of the gas spring: the same static load at zero stroke, the
design's rate k.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator

from .params import StrutParams, VehicleParams


def _strut(params: StrutParams | VehicleParams) -> StrutParams:
    return params.strut if isinstance(params, VehicleParams) else params


def static_pressure_pa(
    static_load_n: np.ndarray | float, params: StrutParams | VehicleParams
) -> np.ndarray:
    """Absolute static gas pressure [Pa]: (p - p_atm) A_p = static load (physics-ref 3.2)."""
    sp = _strut(params)
    return np.asarray(static_load_n, dtype=float) / sp.piston_area_m2 + sp.atmospheric_pressure_pa


def gas_pressure_pa(
    k_sum: np.ndarray,
    v_conn_m3: np.ndarray,
    v_static_m3: np.ndarray,
    params: StrutParams | VehicleParams,
) -> np.ndarray:
    """Absolute pressure of the connected gas [Pa] from ``p = (K / V)^n``.

    Parameters
    ----------
    k_sum : np.ndarray
        Sum of ``K_j = V_j p_j^(1/n)`` over the connected accumulators.
    v_conn_m3 : np.ndarray
        Connected gas volume [m^3] (may be below the guard volume).
    v_static_m3 : np.ndarray
        Static volume of the connected accumulators [m^3], sets the guard volume.
    params : StrutParams or VehicleParams
        Strut parameters.

    Returns
    -------
    np.ndarray
        Pressure [Pa]; below ``min_volume_fraction * v_static`` it continues linearly (C1)
        as a numerical guard against gas collapse.
    """
    sp = _strut(params)
    n = sp.polytropic_exponent
    v_min = sp.min_volume_fraction * np.asarray(v_static_m3, dtype=float)
    v = np.maximum(v_conn_m3, v_min)
    p = (k_sum / v) ** n
    below = np.minimum(v_conn_m3 - v_min, 0.0)
    return p - n * p / v * below


def gas_force_n(
    stroke_m: np.ndarray,
    gas_volume_m3: np.ndarray,
    static_load_n: np.ndarray,
    params: StrutParams | VehicleParams,
) -> np.ndarray:
    """Gas-spring force of one strut with a single connected gas volume [N].

    ``F = (p(x) - p_atm) A_p`` with ``p(x) = p_s (V_s / (V_s - A_p x))^n`` (physics-ref 3.2).
    """
    sp = _strut(params)
    p_s = static_pressure_pa(static_load_n, sp)
    v_s = np.asarray(gas_volume_m3, dtype=float)
    k = v_s * p_s ** (1.0 / sp.polytropic_exponent)
    p = gas_pressure_pa(k, v_s - sp.piston_area_m2 * np.asarray(stroke_m), v_s, sp)
    return (p - sp.atmospheric_pressure_pa) * sp.piston_area_m2


def gas_stiffness_n_per_m(
    gas_volume_m3: np.ndarray | float,
    static_load_n: np.ndarray | float,
    params: StrutParams | VehicleParams,
) -> np.ndarray:
    """Return the static tangent stiffness of the gas spring ``k = n p_s A_p^2 / V_s`` [N/m]."""
    sp = _strut(params)
    p_s = static_pressure_pa(static_load_n, sp)
    return sp.polytropic_exponent * p_s * sp.piston_area_m2**2 / np.asarray(gas_volume_m3)


def coil_force_n(
    stroke_m: np.ndarray, stiffness_n_per_m: np.ndarray, static_load_n: np.ndarray
) -> np.ndarray:
    """Linear (coil) spring force of one strut [N]: ``F = F_s + k x``, compression positive."""
    return np.asarray(static_load_n, dtype=float) + np.asarray(stiffness_n_per_m) * np.asarray(
        stroke_m, dtype=float)


def damper_knot_slopes(params: StrutParams | VehicleParams) -> np.ndarray:
    """PCHIP slopes at the damper-table knots [N s/m] (shared with the compiled kernel)."""
    sp = _strut(params)
    return PchipInterpolator(sp.damper_velocity_mps, sp.damper_force_n).derivative()(
        sp.damper_velocity_mps
    )


def hermite_eval(
    v: np.ndarray, knots: np.ndarray, values: np.ndarray, slopes: np.ndarray
) -> np.ndarray:
    """Cubic Hermite interpolation with linear extrapolation (C1 everywhere)."""
    v = np.asarray(v, dtype=float)
    idx = np.clip(np.searchsorted(knots, v) - 1, 0, knots.size - 2)
    x0, x1 = knots[idx], knots[idx + 1]
    h = x1 - x0
    t = (v - x0) / h
    t2, t3 = t * t, t * t * t
    f = (
        (2 * t3 - 3 * t2 + 1) * values[idx]
        + (t3 - 2 * t2 + t) * h * slopes[idx]
        + (-2 * t3 + 3 * t2) * values[idx + 1]
        + (t3 - t2) * h * slopes[idx + 1]
    )
    lo, hi = v < knots[0], v > knots[-1]
    f = np.where(lo, values[0] + slopes[0] * (v - knots[0]), f)
    return np.where(hi, values[-1] + slopes[-1] * (v - knots[-1]), f)


def damper_force_n(
    stroke_rate_mps: np.ndarray, dpsf: np.ndarray | float, params: StrutParams | VehicleParams,
    dpsf_rebound: np.ndarray | float | None = None,
) -> np.ndarray:
    """Damper force [N], positive pushing apart: ``dpsf x`` standard rear characteristic.

    The table is in extension-positive / tension-positive form, so the strut force is
    ``-dpsf F_table(-stroke_rate)`` (paper section 5.1: the shape and switch velocities are
    kept, only the scale factor changes).  With ``dpsf_rebound`` the two halves of the
    table scale apart: ``dpsf`` in compression (stroke rate > 0), ``dpsf_rebound`` in
    rebound (the force is zero at zero rate, so the characteristic stays continuous).
    """
    if dpsf_rebound is not None:
        rate = np.asarray(stroke_rate_mps, dtype=float)
        dpsf = np.where(rate > 0.0, dpsf, dpsf_rebound)
    sp = _strut(params)
    f = hermite_eval(
        -np.asarray(stroke_rate_mps, dtype=float),
        sp.damper_velocity_mps,
        sp.damper_force_n,
        damper_knot_slopes(sp),
    )
    return -np.asarray(dpsf) * f


def _smooth_penetration(delta: np.ndarray, s: float) -> np.ndarray:
    """C1 ramp: 0 for delta<0, delta^2/(2s) on [0, s], delta - s/2 beyond."""
    d = np.maximum(delta, 0.0)
    return np.where(d < s, d * d / (2.0 * s), d - 0.5 * s)


def stop_force_n(stroke_m: np.ndarray, params: StrutParams | VehicleParams) -> np.ndarray:
    """Bump (compression) and rebound stop force [N], positive pushing apart.

    ``F = k d + k3 d^3`` of the smoothed penetration d (physics-ref 3.4).
    """
    sp = _strut(params)
    x = np.asarray(stroke_m, dtype=float)
    db = _smooth_penetration(x - sp.bump_clearance_m, sp.bump_smoothing_m)
    dr = _smooth_penetration(-x - sp.rebound_clearance_m, sp.rebound_smoothing_m)
    fb = sp.bump_stiffness_n_per_m * db + sp.bump_cubic_n_per_m3 * db**3
    fr = sp.rebound_stiffness_n_per_m * dr + sp.rebound_cubic_n_per_m3 * dr**3
    return fb - fr


def strut_force(
    stroke_m: np.ndarray,
    stroke_rate_mps: np.ndarray,
    gas_volume_m3: np.ndarray,
    dpsf: np.ndarray,
    static_load_n: np.ndarray,
    params: StrutParams | VehicleParams,
    stiffness_n_per_m: np.ndarray | None = None,
    dpsf_rebound: np.ndarray | None = None,
) -> np.ndarray:
    """Total 4S4 strut force [N] for one connected gas volume and one damper scale.

    Parameters
    ----------
    stroke_m : np.ndarray
        Compression from static equilibrium [m] (compression positive).
    stroke_rate_mps : np.ndarray
        Compression rate [m/s].
    gas_volume_m3 : np.ndarray
        Static gas volume of the connected accumulator(s) [m^3] (design variable gvol,
        paper section 5.1 / eq. 5).
    dpsf : np.ndarray
        Damper force scale factor [-] (paper section 5.1 / eq. 5).
    static_load_n : np.ndarray
        Static strut load [N]; the force equals it at zero stroke and rate.
    params : StrutParams or VehicleParams
        Strut parameters.
    stiffness_n_per_m : np.ndarray, optional
        A coil spring's rate [N/m]: the spring is then linear (:func:`coil_force_n`) and
        ``gas_volume_m3`` is not used.
    dpsf_rebound : np.ndarray, optional
        Scale factor of the rebound half of the damper table (default ``dpsf``).

    Returns
    -------
    np.ndarray
        Force [N], positive pushing axle and body apart (broadcast shape of the inputs).
    """
    spring = (gas_force_n(stroke_m, gas_volume_m3, static_load_n, params)
              if stiffness_n_per_m is None
              else coil_force_n(stroke_m, stiffness_n_per_m, static_load_n))
    return (
        spring
        + damper_force_n(stroke_rate_mps, dpsf, params, dpsf_rebound)
        + stop_force_n(stroke_m, params)
    )


def accumulator_constants(
    gas_volume_soft_m3: np.ndarray,
    gas_volume_stiff_m3: np.ndarray,
    static_load_n: np.ndarray,
    params: StrutParams | VehicleParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Gas constants ``K_j = V_j p_s^(1/n)`` of the small (stiff) and large accumulators.

    The stiff state connects the small accumulator alone (volume ``gas_volume_stiff``), the
    soft state connects both (``gas_volume_soft``), all at the static pressure.  A soft
    volume below the stiff one is not possible (the large accumulator would be negative);
    the large accumulator is then empty (K=0) and the strut has one state.

    Returns
    -------
    (K_small, K_large) : tuple of np.ndarray
        In m^3 Pa^(1/n).
    """
    sp = _strut(params)
    p_s = static_pressure_pa(static_load_n, sp)
    root = p_s ** (1.0 / sp.polytropic_exponent)
    v1 = np.minimum(gas_volume_stiff_m3, gas_volume_soft_m3)
    v2 = np.asarray(gas_volume_soft_m3) - v1
    return v1 * root, v2 * root
