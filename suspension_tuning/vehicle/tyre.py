"""Tyre model: vertical point-contact spring-damper and Pacejka '89 lateral force.

Sign conventions (ISO 8855): y to the left, slip angle ``alpha = atan(v_y / v_x)`` of the
contact-point velocity in wheel axes, so a positive slip angle gives a negative (rightward)
lateral force.  Vertical force is positive pushing the wheel up and never negative.
"""

from __future__ import annotations

import numpy as np

from .params import TyreParams, VehicleParams

X1_CLAMP_DEG = 89.5  # [deg] Chrono ChPac89Tire clamps the shifted slip (physics-ref 8.1) [S]
FZ_MIN_KN = 1.0e-6  # [kN] numerical floor so B = BCD/(C D) stays finite at lift-off


def _coeffs(coeffs: np.ndarray | TyreParams | VehicleParams) -> np.ndarray:
    if isinstance(coeffs, VehicleParams):
        return coeffs.tyre.pacejka
    if isinstance(coeffs, TyreParams):
        return coeffs.pacejka
    a = np.asarray(coeffs, dtype=float)
    if a.shape != (14,):
        raise ValueError(f'Pacejka 89 needs 14 coefficients a0..a13, got shape {a.shape}')
    return a


def pacejka89_lateral(
    slip_angle_rad: np.ndarray,
    fz_n: np.ndarray,
    coeffs: np.ndarray | TyreParams | VehicleParams,
    camber_rad: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Pacejka '89 Magic Formula lateral force [N] (physics-ref 8.1, Bakker et al. 1989).

    Parameters
    ----------
    slip_angle_rad : np.ndarray
        Slip angle [rad], ISO sign.
    fz_n : np.ndarray
        Vertical load [N]; no force when the tyre is off the ground (Fz <= 0).
    coeffs : np.ndarray or TyreParams or VehicleParams
        Coefficients a0..a13 (formula units: Fz kN, alpha deg, Fy N).
    camber_rad : np.ndarray or float
        Camber angle [rad] (0 for the beam axles on a flat road).

    Returns
    -------
    np.ndarray
        Lateral force [N], ISO sign: ``Fy(alpha) = -MF(alpha)``.
    """
    a = _coeffs(coeffs)
    alpha = np.asarray(slip_angle_rad, dtype=float)
    fz = np.asarray(fz_n, dtype=float)
    fzk = np.maximum(fz * 1.0e-3, FZ_MIN_KN)
    gam = np.degrees(camber_rad)
    c = a[0]
    d = a[1] * fzk**2 + a[2] * fzk
    bcd = a[3] * np.sin(2.0 * np.arctan(fzk / a[4])) * (1.0 - a[5] * np.abs(gam))
    b = bcd / (c * d)
    e = a[6] * fzk + a[7]
    sh = a[8] * gam + a[9] * fzk + a[10]
    sv = a[11] * fzk * gam + a[12] * fzk + a[13]
    x1 = np.clip(np.degrees(alpha) + sh, -X1_CLAMP_DEG, X1_CLAMP_DEG)
    bx = b * x1
    fy = d * np.sin(c * np.arctan(bx - e * (bx - np.arctan(bx)))) + sv
    return np.where(fz > 0.0, -fy, 0.0)


def cornering_stiffness_n_per_rad(
    fz_n: np.ndarray | float, coeffs: np.ndarray | TyreParams | VehicleParams
) -> np.ndarray:
    """Cornering stiffness ``BCD`` at zero camber [N/rad] (physics-ref 8.2 check values)."""
    a = _coeffs(coeffs)
    fzk = np.maximum(np.asarray(fz_n, dtype=float) * 1e-3, FZ_MIN_KN)
    return np.degrees(1.0) * a[3] * np.sin(2.0 * np.arctan(fzk / a[4]))


def vertical_force(
    deflection_m: np.ndarray, deflection_rate_mps: np.ndarray, k: float, c: float
) -> np.ndarray:
    """Vertical tyre force [N]: spring-damper in contact, zero off the ground.

    Parameters
    ----------
    deflection_m : np.ndarray
        Tyre deflection [m] (positive compressed, includes the static deflection).
    deflection_rate_mps : np.ndarray
        Deflection rate [m/s].
    k : float
        Vertical stiffness [N/m].
    c : float
        Vertical damping [N s/m].

    Returns
    -------
    np.ndarray
        ``max(0, k d + c d')`` for ``d > 0``, else 0: the tyre never pulls (paper eq. 19).
    """
    d = np.asarray(deflection_m, dtype=float)
    f = k * d + c * np.asarray(deflection_rate_mps, dtype=float)
    return np.where(d > 0.0, np.maximum(f, 0.0), 0.0)
