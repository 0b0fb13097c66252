"""Road profiles: ISO 8608 random roads, sett pavings, road files, discrete bumps, flat road.

Roads measured elsewhere come from files (OpenCRG or CSV, key ``file`` in road.yaml):
:mod:`suspension_tuning.vehicle.road_files`.

Two random road models, each with left and right wheel tracks (config/road.yaml, key
``model``):

* ``iso8608`` (:class:`RoadSpec`): a power-law ISO 8608 PSD, below;
* ``sett_paving`` (:class:`SettPavingSpec`): an ISO 8608 bed plus a layer of stones of
  random pitch and height with joints between them (:func:`sett_layer`), the model of the
  Belgian paving (docs/belgian_paving.md).

ISO 8608 displacement PSD (one-sided, m^2 per cycle/m = m^3; physics-reference 6.1):

    G_d(n) = G_d(n0) (n / n0)^(-w)

The seed paper's Belgian paving has G_d(n0) = 1e-4 m^3 at n0 = 0.1 cycles/m and
waviness ("terrain index") w = 4 [P section 5.2].

Synthesis (physics-reference 6.3): sum of cosines with random phases on the harmonic grid
``n_k = k / L`` of a road of length L, evaluated with an inverse real FFT.  Each
component's power is the *integral* of G_d over its frequency cell (width 1/L, clipped to
the band), so the profile's mean square over the whole (periodic) road equals the
integral of G_d over the band exactly, and the periodogram equals the cell average of
G_d.  The right track is ``Z_R = gamma Z_L + sqrt(1 - gamma^2) Z_2`` with an independent
second phase set ``Z_2`` and the isotropic-surface coherence

    gamma(n) = 2^(1 - nu) / Gamma(nu) x^nu K_nu(x),  nu = w / 2,  x = 2 pi n B

for track width B (physics-reference 6.3), which keeps the PSD of each track and gives
cross-spectrum ``gamma G_d`` (magnitude-squared coherence ``gamma^2``).
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import special

from suspension_tuning.paths import config_dir, file_sha256, read_yaml
from suspension_tuning.vehicle.road_profile import SIDES, RoadProfile, _check_side  # noqa: F401

DEFAULT_CONFIG_PATH = config_dir() / 'road.yaml'
"""config/road.yaml of the source tree."""

COHERENCE_MODELS = ('isotropic', 'identical', 'independent')


@dataclass(frozen=True)
class RoadSpec:
    """Specification of an ISO 8608 random road with two wheel tracks.

    Attributes
    ----------
    gd_n0_m3 : float
        Roughness coefficient G_d(n0), m^3 (m^2 per cycle/m).
    n0_cyc_per_m : float
        Reference spatial frequency, cycles/m.
    waviness : float
        Exponent w of the PSD slope (ISO 8608 uses 2 for classification).
    n_min_cyc_per_m, n_max_cyc_per_m : float
        Synthesised band, cycles/m.
    track_m : float
        Lateral distance between the left and right wheel tracks, m.
    length_m : float
        Road length, m (the profile is periodic with this period).
    dx_m : float
        Sample spacing, m.
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed gives the same bits.
    ramp_in_m : float
        Length of a raised-cosine fade-in from z = 0 at x = 0, m (0 = none).  It avoids
        an elevation step when the vehicle starts at rest on the road.
    coherence_model : str
        'isotropic' (physics-reference 6.3), 'identical' (z_right = z_left) or
        'independent' (uncorrelated tracks).
    """

    gd_n0_m3: float = 1e-4
    n0_cyc_per_m: float = 0.1
    waviness: float = 4.0
    n_min_cyc_per_m: float = 0.05
    n_max_cyc_per_m: float = 10.0
    track_m: float = 1.486
    length_m: float = 300.0
    dx_m: float = 0.01
    seed: int = 8608
    ramp_in_m: float = 0.0
    coherence_model: str = 'isotropic'

    def __post_init__(self) -> None:
        """Check the values (ValueError with the field name)."""
        for name in (
            'gd_n0_m3',
            'n0_cyc_per_m',
            'waviness',
            'n_min_cyc_per_m',
            'n_max_cyc_per_m',
            'track_m',
            'length_m',
            'dx_m',
        ):
            v = getattr(self, name)
            if not isinstance(v, numbers.Real) or not np.isfinite(v) or v <= 0:
                raise ValueError(f'RoadSpec.{name} must be a positive finite number, got {v!r}')
        if not isinstance(self.ramp_in_m, numbers.Real) or not 0 <= self.ramp_in_m < self.length_m:
            raise ValueError(f'RoadSpec.ramp_in_m must lie in [0, length_m), got {self.ramp_in_m}')
        if not isinstance(self.seed, int | np.integer) or isinstance(self.seed, bool):
            raise ValueError(f'RoadSpec.seed must be an integer, got {self.seed!r}')
        if self.coherence_model not in COHERENCE_MODELS:
            raise ValueError(
                f'RoadSpec.coherence_model must be one of {COHERENCE_MODELS}, '
                f'got {self.coherence_model!r}'
            )
        if self.n_max_cyc_per_m <= self.n_min_cyc_per_m:
            raise ValueError('RoadSpec.n_max_cyc_per_m must exceed n_min_cyc_per_m')
        if self.n_max_cyc_per_m > 0.5 / self.dx_m:
            raise ValueError(
                f'RoadSpec.n_max_cyc_per_m = {self.n_max_cyc_per_m} exceeds the Nyquist '
                f'frequency 1/(2 dx) = {0.5 / self.dx_m} cycles/m'
            )
        if self.n_min_cyc_per_m * self.length_m < 1.0:
            raise ValueError(
                f'RoadSpec.length_m = {self.length_m} m is shorter than the longest '
                f'wavelength 1/n_min = {1.0 / self.n_min_cyc_per_m} m'
            )

    @classmethod
    def from_yaml_dict(cls, d: dict) -> RoadSpec:
        """Build a spec from a mapping of field names (e.g. one entry of road.yaml).

        Parameters
        ----------
        d : dict
            Keys are field names of :class:`RoadSpec`; missing keys take the defaults.

        Returns
        -------
        RoadSpec
            The specification.

        Raises
        ------
        ValueError
            For unknown keys or invalid values.
        """
        if not isinstance(d, dict):
            raise ValueError(f'road spec must be a mapping, got {type(d).__name__}')
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f'unknown {cls.__name__} keys {unknown}; valid keys: {sorted(names)}')
        return cls(**d)


SETT_LAYOUTS = ('rows', 'independent', 'identical')


@dataclass(frozen=True)
class SettPavingSpec(RoadSpec):
    """A sett (cobblestone) paving: ISO 8608 base undulation plus a layer of stones.

    The inherited fields describe the base: a smooth ISO 8608 surface (long waves of
    the foundation on which the setts are bedded), synthesised exactly as a
    :class:`RoadSpec` road.  On each wheel track a layer of setts is added: stones of
    random length along the road, each with its own random height, separated by
    joints.

    * Stone pitch (stone plus its joint) along the road: uniform in
      ``sett_length_m (1 -/+ sett_length_spread)``.
    * Stone top: flat at a height ``h_i ~ N(0, sett_height_std_m^2)`` above the base,
      independent from stone to stone (the random seating of hand-laid stones).
    * Joint: the last ``joint_width_m`` of each pitch, its floor ``joint_depth_m`` below
      the lower of the two stones beside it.
    * ``sett_layout``: 'rows' - stones laid in transverse courses, so both tracks share
      the course boundaries (joints at the same x) but run on different stones (own
      heights); 'independent' - own courses and own stones per track; 'identical' -
      the right track repeats the left one.  ``coherence_model='identical'`` makes the
      stone layer identical too, so that setting still means z_right = z_left.

    The sett layer's mean is removed, and the fade-in ``ramp_in_m`` applies to the sum.
    The stones come from their own random stream (``default_rng([seed, 1])``), so the
    base is bit for bit the :class:`RoadSpec` road of the same base fields.

    Attributes
    ----------
    sett_length_m : float
        Mean stone pitch along the road (stone plus joint), m.
    sett_length_spread : float
        Half-width of the uniform pitch distribution as a fraction of the mean, [0, 1).
    sett_height_std_m : float
        Standard deviation of the stone heights, m (>= 0).
    joint_width_m : float
        Joint width along the road, m (>= 0, below the shortest pitch).
    joint_depth_m : float
        Depth of the joint floor below the lower neighbouring stone, m (>= 0).
    sett_layout : str
        One of :data:`SETT_LAYOUTS`.
    """

    sett_length_m: float = 0.14
    sett_length_spread: float = 0.3
    sett_height_std_m: float = 0.01
    joint_width_m: float = 0.02
    joint_depth_m: float = 0.005
    sett_layout: str = 'rows'

    def __post_init__(self) -> None:
        """Check the base fields (RoadSpec) and the sett fields (ValueError with the name)."""
        super().__post_init__()
        sett_fields = (
            'sett_length_m',
            'sett_length_spread',
            'sett_height_std_m',
            'joint_width_m',
            'joint_depth_m',
        )
        for name in sett_fields:
            v = getattr(self, name)
            if not isinstance(v, numbers.Real) or not np.isfinite(v) or v < 0:
                raise ValueError(f'SettPavingSpec.{name} must be a finite number >= 0, got {v!r}')
        if self.sett_length_m <= 0:
            raise ValueError(f'SettPavingSpec.sett_length_m must be > 0, got {self.sett_length_m}')
        if self.sett_length_spread >= 1.0:
            raise ValueError(
                f'SettPavingSpec.sett_length_spread must lie in [0, 1), '
                f'got {self.sett_length_spread}'
            )
        shortest = self.sett_length_m * (1.0 - self.sett_length_spread)
        if self.joint_width_m >= shortest:
            raise ValueError(
                f'SettPavingSpec.joint_width_m = {self.joint_width_m} m must be shorter '
                f'than the shortest stone pitch {shortest:.4g} m'
            )
        if shortest < 2.0 * self.dx_m:
            raise ValueError(
                f'the shortest stone pitch {shortest:.4g} m needs at least 2 samples of '
                f'dx_m = {self.dx_m} m'
            )
        if self.sett_layout not in SETT_LAYOUTS:
            raise ValueError(
                f'SettPavingSpec.sett_layout must be one of {SETT_LAYOUTS}, '
                f'got {self.sett_layout!r}'
            )


ROAD_MODELS: dict[str, type[RoadSpec]] = {'iso8608': RoadSpec, 'sett_paving': SettPavingSpec}
"""Values of the ``model`` key of a road.yaml entry and the spec class each one builds."""


def load_road_spec(name: str = 'belgian_paving', path: str | Path | None = None):
    """Load a named road specification from a YAML file (default config/road.yaml).

    Parameters
    ----------
    name : str
        Key of the road in the file's ``roads`` mapping.
    path : str or Path, optional
        YAML file; :data:`DEFAULT_CONFIG_PATH` when omitted.

    Returns
    -------
    RoadSpec or FileRoadSpec
        The specification (a road with a ``file`` key is a
        :class:`~suspension_tuning.vehicle.road_files.FileRoadSpec`, its relative path
        resolved against the YAML file's folder).
    """
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    data = read_yaml(p)
    roads = data.get('roads', {})
    if name not in roads:
        raise ValueError(f'road {name!r} not found in {p}; available: {sorted(roads)}')
    return road_spec_from_yaml_dict(roads[name], base_dir=p.parent)


def road_spec_from_yaml_dict(d: dict, base_dir: str | Path | None = None):
    """Build an ISO 8608, sett-paving or file road spec from one entry of road.yaml.

    Parameters
    ----------
    d : dict
        Field names of the spec class plus an optional ``model`` key, one of
        :data:`ROAD_MODELS` ('iso8608' when omitted), or 'file' (implied by a ``file``
        key).
    base_dir : str or Path, optional
        Folder a relative ``file`` is relative to (default the config folder).

    Returns
    -------
    RoadSpec or FileRoadSpec
        A :class:`RoadSpec`, a :class:`SettPavingSpec` or a
        :class:`~suspension_tuning.vehicle.road_files.FileRoadSpec`.

    Raises
    ------
    ValueError
        For an unknown model, unknown keys or invalid values.
    """
    if not isinstance(d, dict):
        raise ValueError(f'road spec must be a mapping, got {type(d).__name__}')
    if 'file' in d or d.get('model') == 'file':
        from .road_files import FileRoadSpec

        return FileRoadSpec.from_yaml_dict(
            d, base_dir=base_dir if base_dir is not None else DEFAULT_CONFIG_PATH.parent)
    fields = dict(d)
    model = fields.pop('model', 'iso8608')
    if model not in ROAD_MODELS:
        raise ValueError(f"unknown road model {model!r}; valid models: {sorted(ROAD_MODELS)} "
                         "or a road file (key 'file')")
    return ROAD_MODELS[model].from_yaml_dict(fields)


ROAD_FILE_SUFFIXES = ('.crg', '.csv')


def resolve_road(road, path: str | Path | None = None):
    """A road as a scenario or a goal names it: a name, a file, or an entry of its own.

    Parameters
    ----------
    road : str or dict
        A road of config/road.yaml by name; a path to an OpenCRG (``.crg``) or CSV
        (``.csv``) file (relative to the working folder); a YAML mapping of a road entry
        as text (``'{file: /data/track.crg, repeat: true}'``) or as a dict.
    path : str or Path, optional
        The road.yaml to look names up in (default config/road.yaml).

    Returns
    -------
    RoadSpec or FileRoadSpec

    Raises
    ------
    ValueError
        An unknown name (with the names there are), or a bad entry.
    """
    if isinstance(road, dict):
        return road_spec_from_yaml_dict(road, base_dir=Path.cwd())
    if not isinstance(road, str) or not road.strip():
        raise ValueError(f'a road is a name, a file or a mapping, got {road!r}')
    text = road.strip()
    if text.startswith('{'):
        import yaml

        try:
            entry = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f'road {text!r} is not a YAML mapping: {error}') from None
        return resolve_road(entry, path)
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    roads = read_yaml(p).get('roads', {})
    if text in roads:
        return load_road_spec(text, p)
    if Path(text).suffix.lower() in ROAD_FILE_SUFFIXES or Path(text).is_file():
        return road_spec_from_yaml_dict({'file': str(Path(text).expanduser().absolute())})
    raise ValueError(f'road {text!r} is neither a road of {p} ({", ".join(sorted(roads))}) nor '
                     'a .crg or .csv file')


def iso8608_psd(n_cyc_per_m: np.ndarray, spec: RoadSpec) -> np.ndarray:
    """Return the ISO 8608 displacement PSD G_d(n) in m^3 (zero outside the band).

    Parameters
    ----------
    n_cyc_per_m : array_like
        Spatial frequencies, cycles/m.
    spec : RoadSpec
        Road specification.

    Returns
    -------
    np.ndarray
        One-sided PSD, m^2/(cycle/m).
    """
    n = np.asarray(n_cyc_per_m, dtype=float)
    inside = (n >= spec.n_min_cyc_per_m) & (n <= spec.n_max_cyc_per_m)
    with np.errstate(divide='ignore'):
        g = spec.gd_n0_m3 * (np.where(inside, n, 1.0) / spec.n0_cyc_per_m) ** (-spec.waviness)
    return np.where(inside, g, 0.0)


def _psd_integral(n_lo: np.ndarray, n_hi: np.ndarray, spec: RoadSpec) -> np.ndarray:
    """Integral of G_d from n_lo to n_hi (closed form of the power law), m^2."""
    w = spec.waviness
    c = spec.gd_n0_m3 * spec.n0_cyc_per_m**w
    if abs(w - 1.0) < 1e-12:
        return c * np.log(n_hi / n_lo)
    return c * (n_hi ** (1.0 - w) - n_lo ** (1.0 - w)) / (1.0 - w)


def left_right_coherence(n_cyc_per_m: np.ndarray, track_m: float, waviness: float) -> np.ndarray:
    """Return the coherence gamma(n) between two parallel tracks of an isotropic surface.

    ``gamma = 2^(1 - nu) / Gamma(nu) x^nu K_nu(x)`` with ``nu = w/2`` and
    ``x = 2 pi n B`` (physics-reference 6.3).  gamma -> 1 as n -> 0.  The magnitude-squared
    coherence (as estimated by Welch's method) is gamma^2.

    Parameters
    ----------
    n_cyc_per_m : array_like
        Spatial frequencies, cycles/m (>= 0).
    track_m : float
        Track spacing B, m.
    waviness : float
        PSD exponent w (> 0).

    Returns
    -------
    np.ndarray
        gamma in [0, 1].
    """
    nu = waviness / 2.0
    x = 2.0 * np.pi * np.asarray(n_cyc_per_m, dtype=float) * track_m
    xs = np.where(x > 0, x, 1.0)
    with np.errstate(over='ignore', under='ignore', invalid='ignore'):
        g = 2.0 ** (1.0 - nu) / special.gamma(nu) * xs**nu * special.kv(nu, xs)
    g = np.where(np.isfinite(g), g, 0.0)
    return np.clip(np.where(x > 0, g, 1.0), 0.0, 1.0)


def _ramp(x: np.ndarray, ramp_m: float) -> np.ndarray:
    if ramp_m <= 0:
        return np.ones_like(x)
    r = np.clip(x / ramp_m, 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * r))


def synthesise_tracks(spec: RoadSpec) -> RoadProfile:
    """Synthesise left and right tracks (deterministic for a given seed).

    Parameters
    ----------
    spec : RoadSpec, SettPavingSpec or FileRoadSpec
        Road specification: an ISO 8608 road, a sett paving (ISO 8608 base plus the
        stone layer of :func:`sett_layer`), or a road file
        (:func:`~suspension_tuning.vehicle.road_files.file_road_profile`).

    Returns
    -------
    RoadProfile
        ``x_m = 0, dx, ..., N dx`` with ``N = round(length_m / dx_m)``.  For an ISO 8608
        road the last sample repeats the first (the synthesised road is periodic with
        period N dx); the stone layer of a sett paving is not periodic.
    """
    from .road_files import FileRoadSpec, file_road_profile

    if isinstance(spec, FileRoadSpec):
        return file_road_profile(spec)
    if not isinstance(spec, RoadSpec):
        raise ValueError(f'spec must be a RoadSpec, got {type(spec).__name__}')
    x, z_left, z_right = _iso8608_tracks(spec)
    if isinstance(spec, SettPavingSpec):
        s_left, s_right = sett_layer(spec, x.size)
        z_left, z_right = z_left + s_left, z_right + s_right
    w = _ramp(x, spec.ramp_in_m)
    return RoadProfile(x_m=x, z_left_m=z_left * w, z_right_m=z_right * w, spec=spec)


def _iso8608_tracks(spec: RoadSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, z_left, z_right of the ISO 8608 part of ``spec`` (periodic, no fade-in), m."""
    n_pts = int(round(spec.length_m / spec.dx_m))
    period = n_pts * spec.dx_m
    dn = 1.0 / period
    k = np.arange(n_pts // 2 + 1)
    n_k = k * dn
    lo = np.clip(n_k - 0.5 * dn, spec.n_min_cyc_per_m, spec.n_max_cyc_per_m)
    hi = np.clip(n_k + 0.5 * dn, spec.n_min_cyc_per_m, spec.n_max_cyc_per_m)
    valid = (hi > lo) & (k > 0) & (k < n_pts / 2)  # no DC, no Nyquist bin
    power = np.zeros(k.size)
    power[valid] = _psd_integral(lo[valid], hi[valid], spec)  # variance per component
    amp = np.sqrt(2.0 * power)  # cosine amplitude A_k, var = A_k^2 / 2

    rng = np.random.default_rng(spec.seed)
    phi_1 = rng.uniform(0.0, 2.0 * np.pi, k.size)
    phi_2 = rng.uniform(0.0, 2.0 * np.pi, k.size)
    scale = 0.5 * n_pts  # irfft: z = sum (2/N) |Z_k| cos(...)
    z1 = scale * amp * np.exp(1j * phi_1)
    z2 = scale * amp * np.exp(1j * phi_2)
    if spec.coherence_model == 'isotropic':
        gam = left_right_coherence(n_k, spec.track_m, spec.waviness)
        zr = gam * z1 + np.sqrt(1.0 - gam**2) * z2
    elif spec.coherence_model == 'identical':
        zr = z1
    else:
        zr = z2
    z_left = np.fft.irfft(z1, n=n_pts)
    z_right = np.fft.irfft(zr, n=n_pts)
    x = np.arange(n_pts + 1) * spec.dx_m
    return x, np.append(z_left, z_left[0]), np.append(z_right, z_right[0])


def _sett_track(
    x_m: np.ndarray, edges_m: np.ndarray, heights_m: np.ndarray, spec: SettPavingSpec
) -> np.ndarray:
    """Stone layer on one track: flat stone tops, joints at the end of each pitch, m."""
    i = np.clip(np.searchsorted(edges_m, x_m, side='right') - 1, 0, heights_m.size - 2)
    z = heights_m[i].copy()
    if spec.joint_width_m > 0:
        in_joint = x_m >= edges_m[i + 1] - spec.joint_width_m
        floor = np.minimum(heights_m[i], heights_m[i + 1]) - spec.joint_depth_m
        z = np.where(in_joint, floor, z)
    return z


def sett_layer(spec: SettPavingSpec, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the stone layer of a sett paving on the left and right tracks.

    Parameters
    ----------
    spec : SettPavingSpec
        Paving specification (stone pitch, height spread, joints, layout, seed).
    n_samples : int
        Number of samples, at ``x = 0, dx_m, ...``.

    Returns
    -------
    (np.ndarray, np.ndarray)
        Left and right elevations, m, each of zero mean, shape (n_samples,).
    """
    if not isinstance(spec, SettPavingSpec):
        raise ValueError(f'spec must be a SettPavingSpec, got {type(spec).__name__}')
    rng = np.random.default_rng([spec.seed, 1])
    x = np.arange(n_samples) * spec.dx_m
    length = x[-1] + spec.dx_m
    # enough pitches to cover the road (and the random shift of the first course) even
    # if every stone is the shortest one
    shortest = spec.sett_length_m * (1.0 - spec.sett_length_spread)
    longest = spec.sett_length_m * (1.0 + spec.sett_length_spread)
    n_stones = int(np.ceil((length + 2.0 * longest) / shortest)) + 1
    layout = 'identical' if spec.coherence_model == 'identical' else spec.sett_layout

    def edges() -> np.ndarray:
        lo, hi = 1.0 - spec.sett_length_spread, 1.0 + spec.sett_length_spread
        pitch = spec.sett_length_m * rng.uniform(lo, hi, n_stones)
        # random phase of the first course so x = 0 is not always a joint
        return np.concatenate(([0.0], np.cumsum(pitch))) - rng.uniform(0.0, pitch[0])

    def heights() -> np.ndarray:
        return spec.sett_height_std_m * rng.standard_normal(n_stones + 1)

    e_left = edges()
    h_left = heights()
    if layout == 'identical':
        e_right, h_right = e_left, h_left
    elif layout == 'rows':
        e_right, h_right = e_left, heights()
    else:
        e_right = edges()
        h_right = heights()
    z_left = _sett_track(x, e_left, h_left, spec)
    z_right = _sett_track(x, e_right, h_right, spec)
    return z_left - np.mean(z_left), z_right - np.mean(z_right)


def sett_height_psd(n_cyc_per_m: np.ndarray, spec: SettPavingSpec) -> np.ndarray:
    """Return the PSD of the stone layer without joints, m^3 (one-sided, per cycle/m).

    For flat stones of independent heights (variance sigma^2) and independent pitches L
    (a renewal process), the two-sided PSD in angular wavenumber is
    ``sigma^2 E[|F_L|^2] / (2 pi E[L])`` with ``|F_L|^2 = 4 sin^2(k L / 2) / k^2``;
    one-sided in cycles/m this is

        G(n) = 2 sigma^2 E[sin^2(pi n L)] / (E[L] (pi n)^2),

    and for L uniform in [a, b], ``E[sin^2(pi n L)] = 1/2 - (sin 2 pi n b - sin 2 pi n a)
    / (4 pi n (b - a))``.  G(0) = 2 sigma^2 E[L^2] / E[L].  The joints add a little
    short-wave power on top of this (their depth and width are small beside the stones).

    Parameters
    ----------
    n_cyc_per_m : array_like
        Spatial frequencies, cycles/m (> 0).
    spec : SettPavingSpec
        Paving specification.

    Returns
    -------
    np.ndarray
        G(n), m^2/(cycle/m).
    """
    n = np.asarray(n_cyc_per_m, dtype=float)
    if np.any(n <= 0) or np.any(~np.isfinite(n)):
        raise ValueError('sett_height_psd needs finite spatial frequencies > 0')
    mean = spec.sett_length_m
    half = spec.sett_length_spread * mean
    a, b = mean - half, mean + half
    if half > 0:
        e_sin2 = 0.5 - (np.sin(2 * np.pi * n * b) - np.sin(2 * np.pi * n * a)) / (
            4 * np.pi * n * (b - a)
        )
    else:
        e_sin2 = np.sin(np.pi * n * mean) ** 2
    return 2.0 * spec.sett_height_std_m**2 * e_sin2 / (mean * (np.pi * n) ** 2)


def smooth_road(length_m: float, dx_m: float = 0.01) -> RoadProfile:
    """Return a flat road (z = 0 on both tracks).

    Parameters
    ----------
    length_m : float
        Road length, m.
    dx_m : float
        Sample spacing, m.

    Returns
    -------
    RoadProfile
        Flat profile from x = 0 to about ``length_m``.
    """
    if not (np.isfinite(length_m) and np.isfinite(dx_m)) or length_m <= 0 or dx_m <= 0:
        raise ValueError(f'length_m and dx_m must be positive, got {length_m}, {dx_m}')
    n = max(int(round(length_m / dx_m)), 1)
    x = np.arange(n + 1) * dx_m
    return RoadProfile(x_m=x, z_left_m=np.zeros_like(x), z_right_m=np.zeros_like(x))


def discrete_bump(
    height_m: float,
    bump_length_m: float,
    x_start_m: float | list[float],
    road_length_m: float,
    dx_m: float = 0.01,
    shape: str = 'half_sine',
    side: str = 'both',
    top_length_m: float = 0.0,
) -> RoadProfile:
    """Return a flat road with one or more discrete bumps.

    Parameters
    ----------
    height_m : float
        Bump height, m (negative for a pothole).
    bump_length_m : float
        Length of each bump along the road, m.
    x_start_m : float or sequence of float
        Start position(s) of the bump(s), m; bumps must not overlap.
    road_length_m : float
        Road length, m.
    dx_m : float
        Sample spacing, m.
    shape : str
        'half_sine' (z = h sin(pi s / L)) or 'trapezoid' (linear ramps either side of a
        flat top of ``top_length_m``).
    side : str
        'both', 'left' or 'right' track.
    top_length_m : float
        Flat-top length for the trapezoid, m (< bump_length_m).

    Returns
    -------
    RoadProfile
        The profile.
    """
    if shape not in ('half_sine', 'trapezoid'):
        raise ValueError(f"shape must be 'half_sine' or 'trapezoid', got {shape!r}")
    if side not in ('both', 'left', 'right'):
        raise ValueError(f"side must be 'both', 'left' or 'right', got {side!r}")
    if not np.isfinite(height_m):
        raise ValueError(f'height_m must be finite, got {height_m}')
    if not np.isfinite(bump_length_m) or bump_length_m <= 0:
        raise ValueError(f'bump_length_m must be positive, got {bump_length_m}')
    if shape == 'trapezoid' and not 0 <= top_length_m < bump_length_m:
        raise ValueError('top_length_m must lie in [0, bump_length_m)')
    starts = np.sort(np.atleast_1d(np.asarray(x_start_m, dtype=float)))
    if np.any(~np.isfinite(starts)) or np.any(starts < 0):
        raise ValueError(f'x_start_m must be finite and >= 0, got {x_start_m}')
    if np.any(np.diff(starts) < bump_length_m):
        raise ValueError('bumps overlap: starts must be at least bump_length_m apart')
    if starts[-1] + bump_length_m > road_length_m:
        raise ValueError('the last bump ends beyond road_length_m')
    flat = smooth_road(road_length_m, dx_m)
    x = flat.x_m
    z = np.zeros_like(x)
    for x0 in starts:
        s = x - x0
        inside = (s >= 0) & (s <= bump_length_m)
        if shape == 'half_sine':
            zb = height_m * np.sin(np.pi * s / bump_length_m)
        else:
            ramp = 0.5 * (bump_length_m - top_length_m)
            zb = height_m * np.clip(np.minimum(s, bump_length_m - s) / ramp, 0.0, 1.0)
        z = np.where(inside, zb, z)
    zl = z if side in ('both', 'left') else np.zeros_like(z)
    zr = z if side in ('both', 'right') else np.zeros_like(z)
    return RoadProfile(x_m=x, z_left_m=zl, z_right_m=zr)


def road_identity(road: str) -> dict[str, str]:
    """What identifies a road a goal names: its text and, for a road file, file and SHA-256.

    Empty for ``''`` (the configured road, which the model fingerprint covers).  What
    the run configuration records and the calibration's cache key holds.

    Raises
    ------
    ValueError
        An unknown road name or a bad entry.
    """
    if not road:
        return {}
    from .road_files import FileRoadSpec

    spec = resolve_road(road)
    out = {'road': str(road)}
    if isinstance(spec, FileRoadSpec):
        out['file'] = spec.file
        out['sha256'] = file_sha256(spec.file) if spec.path.is_file() else 'missing'
    return out
