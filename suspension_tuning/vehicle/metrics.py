"""Objective and constraint functions of Thoresson et al. 2009, Part 1 (eqs. 9-11).

* :func:`f_ride` - eq. 9, scaled BS 6841 weighted RMS vertical accelerations.
* :func:`f_hand` - eq. 10, scaled RMS roll velocity and first peak roll angle.
* :func:`objective_scaling` - the reference values of eqs. 9 and 10 from
  config/scenarios.yaml (the paper's by default).
* :func:`tyre_hop_constraints` - eq. 11, fraction of time each tyre is off the ground.
* :func:`soft_tyre_hop_constraints` - a measure of tyre hop that is smooth in the
  design, for gradients only (a departure from the paper, see its docstring).
* :func:`first_peak`, :func:`rms`, :func:`roll_rate_rms` - the signal metrics they use.

Every function broadcasts over leading (batch) axes; time runs along the last axis.
"""

from __future__ import annotations

import numpy as np

FZ_CONTACT_THRESHOLD_N = 1e-3
"""Default threshold for "Fz == 0" in eq. 11, N [E].

The tyre model clips its force at exactly 0 N when the tyre leaves the ground, so any
threshold far below the static wheel load (~5 kN) and far above float round-off of a
force of that size (5e3 N * 2.2e-16 ~ 1e-12 N) counts the same samples; 1 mN is 6-7
orders of magnitude below the static load.
"""

FIRST_PEAK_MIN_FRACTION = 0.5
"""Default: a local maximum of |roll| counts as the first peak only if it reaches this
fraction of the largest |roll| in the window [E].  It rejects ripples (tyre and body
vibration, numerical noise) before the main roll swing of the first lane change."""


def rms(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Return the root mean square along an axis.

    Parameters
    ----------
    x : array_like
        Signal, uniformly sampled along ``axis``.
    axis : int
        Time axis (default last).

    Returns
    -------
    np.ndarray
        ``sqrt(mean(x**2))``, same units as ``x``.
    """
    arr = np.asarray(x, dtype=float)
    if arr.shape[axis] == 0:
        raise ValueError('rms of an empty signal')
    return np.sqrt(np.mean(arr * arr, axis=axis))


def _window_mask(t_s: np.ndarray, t_window: tuple | None, shape: tuple) -> np.ndarray:
    t = np.asarray(t_s, dtype=float)
    if t.shape[-1] != shape[-1]:
        raise ValueError(
            f't_s has {t.shape[-1]} samples but the signal has {shape[-1]} along its last axis'
        )
    if t_window is None:
        return np.broadcast_to(np.ones(t.shape, dtype=bool), shape)
    t0 = np.asarray(t_window[0], dtype=float)[..., np.newaxis]
    t1 = np.asarray(t_window[1], dtype=float)[..., np.newaxis]
    if np.any(t1 <= t0):
        raise ValueError(f't_window end must be after its start, got {t_window}')
    mask = np.broadcast_to((t >= t0) & (t <= t1), shape)
    if not np.all(mask.any(axis=-1)):
        raise ValueError(f't_window {t_window} contains no samples of t_s')
    return mask


def roll_rate_rms(
    roll_rate: np.ndarray, t_s: np.ndarray | None = None, t_window: tuple | None = None
) -> np.ndarray:
    """Return the RMS roll velocity over the manoeuvre (input of eq. 10).

    Parameters
    ----------
    roll_rate : array_like
        Roll rate history, shape (..., n_samples), uniformly sampled (any unit; the
        result has the same unit: pass deg/s to feed :func:`f_hand`).
    t_s : array_like, optional
        Sample times in s, shape (n_samples,) or broadcastable to ``roll_rate``.
    t_window : (float, float), optional
        Start and end time in s of the averaging window (inclusive); scalars or arrays
        broadcastable to the batch shape.  Whole record when omitted.

    Returns
    -------
    np.ndarray
        RMS over the window, shape (...).
    """
    p = np.asarray(roll_rate, dtype=float)
    if t_window is None:
        return rms(p)
    if t_s is None:
        raise ValueError('t_window needs t_s')
    mask = _window_mask(t_s, t_window, p.shape)
    return np.sqrt(np.sum(np.where(mask, p * p, 0.0), axis=-1) / np.sum(mask, axis=-1))


def first_peak(
    roll_deg: np.ndarray,
    t_s: np.ndarray,
    t_window: tuple,
    min_fraction: float = FIRST_PEAK_MIN_FRACTION,
) -> np.ndarray:
    """Return the first peak of |roll| during the first lane change (input of eq. 10).

    Within ``t_window`` the first local maximum of ``|roll|`` that reaches
    ``min_fraction`` times the largest ``|roll|`` in the window is returned.  If the
    window contains no such interior local maximum (``|roll|`` still rising at the end
    of the window) the largest ``|roll|`` in the window is returned.

    Parameters
    ----------
    roll_deg : array_like
        Body roll angle in deg, shape (..., n_samples).
    t_s : array_like
        Sample times in s, shape (n_samples,) or broadcastable to ``roll_deg``.
    t_window : (float, float)
        Start and end of the first lane change in s (scalars or arrays broadcastable to
        the batch shape).
    min_fraction : float
        Significance threshold, see :data:`FIRST_PEAK_MIN_FRACTION`.

    Returns
    -------
    np.ndarray
        First peak |roll| in deg, shape (...).
    """
    if not 0.0 <= min_fraction <= 1.0:
        raise ValueError(f'min_fraction must lie in [0, 1], got {min_fraction}')
    a = np.abs(np.asarray(roll_deg, dtype=float))
    if a.shape[-1] < 3:
        raise ValueError('first_peak needs at least 3 samples')
    if not np.all(np.isfinite(a)):
        raise ValueError('roll_deg contains NaN or inf')
    mask = _window_mask(t_s, t_window, a.shape)
    aw = np.where(mask, a, -np.inf)
    peak_max = np.max(aw, axis=-1)
    local = np.zeros(a.shape, dtype=bool)
    # interior local maxima inside the window (plateaus count at their first sample)
    local[..., 1:-1] = (aw[..., 1:-1] > aw[..., :-2]) & (aw[..., 1:-1] >= aw[..., 2:])
    local &= mask & (aw >= min_fraction * peak_max[..., np.newaxis])
    # a maximum on the window's last sample is not a completed peak
    last = a.shape[-1] - 1 - np.argmax(mask[..., ::-1], axis=-1)
    np.put_along_axis(local, last[..., np.newaxis], False, axis=-1)
    has = local.any(axis=-1)
    idx = np.argmax(local, axis=-1)
    first = np.take_along_axis(a, idx[..., np.newaxis], axis=-1)[..., 0]
    return np.where(has, first, peak_max)


def objective_scaling(scenario: str) -> dict[str, float]:
    """The reference values that normalise eq. 9 ('ride') or eq. 10 ('handling').

    From config/scenarios.yaml ``<scenario>.objective_scaling`` (the paper's values:
    0.7 and 4.4 m/s^2 for eq. 9; 0.8-5.7 deg/s and 1.4-12.2 deg for eq. 10), as the
    keyword arguments of :func:`f_ride` or :func:`f_hand`.

    Raises
    ------
    ValueError
        A missing or non-numeric value (the message names the key).
    """
    from .params import load_scenarios_config

    keys = {'ride': ('a_min_mps2', 'a_max_mps2'),
            'handling': ('roll_rate_min_deg_s', 'roll_rate_max_deg_s', 'roll_peak_min_deg',
                         'roll_peak_max_deg')}[scenario]
    section = (load_scenarios_config().get(scenario) or {}).get('objective_scaling') or {}
    out = {}
    for key in keys:
        value = section.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f'config/scenarios.yaml {scenario}.objective_scaling.{key}: '
                             f'expected a number, got {value!r}')
        out[key] = float(value)
    return out


def f_ride(
    a_rms_driver_mps2: np.ndarray,
    a_rms_passenger_mps2: np.ndarray,
    a_min: float | None = None,
    a_max: float | None = None,
) -> np.ndarray:
    """Compute the ride comfort objective, eq. 9.

    ``f_ride = ((a_d - a_min)/(a_max - a_min) + (a_p - a_min)/(a_max - a_min)) / 2``.

    Parameters
    ----------
    a_rms_driver_mps2, a_rms_passenger_mps2 : array_like
        BS 6841 W_b weighted RMS vertical accelerations in m/s^2 (driver, passenger).
    a_min, a_max : float, optional
        Scaling range in m/s^2; default config/scenarios.yaml ``ride.objective_scaling``
        (the paper's corner values 0.7 and 4.4 [P]).

    Returns
    -------
    np.ndarray
        Scaled objective (0 at a_min, 1 at a_max).
    """
    if a_min is None or a_max is None:
        scaling = objective_scaling('ride')
        a_min = scaling['a_min_mps2'] if a_min is None else a_min
        a_max = scaling['a_max_mps2'] if a_max is None else a_max
    if a_max <= a_min:
        raise ValueError(f'a_max ({a_max}) must exceed a_min ({a_min})')
    ad = np.asarray(a_rms_driver_mps2, dtype=float)
    ap = np.asarray(a_rms_passenger_mps2, dtype=float)
    span = a_max - a_min
    return ((ad - a_min) / span + (ap - a_min) / span) / 2.0


def f_hand(
    roll_rate_rms_deg_s: np.ndarray,
    roll_first_peak_deg: np.ndarray,
    rate_min_deg_s: float | None = None,
    rate_max_deg_s: float | None = None,
    peak_min_deg: float | None = None,
    peak_max_deg: float | None = None,
) -> np.ndarray:
    """Compute the handling objective, eq. 10.

    ``f_hand = ((r - 0.8) 0.9/(5.7 - 0.8) + 0.1 + (p - 1.4) 0.9/(12.2 - 1.4) + 0.1) / 2``
    (the paper's ranges) with r the RMS roll velocity (deg/s) and p the first peak roll
    angle (deg).  Each term is 0.1 at its minimum and 1.0 at its maximum.

    Parameters
    ----------
    roll_rate_rms_deg_s : array_like
        RMS roll velocity over the whole double lane change, deg/s.
    roll_first_peak_deg : array_like
        First peak roll angle in the first lane change, deg.
    rate_min_deg_s, rate_max_deg_s, peak_min_deg, peak_max_deg : float, optional
        Scaling ranges; default config/scenarios.yaml ``handling.objective_scaling``
        (the paper's 0.8, 5.7, 1.4 and 12.2 [P eq. 10]).

    Returns
    -------
    np.ndarray
        Scaled objective.
    """
    if None in (rate_min_deg_s, rate_max_deg_s, peak_min_deg, peak_max_deg):
        scaling = objective_scaling('handling')
        rate_min_deg_s = scaling['roll_rate_min_deg_s'] if rate_min_deg_s is None \
            else rate_min_deg_s
        rate_max_deg_s = scaling['roll_rate_max_deg_s'] if rate_max_deg_s is None \
            else rate_max_deg_s
        peak_min_deg = scaling['roll_peak_min_deg'] if peak_min_deg is None else peak_min_deg
        peak_max_deg = scaling['roll_peak_max_deg'] if peak_max_deg is None else peak_max_deg
    if rate_max_deg_s <= rate_min_deg_s or peak_max_deg <= peak_min_deg:
        raise ValueError('f_hand scaling ranges must have max > min')
    r = np.asarray(roll_rate_rms_deg_s, dtype=float)
    p = np.asarray(roll_first_peak_deg, dtype=float)
    term_r = (r - rate_min_deg_s) * 0.9 / (rate_max_deg_s - rate_min_deg_s) + 0.1
    term_p = (p - peak_min_deg) * 0.9 / (peak_max_deg - peak_min_deg) + 0.1
    return (term_r + term_p) / 2.0


#: Permitted fraction of time a tyre is off the ground, eq. 11 [P section 5.3].
TYRE_HOP_MAX_FRACTION = 0.1


def tyre_hop_constraints(
    fz_n: np.ndarray,
    dt_s: float | np.ndarray,
    fz_threshold_n: float = FZ_CONTACT_THRESHOLD_N,
    max_fraction: float = TYRE_HOP_MAX_FRACTION,
) -> np.ndarray:
    """Compute the tyre hop constraints, eq. 11: ``g_i = 10 (t(Fz_i = 0)/t_total - 0.1) <= 0``.

    Parameters
    ----------
    fz_n : array_like
        Tyre vertical forces in N, shape (..., n_tyres, n_samples).
    dt_s : float or array_like
        Sample interval in s (uniform sampling), or per-sample durations of shape
        (n_samples,) for non-uniform sampling (each sample weighted by its duration).
    fz_threshold_n : float
        A tyre counts as off the ground when ``Fz <= fz_threshold_n``; see
        :data:`FZ_CONTACT_THRESHOLD_N`.
    max_fraction : float
        Permitted fraction of time off the ground, 0.1 [P section 5.3].

    Returns
    -------
    np.ndarray
        Constraint values, shape (..., n_tyres); <= 0 is feasible.
    """
    fz = np.asarray(fz_n, dtype=float)
    if fz.ndim < 2:
        raise ValueError(f'fz_n must have shape (..., n_tyres, n_samples), got {fz.shape}')
    if fz.shape[-1] == 0:
        raise ValueError('fz_n has no samples')
    if np.any(np.isnan(fz)):
        raise ValueError('fz_n contains NaN')
    w = np.broadcast_to(np.asarray(dt_s, dtype=float), (fz.shape[-1],))
    if np.any(~np.isfinite(w)) or np.any(w <= 0):
        raise ValueError('dt_s must be positive and finite')
    off = fz <= fz_threshold_n
    fraction = np.sum(off * w, axis=-1) / np.sum(w)
    return 10.0 * (fraction - max_fraction)


def soft_tyre_hop_constraints(
    fz_n: np.ndarray,
    static_load_n: np.ndarray,
    load_fraction: float,
    max_fraction: float = TYRE_HOP_MAX_FRACTION,
) -> np.ndarray:
    """A tyre-hop measure that is smooth in the design: eq. 11 with a soft count.

    ``g_i = 10 (mean_t clip(1 - Fz_i / w_i, 0, 1) - 0.1)`` with ``w_i = load_fraction x
    static wheel load``.  A sample with the tyre off the ground (Fz = 0) counts 1, as in
    eq. 11; a sample whose load has fallen below w counts the fraction of w lost, and
    one above w counts 0.  Each sample's Fz changes continuously with the design, so
    this measure does too, where eq. 11 (a count of 2 ms samples) is a staircase: along
    the rear damping, 61.5 % of 1e-4 steps leave the full model's eq. 11 unchanged and
    one that does not changes it by 7.4e-4; along the rear gas volume 91.5 % (full
    model) and 99 % (pitch-plane model) of such steps change nothing.

    A departure from the paper, used only for the simplified models' gradients: the
    constraint values still come from the full model's eq. 11.  Eq. 25 maps the
    measure onto the full model's eq. 11 range like any other simplified value.

    Parameters
    ----------
    fz_n : array_like
        Tyre vertical forces in N, shape (..., n_tyres, n_samples), uniformly sampled.
    static_load_n : array_like
        Static load of each tyre in N, shape (n_tyres,).
    load_fraction : float
        w as a fraction of the static load, in (0, 1].
    max_fraction : float
        Permitted fraction, 0.1 [P section 5.3] (as eq. 11).

    Returns
    -------
    np.ndarray
        Shape (..., n_tyres); > 0 where the soft fraction exceeds ``max_fraction``.
    """
    fz = np.asarray(fz_n, dtype=float)
    if fz.ndim < 2 or fz.shape[-1] == 0:
        raise ValueError(f'fz_n must have shape (..., n_tyres, n_samples), got {fz.shape}')
    if not 0.0 < load_fraction <= 1.0:
        raise ValueError(f'load_fraction must lie in (0, 1], got {load_fraction}')
    w = load_fraction * np.asarray(static_load_n, dtype=float)
    if w.shape != (fz.shape[-2],) or np.any(~(w > 0)):
        raise ValueError(f'static_load_n must hold {fz.shape[-2]} positive loads, got '
                         f'{static_load_n}')
    soft = np.clip(1.0 - fz / w[:, None], 0.0, 1.0)
    return 10.0 * (soft.mean(axis=-1) - max_fraction)
