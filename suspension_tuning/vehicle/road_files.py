"""Measured roads from files: ASAM OpenCRG (``.crg``) and CSV columns (no rclpy).

A road of config/road.yaml with the key ``file`` (:class:`FileRoadSpec`) is read from a
file instead of being synthesised; every road-driven scenario then drives it (the full
model's two wheel tracks, the pitch-plane model's left/right average, paper section
6.2, and an FMU worker's road inputs).

Formats
-------
* OpenCRG (``.crg``, all four data formats KRBI, KDBI, LRFI, LDFI), read with
  PyOpenCRG (requirements.txt says why that reader).  Modifiers the file defines
  (``$ROAD_CRG_MODS``) are applied as a simulator applies them; a file without that
  block is read as stored (OpenCRG's default modifiers would only move the reference
  line, which the tracks do not use, and fill missing values at the road's edges
  with copies of their neighbours, which step 1 below refuses to do silently).  The
  elevation of a wheel track is the road surface
  (grid plus reference-line elevation and banking) along the reference line at the
  lateral position ``v = +track/2`` (left; OpenCRG's v is positive to the left) and
  ``v = -track/2`` (right), linear between the two neighbouring long sections.  The
  distance driven is the reference line's ``u``: on a curved reference line the outer
  track is longer than u by ``v kappa`` (2.9 % at the 26 m radius of the measured
  Belgian block); the vehicle model drives straight, so the curvature is not used.
  Units: the header's ``U:`` and ``D:`` channels of the elevation must be in m.
* CSV: a header line, then three columns: distance along the road, left and right
  elevation, all in metres.  Each header name says its unit, as a suffix ``_m`` or in
  brackets (``distance_m,left_m,right_m`` or ``distance [m],left [m],right [m]``);
  another unit (mm, ft...) is refused with its name.  Lines starting with ``#`` are
  comments; an empty cell or ``nan`` is a missing value.

What is done to the tracks, in this order
-----------------------------------------
1. **Missing values.** Samples where either track has no value (NaN) at the start or
   the end of the road (a scan's ragged borders) are cut off, and the road starts at
   the first sample with both tracks; a gap *inside* the road is refused with its
   position (fill it first, e.g. PyOpenCRG's ``fill_holes``).
2. **Resampling** onto ``dx_m`` (default: the file's own spacing) by linear
   interpolation; a spacing coarser than the file's first averages over ``dx_m``
   (a box filter), so that shorter waves do not alias.
3. **Offset.** One constant, the mean of the left/right average, is removed, so that
   the road lies around z = 0 where the vehicle's static equilibrium is solved; the
   left/right difference (cross slope) is kept.
4. **Length.** A road shorter than a run is refused with a clear error, or repeated
   when the user says so (``repeat: true``, ``tune --repeat-road``) with a
   :class:`RoadRepetitionWarning` that names the period repetition introduces (a
   10 m road at 50 km/h excites 1.39 Hz, the body-bounce frequency).  Each copy is
   tilted by the straight line through its end points so that the copies join
   without a step.
5. **Fade-in** over ``ramp_in_m`` (raised cosine from z = 0), as for synthesised roads.

Bad files raise :class:`RoadFileError` (a ValueError) naming the file and the problem.
"""

from __future__ import annotations

import functools
import math
import numbers
import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from .road_profile import RoadProfile

FORMATS = ('auto', 'crg', 'csv')
#: The unit every distance and elevation of a road file must have.
UNIT_M = 'm'


class RoadFileError(ValueError):
    """A road file that cannot be driven: unreadable, damaged, wrong units, too short."""


class RoadRepetitionWarning(UserWarning):
    """A road file is repeated to cover a run: the repetition is a periodic excitation."""


@dataclass(frozen=True)
class FileRoadSpec:
    """A road read from a file (OpenCRG or CSV): an entry of config/road.yaml with ``file``.

    Attributes
    ----------
    file : str
        Path of the road file; a relative path in config/road.yaml is relative to the
        config folder (as the model fingerprint hashes it).
    format : str
        'crg', 'csv' or 'auto' (by the file's extension).
    track_m : float
        Lateral distance between the wheel tracks, m: they are taken at +-track/2 from
        the road's reference line (OpenCRG) or are the file's two columns (CSV, where
        the value is not used).
    dx_m : float or None
        Sample spacing of the profile, m; None = the file's own.
    length_m : float or None
        Length of road to drive, m; None = the file's.  Longer than the file needs
        ``repeat``.
    repeat : bool
        Repeat the file to ``length_m`` (a warning names the period).
    ramp_in_m : float
        Raised-cosine fade-in from z = 0 over this distance, m (0 = none).
    """

    file: str
    format: str = 'auto'
    track_m: float = 1.486
    dx_m: float | None = None
    length_m: float | None = None
    repeat: bool = False
    ramp_in_m: float = 0.0

    def __post_init__(self) -> None:
        """Check the values (ValueError naming the field)."""
        if not isinstance(self.file, str | Path) or not str(self.file):
            raise ValueError(f'FileRoadSpec.file must be a path, got {self.file!r}')
        object.__setattr__(self, 'file', str(self.file))
        if self.format not in FORMATS:
            raise ValueError(f'FileRoadSpec.format must be one of {FORMATS}, got {self.format!r}')
        for name in ('track_m', 'dx_m', 'length_m'):
            v = getattr(self, name)
            if v is None and name != 'track_m':
                continue
            if not isinstance(v, numbers.Real) or isinstance(v, bool) or not math.isfinite(v) \
                    or v <= 0:
                raise ValueError(f'FileRoadSpec.{name} must be a positive finite number, '
                                 f'got {v!r}')
        if not isinstance(self.repeat, bool):
            raise ValueError(f'FileRoadSpec.repeat must be true or false, got {self.repeat!r}')
        if not isinstance(self.ramp_in_m, numbers.Real) or not 0 <= self.ramp_in_m < 1e6:
            raise ValueError(f'FileRoadSpec.ramp_in_m must be >= 0, got {self.ramp_in_m!r}')

    @property
    def path(self) -> Path:
        """The file as a Path."""
        return Path(self.file)

    @property
    def kind(self) -> str:
        """'crg' or 'csv' (``format``, or the file's extension for 'auto')."""
        if self.format != 'auto':
            return self.format
        suffix = self.path.suffix.lower()
        if suffix in ('.crg', '.csv'):
            return suffix[1:]
        raise RoadFileError(f'road file {self.file}: cannot tell its format from the '
                            f'extension {suffix!r}: name it .crg or .csv, or set format')

    @classmethod
    def from_yaml_dict(cls, d: dict, base_dir: str | Path | None = None) -> FileRoadSpec:
        """Build from one entry of road.yaml (``model: file`` optional).

        Parameters
        ----------
        d : dict
            Field names of this class.
        base_dir : str or Path, optional
            Folder a relative ``file`` is relative to (the config folder).

        Raises
        ------
        ValueError
            For unknown keys or invalid values.
        """
        fields = dict(d)
        model = fields.pop('model', 'file')
        if model != 'file':
            raise ValueError(f"a road with a 'file' has model 'file', got {model!r}")
        names = set(cls.__dataclass_fields__)
        unknown = sorted(set(fields) - names)
        if unknown:
            raise ValueError(f'unknown file road keys {unknown}; valid keys: {sorted(names)}')
        if 'file' not in fields:
            raise ValueError("a file road needs the key 'file'")
        file = Path(str(fields['file'])).expanduser()
        if not file.is_absolute() and base_dir is not None:
            file = Path(base_dir) / file
        fields['file'] = str(file)
        return cls(**fields)


# ---------------------------------------------------------------------- reading
@dataclass(frozen=True, eq=False)
class RoadTracks:
    """The two wheel tracks of a road file as read (before resampling and offset).

    Attributes
    ----------
    u_m : np.ndarray
        Distance along the road, m, strictly increasing (n,).
    z_left_m, z_right_m : np.ndarray
        Elevations, m (n,); NaN where the file has no value.
    source : str
        What the tracks are, for messages (file and, for OpenCRG, the lateral positions).
    """

    u_m: np.ndarray
    z_left_m: np.ndarray
    z_right_m: np.ndarray
    source: str


def _error(path: str | Path, problem: str) -> RoadFileError:
    return RoadFileError(f'road file {path}: {problem}')


def _crg_header_lines(path: Path) -> list[str]:
    """The header lines of an OpenCRG file (up to the ``$$$$`` separator), ISO-8859-1."""
    lines = []
    with open(path, 'rb') as handle:
        for raw in handle:
            line = raw.decode('latin-1').rstrip('\r\n')
            if line.startswith('$$$$'):
                return lines
            lines.append(line)
            if len(lines) > 100_000:
                break
    raise _error(path, 'no $$$$ separator line between the header and the data: not an '
                       'OpenCRG file, or a truncated one')


def crg_channel_units(path: str | Path) -> list[tuple[str, str, str]]:
    """The ``U:`` and ``D:`` channels of an OpenCRG header: (kind, name, unit) each.

    Kind is 'U' (the reference line's u) or 'D' (a data channel), as in the
    ``$KD_DEFINITION`` block of the ASAM OpenCRG file format.
    """
    out = []
    for line in _crg_header_lines(Path(path)):
        text = line.split('!', 1)[0].strip()
        if len(text) > 2 and text[0] in 'UD' and text[1] == ':':
            parts = [p.strip() for p in text[2:].split(',')]
            out.append((text[0], parts[0], parts[1] if len(parts) > 1 else ''))
    return out


def _check_crg_units(path: Path) -> None:
    """Refuse an OpenCRG file whose u or elevation channels are not in metres."""
    channels = crg_channel_units(path)
    if not channels:
        raise _error(path, 'no U: or D: channel in its $KD_DEFINITION block: not an '
                           'OpenCRG file')
    for kind, name, unit in channels:
        length_channel = kind == 'U' or 'long section' in name.lower() or \
            name.lower() in ('reference line z', 'reference line elevation')
        if length_channel and unit != UNIT_M:
            raise _error(path, f"channel '{name}' is in {unit or 'no unit'!s}, expected "
                               f"{UNIT_M}: the road's distances and elevations must be in "
                               'metres')


def crg_header_values(path: str | Path) -> dict[str, float]:
    """The numeric entries of an OpenCRG header's ``$ROAD_CRG`` block, by key.

    Also the ``U:`` channel's start and increment (keys ``U_start``, ``U_increment``).
    """
    values: dict[str, float] = {}
    block = ''
    for line in _crg_header_lines(Path(path)):
        text = line.split('!', 1)[0].strip()
        if text.startswith('$'):
            block = text[1:].strip().upper()
            continue
        if block == 'ROAD_CRG' and '=' in text:
            key, _, value = text.partition('=')
            try:
                values[key.strip().lower()] = float(value.strip())
            except ValueError:
                continue
        elif text.startswith('U:'):
            parts = [part.strip() for part in text[2:].split(',')]
            for key, part in zip(('U_start', 'U_increment'), parts[2:4]):
                try:
                    values[key] = float(part)
                except ValueError:
                    continue
    return values


def _check_crg_header_against_data(path: Path, road: Any) -> None:
    """Refuse an OpenCRG file whose header and data disagree (rows, length, increments).

    The ``$ROAD_CRG`` block's reference line from ``reference_line_start_u`` to
    ``reference_line_end_u`` in steps of ``reference_line_increment`` gives the number
    of data rows (cross sections); ``long_section_v_right`` to ``long_section_v_left``
    in steps of ``long_section_v_increment`` the number of long sections.  A file cut
    short (e.g. after 500 of 1001 rows) has fewer rows than its header says.
    """
    h = crg_header_values(path)
    inc = h.get('reference_line_increment')
    if inc is not None and 'U_increment' in h and not np.isclose(inc, h['U_increment'],
                                                                  rtol=1e-9, atol=0.0):
        raise _error(path, f'reference_line_increment {inc:g} m in the header, but the U: '
                           f"channel's increment is {h['U_increment']:g} m")
    inc = inc if inc is not None else h.get('U_increment')
    start = h.get('reference_line_start_u', h.get('U_start'))
    end = h.get('reference_line_end_u')
    rows = int(road.nu)
    if inc is not None and start is not None and end is not None and inc > 0:
        expected = int(round((end - start) / inc)) + 1
        if expected != rows:
            raise _error(path, f'the header (reference_line_start_u {start:g} to '
                               f'reference_line_end_u {end:g} m, reference_line_increment '
                               f'{inc:g} m) gives {expected} data rows, {end - start:g} m; '
                               f'the data has {rows} rows, {(rows - 1) * inc:g} m: a '
                               'truncated or damaged file')
    keys = ('long_section_v_right', 'long_section_v_left', 'long_section_v_increment')
    if all(key in h for key in keys) and h[keys[2]] > 0:
        right, left, v_inc = (h[key] for key in keys)
        expected = int(round((left - right) / v_inc)) + 1
        if expected != int(road.nv):
            raise _error(path, f'the header (long_section_v_right {right:g} to '
                               f'long_section_v_left {left:g} m, long_section_v_increment '
                               f'{v_inc:g} m) gives {expected} long sections; the data has '
                               f'{int(road.nv)}: a damaged file')


def read_crg_tracks(path: str | Path, track_m: float) -> RoadTracks:
    """Read the wheel tracks at +-track/2 from the reference line of an OpenCRG file.

    Parameters
    ----------
    path : str or Path
        The ``.crg`` file.
    track_m : float
        Distance between the wheel tracks, m.

    Returns
    -------
    RoadTracks
        u along the reference line and the two tracks' absolute elevations (grid plus
        reference-line elevation and banking), NaN where the grid has none.

    Raises
    ------
    RoadFileError
        Missing, unreadable, damaged or truncated file (PyOpenCRG's checks, named),
        units other than metres, or tracks outside the road's width.
    """
    import pyopencrg

    path = Path(path)
    if not path.is_file():
        raise _error(path, 'no such file')
    _check_crg_units(path)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            road = pyopencrg.read(str(path), apply_mods=False, check=True)
            if road.mods is not None:  # the file's own modifiers, as a simulator applies them
                road = road.apply_mods()
    except (pyopencrg.CrgCheckError, ValueError, OSError, EOFError) as error:
        text = str(error).replace(str(path) + ': ', '').replace(str(path), '').strip()
        text = text.split('\nTo open it anyway')[0].strip()
        raise _error(path, f'not a readable OpenCRG road: {text}') from None
    _check_crg_header_against_data(path, road)  # before PyOpenCRG's warnings about it
    for warning in caught:
        if not issubclass(warning.category, ResourceWarning):
            warnings.warn_explicit(warning.message, warning.category, warning.filename,
                                   warning.lineno)
    v = np.asarray(road.v, dtype=float)
    z = np.asarray(road.z, dtype=float)
    half = 0.5 * float(track_m)
    if v.size < 2 or v.min() > -half or v.max() < half:
        raise _error(path, f'the wheel tracks at +-{half:.3f} m lie outside the road, which '
                           f'spans v = {v.min():.3f} to {v.max():.3f} m from its reference '
                           'line')
    zr = np.asarray(road.zr, dtype=float)
    banking = np.asarray(road.banking, dtype=float)

    def track(v_t: float) -> np.ndarray:
        j = int(np.clip(np.searchsorted(v, v_t, side='right') - 1, 0, v.size - 2))
        t = (v_t - v[j]) / (v[j + 1] - v[j])
        if t <= 0.0:
            grid = z[:, j]
        elif t >= 1.0:
            grid = z[:, j + 1]
        else:
            grid = (1.0 - t) * z[:, j] + t * z[:, j + 1]
        return grid + zr + banking * v_t

    u = np.asarray(road.u, dtype=float)
    return RoadTracks(u - u[0], track(half), track(-half),
                      f'{path} (wheel tracks at v = +-{half:.3f} m)')


_UNIT_PATTERNS = (re.compile(r'\[\s*([^\]]*?)\s*\]'), re.compile(r'\(\s*([^)]*?)\s*\)'),
                  re.compile(r'_([A-Za-z]+)$'))


def _header_unit(name: str) -> str | None:
    for pattern in _UNIT_PATTERNS:
        match = pattern.search(name.strip())
        if match:
            return match.group(1)
    return None


def read_csv_tracks(path: str | Path) -> RoadTracks:
    """Read a CSV road: header, then distance, left and right elevation in m.

    Raises
    ------
    RoadFileError
        Missing file, no header, a unit other than m, a line without three numbers,
        a distance that does not increase, or fewer than two samples.
    """
    path = Path(path)
    if not path.is_file():
        raise _error(path, 'no such file')
    try:
        lines = path.read_text(encoding='utf-8').splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise _error(path, f'cannot read it as text: {error}') from None
    body = [(k + 1, line) for k, line in enumerate(lines)
            if line.strip() and not line.lstrip().startswith('#')]
    if not body:
        raise _error(path, 'empty: expected a header line and rows of distance, left and '
                           'right elevation in m')
    line_no, header = body[0]
    names = [name.strip() for name in header.split(',')]
    example = 'e.g. distance_m,left_m,right_m'
    if len(names) != 3:
        raise _error(path, f'line {line_no}: the header has {len(names)} columns, expected 3 '
                           f'(distance, left, right), {example}')
    try:
        float(names[0])
        numeric = True
    except ValueError:
        numeric = False
    if numeric:
        raise _error(path, f'line {line_no}: the first line is a number, expected a header '
                           f'naming the columns and their unit, {example}')
    for k, name in enumerate(names):
        unit = _header_unit(name)
        if unit is None:
            raise _error(path, f"column {k + 1} ('{name}') names no unit: write it in the "
                               f'header, {example}')
        if unit != UNIT_M:
            raise _error(path, f"column {k + 1} ('{name}') is in {unit}, expected {UNIT_M}: "
                               'distance and elevations must be in metres')
    lower = [name.lower() for name in names]
    if 'right' in lower[1] or 'left' in lower[2]:
        raise _error(path, f'the header names the columns {names}: the order must be '
                           'distance, left, right')
    rows = []
    for line_no, line in body[1:]:
        cells = [cell.strip() for cell in line.split(',')]
        if len(cells) != 3:
            raise _error(path, f'line {line_no}: {len(cells)} values, expected 3')
        try:
            rows.append([float(cell) if cell else math.nan for cell in cells])
        except ValueError:
            raise _error(path, f'line {line_no}: not three numbers: {line.strip()!r}') from None
    data = np.asarray(rows, dtype=float).reshape(-1, 3)
    if data.shape[0] < 2:
        raise _error(path, f'{data.shape[0]} data row(s): a road needs at least 2')
    u = data[:, 0]
    if not np.all(np.isfinite(u)):
        raise _error(path, 'a distance is missing or not finite')
    if not np.all(np.diff(u) > 0):
        k = int(np.argmax(np.diff(u) <= 0))
        raise _error(path, f'the distance must increase from row to row: {u[k]:g} m is '
                           f'followed by {u[k + 1]:g} m (data row {k + 2})')
    return RoadTracks(u - u[0], data[:, 1], data[:, 2], str(path))


def read_tracks(spec: FileRoadSpec) -> RoadTracks:
    """The wheel tracks of ``spec``'s file (OpenCRG or CSV), as read."""
    if spec.kind == 'crg':
        return read_crg_tracks(spec.file, spec.track_m)
    return read_csv_tracks(spec.file)


# ---------------------------------------------------------------------- profile
def _trim_missing(tracks: RoadTracks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut NaN borders; refuse a gap inside the road (RoadFileError with its position)."""
    u, zl, zr = tracks.u_m, np.asarray(tracks.z_left_m), np.asarray(tracks.z_right_m)
    both = np.isfinite(zl) & np.isfinite(zr)
    if not both.any():
        raise RoadFileError(f'road file {tracks.source}: no sample has a value on both tracks')
    first, last = int(np.argmax(both)), int(both.size - 1 - np.argmax(both[::-1]))
    inside = both[first:last + 1]
    if not inside.all():
        holes = np.flatnonzero(~inside) + first
        raise RoadFileError(
            f'road file {tracks.source}: {holes.size} sample(s) without a value inside the '
            f'road, the first at {u[holes[0]]:.3f} m, the last at {u[holes[-1]]:.3f} m: fill '
            'the gaps (e.g. PyOpenCRG fill_holes) or choose other wheel tracks')
    if last - first < 1:
        raise RoadFileError(f'road file {tracks.source}: fewer than 2 samples have a value on '
                            'both tracks')
    sl = slice(first, last + 1)
    return u[sl] - u[first], zl[sl], zr[sl]


def _resample(u: np.ndarray, z: np.ndarray, dx_m: float) -> tuple[np.ndarray, np.ndarray]:
    """z on x = 0, dx, ..., floor(L/dx) dx (box filter first when dx is coarser)."""
    du = float(np.median(np.diff(u)))
    width = int(round(dx_m / du))
    if width > 1:  # a centred box of width dx (half weights at its two ends)
        kernel = np.ones(width + 1)
        kernel[[0, -1]] = 0.5
        z = ndimage.convolve1d(z, kernel / width, mode='nearest')
    n = int(math.floor(u[-1] / dx_m + 1e-6))  # u of a file carries rounding errors
    x = np.arange(n + 1) * dx_m
    return x, np.interp(x, u, z)


@functools.lru_cache(maxsize=8)
def _file_profile(spec: FileRoadSpec, mtime_ns: int, size: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, z_left, z_right of the file after steps 1-3 (cached per file version)."""
    tracks = read_tracks(spec)
    u, zl, zr = _trim_missing(tracks)
    # the file's own spacing, to 9 digits (u = u0 + k du in a file carries rounding errors)
    dx = spec.dx_m if spec.dx_m is not None else float(f'{np.median(np.diff(u)):.9g}')
    if u[-1] < dx:
        raise _error(spec.file, f'{u[-1]:.4g} m long, shorter than one sample spacing '
                                f'({dx:g} m)')
    x, zl = _resample(u, zl, dx)
    _, zr = _resample(u, zr, dx)
    offset = 0.5 * (np.mean(zl) + np.mean(zr))
    return x, zl - offset, zr - offset


def _stat(spec: FileRoadSpec) -> tuple[int, int]:
    try:
        st = spec.path.stat()
    except OSError:
        raise _error(spec.file, 'no such file') from None
    return st.st_mtime_ns, st.st_size


def file_length_m(spec: FileRoadSpec) -> float:
    """Length of the file's road after its missing borders are cut, m."""
    x, _, _ = _file_profile(replace(spec, length_m=None, repeat=False, ramp_in_m=0.0),
                            *_stat(spec))
    return float(x[-1])


def repetition_note(period_m: float, speed_mps: float | None = None) -> str:
    """What repeating a road of ``period_m`` does: the period and, at a speed, its frequency."""
    text = f'the road repeats every {period_m:.2f} m'
    if speed_mps:
        text += (f': a periodic excitation at {speed_mps / period_m:.2f} Hz at '
                 f'{3.6 * speed_mps:.0f} km/h (body bounce lies near 1-1.5 Hz, wheel hop '
                 'near 10-12 Hz)')
    else:
        text += ', a periodic excitation at speed / period'
    return text


def _repeat(x: np.ndarray, z: np.ndarray, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Copies of z (each tilted so that its ends meet) on a grid up to ``length_m``."""
    dx = float(x[1] - x[0])
    period = z - (z[-1] - z[0]) * x / x[-1]  # period[-1] == period[0]: no step at a join
    one = period[:-1]
    n = int(math.floor(length_m / dx + 1e-6))
    reps = -(-(n + 1) // one.size)
    return np.arange(n + 1) * dx, np.tile(one, reps)[: n + 1]


def file_road_profile(spec: FileRoadSpec) -> RoadProfile:
    """The wheel tracks of a file road as a :class:`~suspension_tuning.vehicle.road.RoadProfile`.

    Steps 1-5 of the module docstring.  A ``length_m`` longer than the file without
    ``repeat`` raises; with it the file is repeated (warning naming the period).

    Raises
    ------
    RoadFileError
        A bad file, or a file shorter than ``length_m`` without ``repeat``.
    """
    x, zl, zr = _file_profile(replace(spec, length_m=None, repeat=False, ramp_in_m=0.0),
                              *_stat(spec))
    length = float(x[-1])
    if spec.length_m is not None and spec.length_m > length + 1e-9:
        if not spec.repeat:
            raise _error(spec.file, f'{length:.2f} m long, shorter than the {spec.length_m:.1f} '
                                    'm asked for: give a longer road, or repeat this one '
                                    f'(repeat: true; {repetition_note(length)})')
        x_long, zl = _repeat(x, zl, spec.length_m)
        _, zr = _repeat(x, zr, spec.length_m)
        x = x_long
    elif spec.length_m is not None:
        keep = x <= spec.length_m + 1e-9
        x, zl, zr = x[keep], zl[keep], zr[keep]
    if spec.ramp_in_m > 0:
        r = np.clip(x / spec.ramp_in_m, 0.0, 1.0)
        w = 0.5 * (1.0 - np.cos(np.pi * r))
        zl, zr = zl * w, zr * w
    return RoadProfile(x_m=x, z_left_m=zl, z_right_m=zr, spec=spec)


def fit_to_run(spec: FileRoadSpec, needed_m: float, speed_mps: float | None = None,
               what: str = 'the run') -> FileRoadSpec:
    """The spec to drive a run of ``needed_m``: refused, repeated or as it is.

    Parameters
    ----------
    spec : FileRoadSpec
        The road.
    needed_m : float
        Road length the run needs, m (start position, distance driven and the vehicle).
    speed_mps : float, optional
        The run's speed, to name the repetition's frequency.
    what : str
        The run, for the messages.

    Returns
    -------
    FileRoadSpec
        ``spec`` itself when the file (or its ``length_m``) covers the run; with
        ``length_m = needed_m`` when it is repeated (with a RoadRepetitionWarning).

    Raises
    ------
    RoadFileError
        The file is shorter than the run and ``repeat`` is not set.
    """
    if spec.length_m is not None and spec.length_m >= needed_m:
        file_length_m(spec)  # a bad file is refused now, not in the middle of a run
        return spec
    length = file_length_m(spec)
    if length >= needed_m:
        return spec
    if not spec.repeat:
        raise _error(spec.file, f'{length:.2f} m long, shorter than {what} ({needed_m:.1f} m): '
                                'give a longer road, or repeat this one (road.yaml key repeat: '
                                f'true, or tune --repeat-road; '
                                f'{repetition_note(length, speed_mps)})')
    warnings.warn(f'road file {spec.file} ({length:.2f} m) is repeated {needed_m / length:.1f} '
                  f'times to cover {what} ({needed_m:.1f} m): '
                  f'{repetition_note(length, speed_mps)}', RoadRepetitionWarning, stacklevel=2)
    return replace(spec, length_m=float(needed_m))


# ---------------------------------------------------------------------- writing
def write_crg(profile: RoadProfile, path: str | Path, track_m: float,
              fmt: str = 'KDBI', comment: str = '') -> Path:
    """Write a profile's two wheel tracks as an OpenCRG file (PyOpenCRG's writer).

    The grid has two long sections, the right track at v = -track/2 and the left at
    +track/2, on a straight reference line; the file holds an empty modifier section,
    so that every reader keeps the data where it is.

    Parameters
    ----------
    profile : RoadProfile
        Uniformly sampled tracks.
    path : str or Path
        Output file.
    track_m : float
        Distance between the wheel tracks, m.
    fmt : str
        OpenCRG data format: 'KDBI' (binary, double; default, exact), 'KRBI' (binary,
        single), 'LDFI' or 'LRFI' (text).
    comment : str
        Text for the file's comment block.
    """
    import pyopencrg

    x = np.asarray(profile.x_m, dtype=float)
    dx = float(x[1] - x[0])
    if not np.allclose(np.diff(x), dx, rtol=1e-6, atol=1e-12):
        raise ValueError('write_crg needs a uniformly sampled profile')
    z = np.column_stack([profile.z_right_m, profile.z_left_m])
    half = 0.5 * float(track_m)
    road = pyopencrg.CrgRoad(z, u_inc=dx, v=[-half, half], u_start=float(x[0]),
                             comments=[line for line in comment.splitlines()] or None)
    road.mods = {}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    road.save(str(path), fmt=fmt)
    return path


def write_csv(profile: RoadProfile, path: str | Path, comment: str = '') -> Path:
    """Write a profile as a CSV road (``distance_m,left_m,right_m``, 9 significant digits)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = np.column_stack([profile.x_m, profile.z_left_m, profile.z_right_m])
    head = ''.join(f'# {line}\n' for line in comment.splitlines())
    with open(path, 'w', encoding='utf-8') as handle:
        handle.write(head + 'distance_m,left_m,right_m\n')
        np.savetxt(handle, data, fmt='%.9g', delimiter=',')
    return path
