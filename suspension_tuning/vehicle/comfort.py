"""BS 6841 (1987) W_b frequency weighting for vertical seat acceleration.

Used by the ride objective, paper eq. 9.  The transfer function is the product of a
band limit (second-order high-pass at f1 and low-pass at f2, Q = 1/sqrt(2)), an
acceleration-velocity transition and an upward step (physics-reference section 5.1):

    H_h = s^2 / (s^2 + w1 s/Q1 + w1^2)
    H_l = w2^2 / (s^2 + w2 s/Q2 + w2^2)
    H_t = (1 + s/w3) / (1 + s/(Q4 w4) + s^2/w4^2)
    H_s = K (1 + s/(Q5 w5) + s^2/w5^2) / (1 + s/(Q6 w6) + s^2/w6^2)
    W   = H_h H_l H_t H_s

The ISO 2631-1 W_k weighting has the same structure and is offered as an optional extra
metric (and to validate the code path against the ISO 2631-1 table).

The digital filter is the bilinear transform of the analogue one, as second-order
sections.  Its gain error grows with f/fs (frequency warping): at fs = 1 kHz it is below
0.1 dB up to 63 Hz; pass ``prewarp_hz`` to match the gain exactly at one frequency, or
use a higher sample rate.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import signal


@dataclass(frozen=True)
class WeightingParameters:
    """Parameters of a BS 6841 / ISO 2631 frequency weighting (frequencies in Hz)."""

    f1_hz: float
    f2_hz: float
    f3_hz: float
    f4_hz: float
    q4: float
    f5_hz: float
    q5: float
    f6_hz: float
    q6: float
    gain_k: float
    q1: float = 1.0 / np.sqrt(2.0)
    q2: float = 1.0 / np.sqrt(2.0)


WB = WeightingParameters(
    f1_hz=0.4,
    f2_hz=100.0,
    f3_hz=16.0,
    f4_hz=16.0,
    q4=0.55,
    f5_hz=2.5,
    q5=0.90,
    f6_hz=4.0,
    q6=0.95,
    gain_k=0.4,
)
"""BS 6841 W_b, seat vertical [S: physics-reference 5.1, from the cseats
bs6841freqweight.m and HVLab hvweighting.m sources, which agree]."""

WK = WeightingParameters(
    f1_hz=0.4,
    f2_hz=100.0,
    f3_hz=12.5,
    f4_hz=12.5,
    q4=0.63,
    f5_hz=2.37,
    q5=0.91,
    f6_hz=3.35,
    q6=0.91,
    gain_k=(2.37 / 3.35) ** 2,
)
"""ISO 2631-1:1997 W_k, vertical [S: physics-reference 5.1]; K = (f5/f6)^2 gives unit
high-frequency gain of the step term."""

WEIGHTINGS = {'Wb': WB, 'Wk': WK}


def _params(weighting: str | WeightingParameters) -> WeightingParameters:
    if isinstance(weighting, WeightingParameters):
        return weighting
    try:
        return WEIGHTINGS[weighting]
    except KeyError:
        raise ValueError(
            f'unknown weighting {weighting!r}; choose one of {sorted(WEIGHTINGS)}'
        ) from None


def analogue_tf(weighting: str | WeightingParameters = 'Wb') -> tuple[np.ndarray, np.ndarray]:
    """Return the analogue transfer function ``(b, a)`` in s (rad/s) of a weighting.

    Parameters
    ----------
    weighting : str or WeightingParameters
        'Wb' (BS 6841, default) or 'Wk' (ISO 2631-1), or explicit parameters.

    Returns
    -------
    (np.ndarray, np.ndarray)
        Numerator and denominator polynomial coefficients, highest power first.
    """
    p = _params(weighting)
    w1, w2, w3, w4, w5, w6 = (
        2.0 * np.pi * f for f in (p.f1_hz, p.f2_hz, p.f3_hz, p.f4_hz, p.f5_hz, p.f6_hz)
    )
    num = [
        [1.0, 0.0, 0.0],  # H_h numerator s^2
        [w2**2],  # H_l numerator
        [1.0 / w3, 1.0],  # H_t numerator 1 + s/w3
        [p.gain_k / w5**2, p.gain_k / (p.q5 * w5), p.gain_k],  # K (1 + s/(Q5 w5) + s^2/w5^2)
    ]
    den = [
        [1.0, w1 / p.q1, w1**2],
        [1.0, w2 / p.q2, w2**2],
        [1.0 / w4**2, 1.0 / (p.q4 * w4), 1.0],
        [1.0 / w6**2, 1.0 / (p.q6 * w6), 1.0],
    ]
    b = np.array([1.0])
    a = np.array([1.0])
    for nb in num:
        b = np.polymul(b, nb)
    for na in den:
        a = np.polymul(a, na)
    return b, a


def wb_analogue_gain(f_hz: np.ndarray, weighting: str | WeightingParameters = 'Wb') -> np.ndarray:
    """Return ``|W(j 2 pi f)|`` of the analogue weighting (BS 6841 W_b by default).

    Parameters
    ----------
    f_hz : array_like
        Frequencies in Hz (any shape).
    weighting : str or WeightingParameters
        'Wb' (default) or 'Wk'.

    Returns
    -------
    np.ndarray
        Gain magnitude, dimensionless, same shape as ``f_hz``.
    """
    p = _params(weighting)
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    w1, w2, w3, w4, w5, w6 = (
        2.0 * np.pi * f for f in (p.f1_hz, p.f2_hz, p.f3_hz, p.f4_hz, p.f5_hz, p.f6_hz)
    )
    h_h = s**2 / (s**2 + w1 * s / p.q1 + w1**2)
    h_l = w2**2 / (s**2 + w2 * s / p.q2 + w2**2)
    h_t = (1 + s / w3) / (1 + s / (p.q4 * w4) + s**2 / w4**2)
    h_s = p.gain_k * (1 + s / (p.q5 * w5) + s**2 / w5**2) / (1 + s / (p.q6 * w6) + s**2 / w6**2)
    return np.abs(h_h * h_l * h_t * h_s)


def wb_sos(
    fs_hz: float,
    prewarp_hz: float | None = None,
    weighting: str | WeightingParameters = 'Wb',
) -> np.ndarray:
    """Return the digital weighting filter as second-order sections (bilinear transform).

    Parameters
    ----------
    fs_hz : float
        Sample rate in Hz.  Must exceed twice the 100 Hz band-limit frequency f2 so that
        the band limit is represented (>= 500 Hz recommended, 1 kHz preferred).
    prewarp_hz : float, optional
        If given, the bilinear transform is pre-warped so the digital gain equals the
        analogue gain exactly at this frequency (must be below fs/2).
    weighting : str or WeightingParameters
        'Wb' (default) or 'Wk'.

    Returns
    -------
    np.ndarray
        SOS array of shape (n_sections, 6) for :func:`scipy.signal.sosfilt` (a copy of
        a design cached per (fs, prewarp, weighting): every full-model and simplified
        run weights its seat accelerations with the same filter).
    """
    return _wb_sos_cached(float(fs_hz), None if prewarp_hz is None else float(prewarp_hz),
                          weighting).copy()


@functools.lru_cache(maxsize=32)
def _wb_sos_cached(fs_hz: float, prewarp_hz: float | None,
                   weighting: str | WeightingParameters) -> np.ndarray:
    p = _params(weighting)
    if not np.isfinite(fs_hz) or fs_hz <= 2.0 * p.f2_hz:
        raise ValueError(
            f'fs_hz must exceed 2 * f2 = {2.0 * p.f2_hz} Hz (band-limit low-pass), got {fs_hz}'
        )
    b, a = analogue_tf(p)
    z, pz, k = signal.tf2zpk(b, a)
    fs_eff = fs_hz
    if prewarp_hz is not None:
        if not 0.0 < prewarp_hz < fs_hz / 2.0:
            raise ValueError(f'prewarp_hz must lie in (0, fs/2), got {prewarp_hz}')
        # bilinear_zpk uses s = 2 fs_eff (z-1)/(z+1); choose fs_eff so that the analogue
        # frequency prewarp_hz maps onto itself: 2 fs_eff tan(pi f/fs) = 2 pi f
        fs_eff = np.pi * prewarp_hz / np.tan(np.pi * prewarp_hz / fs_hz)
    zd, pd, kd = signal.bilinear_zpk(z, pz, k, fs_eff)
    return signal.zpk2sos(zd, pd, kd)


def digital_gain(
    f_hz: np.ndarray,
    fs_hz: float,
    prewarp_hz: float | None = None,
    weighting: str | WeightingParameters = 'Wb',
) -> np.ndarray:
    """Return the gain magnitude of the digital filter :func:`wb_sos` at ``f_hz``.

    Parameters
    ----------
    f_hz : array_like
        Frequencies in Hz, 1-D.
    fs_hz, prewarp_hz, weighting
        As :func:`wb_sos`.

    Returns
    -------
    np.ndarray
        Gain magnitude.
    """
    sos = wb_sos(fs_hz, prewarp_hz, weighting)
    _, h = signal.sosfreqz(sos, worN=np.atleast_1d(np.asarray(f_hz, dtype=float)), fs=fs_hz)
    return np.abs(h)


def weighted(
    acc_mps2: np.ndarray,
    fs_hz: float,
    weighting: str | WeightingParameters = 'Wb',
    prewarp_hz: float | None = None,
) -> np.ndarray:
    """Frequency-weighted acceleration time history (BS 6841 W_b by default).

    The signal is filtered from rest (zero initial conditions) along its last axis with
    :func:`wb_sos`; :func:`weighted_rms` is the RMS of this after a settling time.

    Parameters
    ----------
    acc_mps2 : array_like
        Vertical acceleration in m/s^2, shape (..., n_samples), uniformly sampled.
    fs_hz : float
        Sample rate in Hz (above twice the 100 Hz band limit, see :func:`wb_sos`).
    weighting, prewarp_hz
        As :func:`wb_sos`.

    Returns
    -------
    np.ndarray
        Weighted acceleration in m/s^2, the shape of ``acc_mps2``.
    """
    return signal.sosfilt(wb_sos(fs_hz, prewarp_hz, weighting), acc_mps2, axis=-1)


def weighted_rms(
    acc_mps2: np.ndarray,
    fs_hz: float,
    t_settle_s: float = 3.0,
    weighting: str | WeightingParameters = 'Wb',
    prewarp_hz: float | None = None,
) -> float | np.ndarray:
    """Frequency-weighted RMS acceleration (BS 6841 W_b by default), input of eq. 9.

    The signal is filtered from rest (zero initial conditions) along its last axis and the
    first ``t_settle_s`` seconds are discarded (the 0.4 Hz high-pass settles with time
    constant 2 Q1/w1 = 0.56 s).

    Parameters
    ----------
    acc_mps2 : array_like
        Vertical acceleration in m/s^2, shape (..., n_samples), uniformly sampled.
    fs_hz : float
        Sample rate in Hz (see :func:`wb_sos`).
    t_settle_s : float
        Initial time to discard, s.
    weighting : str or WeightingParameters
        'Wb' (default) or 'Wk'.
    prewarp_hz : float, optional
        See :func:`wb_sos`.

    Returns
    -------
    float or np.ndarray
        Weighted RMS in m/s^2, shape (...).
    """
    acc = np.asarray(acc_mps2, dtype=float)
    if acc.ndim == 0:
        raise ValueError('acc_mps2 must have a time axis')
    if not np.all(np.isfinite(acc)):
        raise ValueError('acc_mps2 contains NaN or inf')
    if t_settle_s < 0:
        raise ValueError(f't_settle_s must be >= 0, got {t_settle_s}')
    n_skip = int(round(t_settle_s * fs_hz))
    if n_skip >= acc.shape[-1]:
        raise ValueError(
            f'signal of {acc.shape[-1] / fs_hz:.3f} s is not longer than t_settle_s = '
            f'{t_settle_s} s'
        )
    aw = weighted(acc, fs_hz, weighting, prewarp_hz)[..., n_skip:]
    out = np.sqrt(np.mean(aw * aw, axis=-1))
    return float(out) if out.ndim == 0 else out
