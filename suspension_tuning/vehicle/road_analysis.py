"""Statistics of road profiles: RMS, Welch PSD, the ISO 8608 fit and class (no rclpy).

ISO 8608 describes a road by its displacement PSD ``G_d(n) = G_d(n0) (n / n0)^(-w)``
with n0 = 0.1 cycles/m; its classes A-H are bands of ``G_d(n0)`` (limits
:data:`ISO8608_CLASS_UPPER_M3`, physics-reference 6.1).  :func:`iso8608_fit` fits
``G_d(n0)`` and the waviness w to a measured PSD by least squares in log-log over a
band the caller states, on third-octave band averages of the Welch estimate (each band
the mean of the periodogram's bins in it, so every band counts once whatever its
number of bins), and extrapolates the fitted line to n0 when n0 lies below the band.

:func:`window_statistics` cuts a track into windows of equal length (10 m: the length of
the measured Belgian block) and gives each window's RMS in a wavenumber band and its
short-wave roughness, so that a long synthesised road and a short measured patch are
compared on the same footing (docs/belgian_paving.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

Array = NDArray[np.float64]

N0_CYC_PER_M = 0.1
"""ISO 8608 reference spatial frequency n0, cycles/m."""
ISO8608_CLASSES = 'ABCDEFGH'
ISO8608_CLASS_UPPER_M3 = 2.0 ** np.arange(5, 18, 2) * 1e-6
"""Upper limits of G_d(n0) of classes A-G, m^3 (A < 32e-6, B < 128e-6, ... G < 131072e-6;
H above), ISO 8608 table with w = 2 (physics-reference 6.1)."""
DEFAULT_BAND_CYC_PER_M = (0.1, 10.0)
"""Default band of the ISO 8608 fit, cycles/m: wavelengths 10 m to 0.1 m [E]: the ride
band at 10-100 km/h and the stones of a paving, below the tyre's contact-patch filter."""
DEFAULT_SEGMENT_M = 50.0
"""Welch segment length, m [E]: 0.02 cycles/m resolution, and 9 segments (50 % overlap)
on a 250 m road; a shorter road is one segment."""


def welch(z_m: Array, dx_m: float, segment_m: float = DEFAULT_SEGMENT_M) -> tuple[Array, Array]:
    """One-sided Welch PSD of an elevation record (linear trend removed per segment).

    Parameters
    ----------
    z_m : array_like
        Elevations, m, sampled every ``dx_m``.
    dx_m : float
        Sample spacing, m.
    segment_m : float
        Segment length, m (clipped to the record).

    Returns
    -------
    (np.ndarray, np.ndarray)
        Spatial frequencies n (cycles/m, without 0) and G_d(n), m^3.
    """
    z = np.asarray(z_m, dtype=float)
    nper = min(int(round(segment_m / dx_m)), z.size)
    n, g = signal.welch(z, fs=1.0 / dx_m, nperseg=nper, detrend='linear')
    return n[1:], g[1:]


def band_rms(n: Array, g: Array, lo: float, hi: float) -> float:
    """RMS (m) of the part of a record between ``lo`` and ``hi`` cycles/m: sqrt(int G dn)."""
    n, g = np.asarray(n), np.asarray(g)
    inside = (n >= lo) & (n <= hi)
    if not inside.any():
        return math.nan
    dn = float(n[1] - n[0]) if n.size > 1 else 1.0
    return float(np.sqrt(np.sum(g[inside]) * dn))


def third_octave_bands(n: Array, g: Array, lo: float, hi: float) -> tuple[Array, Array]:
    """Third-octave band centres in [lo, hi] with the mean PSD of the bins in each band."""
    n, g = np.asarray(n), np.asarray(g)
    k = np.arange(math.floor(3 * math.log2(lo)), math.ceil(3 * math.log2(hi)) + 1)
    centres = 2.0 ** (k / 3.0)
    centres = centres[(centres >= lo * (1 - 1e-9)) & (centres <= hi * (1 + 1e-9))]
    out_n, out_g = [], []
    for c in centres:
        inside = (n >= c * 2 ** (-1 / 6)) & (n < c * 2 ** (1 / 6))
        if inside.any():
            out_n.append(c)
            out_g.append(float(np.mean(g[inside])))
    return np.asarray(out_n), np.asarray(out_g)


def iso8608_class(gd_n0_m3: float) -> str:
    """ISO 8608 class letter (A-H) of a roughness coefficient G_d(n0) in m^3."""
    if not np.isfinite(gd_n0_m3):
        return '?'
    k = int(np.searchsorted(ISO8608_CLASS_UPPER_M3, gd_n0_m3, side='right'))
    return ISO8608_CLASSES[min(k, len(ISO8608_CLASSES) - 1)]


@dataclass(frozen=True)
class Iso8608Fit:
    """ISO 8608 fit of a PSD over a band.

    Attributes
    ----------
    gd_n0_m3 : float
        G_d(n0) at n0 = 0.1 cycles/m, m^3 (extrapolated when the band starts above n0).
    waviness : float
        Fitted exponent w.
    iso_class : str
        Class A-H of G_d(n0).
    band_cyc_per_m : (float, float)
        The band fitted, cycles/m.
    n_bands : int
        Third-octave bands in the fit.
    extrapolated : bool
        n0 lies outside the band.
    """

    gd_n0_m3: float
    waviness: float
    iso_class: str
    band_cyc_per_m: tuple[float, float]
    n_bands: int
    extrapolated: bool

    def gd(self, n_cyc_per_m: Array) -> Array:
        """The fitted PSD at ``n``, m^3."""
        return self.gd_n0_m3 * (np.asarray(n_cyc_per_m, float) / N0_CYC_PER_M) ** -self.waviness


def usable_band(length_m: float, band: tuple[float, float], dx_m: float,
                segment_m: float = DEFAULT_SEGMENT_M) -> tuple[float, float]:
    """The part of ``band`` a record resolves: above 2 / segment, below half Nyquist.

    A Hann-windowed segment of length T resolves little below 2 / T (its main lobe);
    the band is also kept below 0.5 / (2 dx), where linear interpolation of the
    record has lost little power.
    """
    segment = min(segment_m, length_m)
    lo = max(band[0], 2.0 / segment)
    hi = min(band[1], 0.25 / dx_m)
    if not lo < hi:
        raise ValueError(f'no usable band: the record ({length_m:.2f} m, {dx_m:g} m spacing) '
                         f'resolves {2.0 / segment:.3g}-{0.25 / dx_m:.3g} cycles/m, the band '
                         f'asked for is {band[0]:g}-{band[1]:g} cycles/m')
    return lo, hi


def iso8608_fit(n: Array, g: Array, band: tuple[float, float]) -> Iso8608Fit:
    """Least-squares fit of log G_d = log G_d(n0) - w log(n / n0) over ``band``.

    Parameters
    ----------
    n, g : array_like
        A PSD estimate (cycles/m, m^3), e.g. from :func:`welch`.
    band : (float, float)
        Fitted band, cycles/m.

    Raises
    ------
    ValueError
        Fewer than two third-octave bands with data inside ``band``.
    """
    nb, gb = third_octave_bands(n, g, *band)
    keep = gb > 0
    nb, gb = nb[keep], gb[keep]
    if nb.size < 2:
        raise ValueError(f'fewer than 2 third-octave bands with data in {band[0]:g}-'
                         f'{band[1]:g} cycles/m: the record is too short for this band')
    slope, intercept = np.polyfit(np.log10(nb / N0_CYC_PER_M), np.log10(gb), 1)
    gd0 = float(10.0 ** intercept)
    return Iso8608Fit(gd0, float(-slope), iso8608_class(gd0), (float(band[0]), float(band[1])),
                      int(nb.size), not band[0] <= N0_CYC_PER_M <= band[1])


def detrended_rms(z_m: Array) -> float:
    """RMS of a record about its least-squares straight line, m."""
    z = np.asarray(z_m, dtype=float)
    return float(np.sqrt(np.mean(signal.detrend(z, type='linear') ** 2)))


@dataclass(frozen=True)
class WindowStatistics:
    """Per-window statistics of a track (arrays over the windows).

    Attributes
    ----------
    band_rms_m : np.ndarray
        RMS in the stone band (``band``), m.
    short_wave_rms_m : np.ndarray
        RMS of wavelengths shorter than ``1 / short_wave_from`` up to ``short_wave_to``
        cycles/m, m.
    gd_band_m3 : np.ndarray
        Mean PSD over the stone band's third-octave bands, m^3.
    waviness_band : np.ndarray
        Fitted w within the stone band.
    """

    band_rms_m: Array
    short_wave_rms_m: Array
    gd_band_m3: Array
    waviness_band: Array


def window_statistics(z_m: Array, dx_m: float, window_m: float = 10.0,
                      band: tuple[float, float] = (1.0, 10.0),
                      short_wave: tuple[float, float] = (1.0, 50.0)) -> WindowStatistics:
    """Statistics of consecutive windows of ``window_m`` along a track.

    Each window's linear trend is removed and its PSD is one Hann-windowed segment
    (:func:`welch` over the window).

    Parameters
    ----------
    z_m : array_like
        Elevations, m, every ``dx_m``.
    dx_m : float
        Sample spacing, m.
    window_m : float
        Window length, m (whole windows only).
    band : (float, float)
        Stone band, cycles/m.
    short_wave : (float, float)
        Band of the short-wave roughness, cycles/m (wavelengths below 1 m, up to the
        Nyquist frequency of the coarser record compared).
    """
    z = np.asarray(z_m, dtype=float)
    per = int(round(window_m / dx_m))
    count = z.size // per
    if count < 1:
        raise ValueError(f'the track ({z.size * dx_m:.2f} m) is shorter than one window '
                         f'({window_m:g} m)')
    rows = []
    for k in range(count):
        n, g = welch(z[k * per:(k + 1) * per], dx_m, window_m)
        nb, gb = third_octave_bands(n, g, *band)
        fit = iso8608_fit(n, g, band)
        rows.append((band_rms(n, g, *band), band_rms(n, g, *short_wave),
                     float(np.mean(gb)), fit.waviness))
    a = np.asarray(rows)
    return WindowStatistics(a[:, 0], a[:, 1], a[:, 2], a[:, 3])


#: The statistics :func:`compare_windows` gives, with their units for a report.
WINDOW_QUANTITIES = {
    'rms_m': ('RMS elevation of the window (trend removed)', 'mm', 1e3),
    'band_rms_m': ('RMS in the stone band 1-10 cycles/m', 'mm', 1e3),
    'short_wave_rms_m': ('RMS of wavelengths below 1 m (1-50 cycles/m)', 'mm', 1e3),
    'gd_band_m3': ('mean PSD over the stone band', 'm^3', 1.0),
    'waviness_band': ('PSD slope w in the stone band', '-', 1.0),
}


def track_windows(tracks: list[Array], dx_m: float, window_m: float = 10.0) -> dict[str, Array]:
    """:func:`window_statistics` of several tracks pooled, plus each window's RMS.

    Parameters
    ----------
    tracks : list of array_like
        Elevation records, m, every ``dx_m`` (e.g. a road's left and right tracks).
    dx_m : float
        Sample spacing, m.
    window_m : float
        Window length, m.

    Returns
    -------
    dict
        Each key of :data:`WINDOW_QUANTITIES` -> values over all windows of all tracks.
    """
    out: dict[str, list] = {key: [] for key in WINDOW_QUANTITIES}
    per = int(round(window_m / dx_m))
    for z in tracks:
        z = np.asarray(z, dtype=float)
        stats = window_statistics(z, dx_m, window_m)
        out['rms_m'] += [detrended_rms(z[k * per:(k + 1) * per]) for k in range(z.size // per)]
        out['band_rms_m'] += list(stats.band_rms_m)
        out['short_wave_rms_m'] += list(stats.short_wave_rms_m)
        out['gd_band_m3'] += list(stats.gd_band_m3)
        out['waviness_band'] += list(stats.waviness_band)
    return {key: np.asarray(value) for key, value in out.items()}
