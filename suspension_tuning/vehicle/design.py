"""Design variables of the tuning problem (Thoresson et al. 2009, Part 1, eqs. 4-8).

The optimiser works on normalised variables ``x`` in ``[X_LOWER, X_UPPER]``; the vehicle
model works on physical settings per axle: a damper force scale factor (dpsf) and a
spring variable, the static gas volume of a gas spring in m^3 or, for a coil-sprung
vehicle, a spring rate in N/m.  What each variable is called, its range and the
baseline vehicle's value come from config/design_space.yaml (:class:`DesignSpace`;
the defaults are the paper's: dpsf 0.1-3, gas volume 0.1-0.6 L).  Eq. 4 maps a
physical value ``v`` in ``[v_low, v_high]`` to ``x = (v - v_low) / (v_high - v_low)``.
Note that the paper's lower bound ``x = 0.001`` (eqs. 6, 8) therefore maps to a value
just above ``v_low`` (``dpsf = 0.1029`` and ``gvol = 0.1005 L`` for the paper's ranges):
that is the paper's choice and is kept.

Two variable sets exist (section 5.1):

* 2 variables ``(dpsf, gvol)``, identical front and rear (eq. 5);
* 4 variables ``(dpsf_front, gvol_front, dpsf_rear, gvol_rear)`` (eq. 7).

All functions accept a single design of shape ``(n,)`` or a batch of shape
``(batch, n)`` and return batched arrays.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.paths import config_dir, read_yaml
from suspension_tuning.units import UNITS, known_units, unit_suffix

X_LOWER = 0.001
"""Lower bound of every normalised design variable [P eqs. 6, 8]."""
X_UPPER = 1.0
"""Upper bound of every normalised design variable [P eqs. 6, 8]."""

VARIABLE_NAMES = {
    2: ('dpsf', 'gvol'),
    4: ('dpsf_front', 'gvol_front', 'dpsf_rear', 'gvol_rear'),
}
"""Names of the normalised variables for the 2- and 4-variable problems [P eqs. 5, 7]."""

DESIGN_SPACE_FILE = 'design_space.yaml'
"""The design space's file in the configuration folder (config/)."""
#: Spring variables the models know: a gas spring's static volume, a coil spring's rate.
SPRING_QUANTITIES = ('volume', 'stiffness')
AXLES = ('front', 'rear')


@dataclass(frozen=True, eq=False)
class AxleSettings:
    """Physical settings per axle for a batch of designs.

    The spring of a design is either a gas spring (static gas volume, the 4S4 strut)
    or a coil spring (rate); the other pair of arrays is None.

    Attributes
    ----------
    dpsf_front, dpsf_rear : np.ndarray
        Damper force scale factors, dimensionless, shape (batch,).
    gas_volume_front_m3, gas_volume_rear_m3 : np.ndarray or None
        Static gas volumes in m^3, shape (batch,).
    stiffness_front_n_per_m, stiffness_rear_n_per_m : np.ndarray or None
        Coil spring rates per strut in N/m, shape (batch,).
    """

    dpsf_front: np.ndarray
    gas_volume_front_m3: np.ndarray | None
    dpsf_rear: np.ndarray
    gas_volume_rear_m3: np.ndarray | None
    stiffness_front_n_per_m: np.ndarray | None = None
    stiffness_rear_n_per_m: np.ndarray | None = None
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    """Settings beyond the paper's, by ``<target>_<axle>`` (SI, (batch,) each):
    ``dpsf_rebound_front`` (then ``dpsf_front`` scales the compression half only),
    ``anti_roll_bar_rear`` (N m/rad), ``gas_volume_stiff_front`` (m^3), ``dpsf_high_rear``...
    (:data:`TARGETS`).  Empty for the paper's 2- and 4-variable designs."""

    def __post_init__(self) -> None:
        """Check that exactly one spring kind is given, on both axles."""
        gas = (self.gas_volume_front_m3, self.gas_volume_rear_m3)
        coil = (self.stiffness_front_n_per_m, self.stiffness_rear_n_per_m)
        if not ((all(v is not None for v in gas) and all(v is None for v in coil))
                or (all(v is None for v in gas) and all(v is not None for v in coil))):
            raise ValueError('AxleSettings need either gas volumes or spring rates, on both '
                             'axles')

    @property
    def batch_size(self) -> int:
        """Number of designs in the batch."""
        return int(np.shape(self.dpsf_front)[0])

    @property
    def spring_quantity(self) -> str:
        """'volume' (gas springs) or 'stiffness' (coil springs)."""
        return 'volume' if self.gas_volume_front_m3 is not None else 'stiffness'

    def spring(self, axle: str) -> np.ndarray:
        """The spring variable of ``axle`` ('front' or 'rear'), SI (m^3 or N/m)."""
        if self.spring_quantity == 'volume':
            value = self.gas_volume_front_m3 if axle == 'front' else self.gas_volume_rear_m3
        else:
            value = (self.stiffness_front_n_per_m if axle == 'front'
                     else self.stiffness_rear_n_per_m)
        return np.asarray(value, dtype=float)

    def dpsf(self, axle: str) -> np.ndarray:
        """The damper scale factor of ``axle`` ('front' or 'rear'): of the compression half
        when :meth:`dpsf_rebound` differs, else of the whole damper table.
        """  # noqa: D205
        return np.asarray(self.dpsf_front if axle == 'front' else self.dpsf_rear, dtype=float)

    def dpsf_rebound(self, axle: str) -> np.ndarray:
        """The scale factor of the rebound half of ``axle``'s damper table (default: dpsf)."""
        value = self.extra.get(f'dpsf_rebound_{axle}')
        return self.dpsf(axle) if value is None else np.asarray(value, dtype=float)

    def anti_roll_bar(self, axle: str) -> np.ndarray | None:
        """The design's anti-roll-bar stiffness of ``axle`` in N m/rad, or None (the
        vehicle's, config/vehicle.yaml).
        """  # noqa: D205
        value = self.extra.get(f'anti_roll_bar_{axle}')
        return None if value is None else np.asarray(value, dtype=float)

    def for_mode(self, mode: str) -> AxleSettings:
        """The settings a one-state model of ``mode`` sees (the simplified models).

        A design that sets a 4S4 state explicitly (``gas_volume_soft``, ``dpsf_low`` in
        'ride'; ``gas_volume_stiff``, ``dpsf_high`` in 'handling') gives that state's
        values as the spring and the damper (both halves) of the result; otherwise the
        settings are returned unchanged.
        """
        spring_key, damper_key = (('gas_volume_soft', 'dpsf_low') if mode == 'ride'
                                  else ('gas_volume_stiff', 'dpsf_high'))
        if not any(k.startswith((spring_key, damper_key)) for k in self.extra):
            return self
        dpsf = {a: self.extra.get(f'{damper_key}_{a}', self.dpsf(a)) for a in AXLES}
        spring = {a: self.extra.get(f'{spring_key}_{a}', self.spring(a)) for a in AXLES}
        extra = {}
        for a in AXLES:
            for key in (f'anti_roll_bar_{a}',) + (
                    () if f'{damper_key}_{a}' in self.extra else (f'dpsf_rebound_{a}',)):
                if key in self.extra:
                    extra[key] = self.extra[key]
        return AxleSettings.of(dpsf, spring, self.spring_quantity, extra)

    @classmethod
    def of(cls, dpsf: Mapping[str, np.ndarray], spring: Mapping[str, np.ndarray],
           spring_quantity: str, extra: Mapping[str, np.ndarray] | None = None
           ) -> AxleSettings:
        """Settings from per-axle dpsf and spring arrays (SI) of a spring quantity."""
        more = {k: np.atleast_1d(np.asarray(v, dtype=float)).copy()
                for k, v in (extra or {}).items()}
        arrays = {axle: np.atleast_1d(np.asarray(spring[axle], dtype=float)).copy()
                  for axle in AXLES}
        dpsf_f = np.atleast_1d(np.asarray(dpsf['front'], dtype=float)).copy()
        dpsf_r = np.atleast_1d(np.asarray(dpsf['rear'], dtype=float)).copy()
        if spring_quantity == 'volume':
            return cls(dpsf_f, arrays['front'], dpsf_r, arrays['rear'], extra=more)
        return cls(dpsf_f, None, dpsf_r, None, arrays['front'], arrays['rear'], more)


@dataclass(frozen=True)
class AxleRange:
    """One axle's range and baseline of a design variable, SI."""

    low: float
    high: float
    baseline: float


@dataclass(frozen=True)
class DesignVariable:
    """One kind of design variable (the damper or the spring) on both axles.

    Attributes
    ----------
    role : str
        'damper' or 'spring'.
    name : str
        Its name in every report (``dpsf``, ``gas_volume``, ``spring_rate``...).
    quantity : str
        'dimensionless' (damper), 'volume' or 'stiffness' (spring).
    unit : str
        The unit it is given and shown in (a name of :data:`suspension_tuning.units.UNITS`).
    front, rear : AxleRange
        Range and baseline per axle, SI.
    """

    role: str
    name: str
    quantity: str
    unit: str
    front: AxleRange
    rear: AxleRange

    @property
    def factor(self) -> float:
        """SI value of one ``unit``."""
        return UNITS[self.unit][1]

    def in_unit(self, value_si: Any) -> Any:
        """An SI value in the variable's unit (``1 / factor`` exact for L, kN/m...)."""
        return value_si * (1.0 / self.factor)

    def axle(self, axle: str) -> AxleRange:
        """The range of ``axle`` ('front' or 'rear')."""
        return self.front if axle == 'front' else self.rear

    def label(self, axle: str | None = None) -> str:
        """``name[_axle][_unit]``: ``gas_volume_front_l``, ``dpsf_rear``, ``gas_volume_l``."""
        parts = [self.name, axle or '', unit_suffix(self.unit)]
        return '_'.join(p for p in parts if p)

    def key(self, axle: str) -> str:
        """``name_axle`` (no unit): the key of the FMU mapping's design section."""
        return f'{self.name}_{axle}'

    def span(self, axle: str | None = None) -> str:
        """``'0.1-0.6 L'``: the axle's range in the variable's unit, for messages."""
        r = self.axle(axle or 'front')
        unit = '' if UNITS[self.unit][0] == 'dimensionless' else f' {self.unit}'
        return f'{self.in_unit(r.low):g}-{self.in_unit(r.high):g}{unit}'


#: What a variable of the ``variables`` list may drive in the built-in model:
#: target -> (quantity, what it sets).  "The scenario's state": the ride scenario runs the
#: 4S4 in its ride mode (soft spring, low damping), the handling scenario in its handling
#: mode (stiff spring, high damping); the other state keeps config/strut_4s4.yaml's values.
TARGETS: dict[str, tuple[str, str]] = {
    'dpsf': ('dimensionless', "damper scale factor, both halves of the table, of the "
             "scenario's damping state (the paper's damper variable)"),
    'dpsf_compression': ('dimensionless', 'scale factor of the compression half of the '
                         "damper table, of the scenario's damping state"),
    'dpsf_rebound': ('dimensionless', 'scale factor of the rebound half of the damper table, '
                     "of the scenario's damping state"),
    'gas_volume': ('volume', "static gas volume of the scenario's spring state (the paper's "
                   'spring variable)'),
    'gas_volume_soft': ('volume', 'ride mode: static gas volume with both accumulators '
                        'connected (strut_4s4.yaml gas_volume_soft_l)'),
    'gas_volume_stiff': ('volume', "handling mode: the small accumulator's static gas "
                         'volume (strut_4s4.yaml gas_volume_stiff_l)'),
    'dpsf_low': ('dimensionless', 'ride mode: damper scale factor with the bypass open '
                 '(strut_4s4.yaml dpsf_low)'),
    'dpsf_high': ('dimensionless', 'handling mode: damper scale factor with the bypass '
                  'closed (strut_4s4.yaml dpsf_high)'),
    'anti_roll_bar': ('torsional_stiffness', 'anti-roll-bar stiffness of the axle '
                      '(vehicle.yaml anti_roll_bar)'),
}
#: Targets whose range may start at zero (an axle without a bar is a design).
ZERO_LOW_TARGETS = ('anti_roll_bar',)
#: Axles a variable of the ``variables`` list may act on ('both': front and rear alike).
VARIABLE_AXLES = ('front', 'rear', 'both')
#: Sizes a ``presets`` entry may not take: the paper's designs (eqs. 5, 7).
PAPER_SIZES = (2, 4)


@dataclass(frozen=True)
class Variable:
    """One design variable of an n-variable design (one entry of the optimiser's x).

    Attributes
    ----------
    name : str
        Its name without unit (``gas_volume_front``).
    target : str
        What it drives (a key of :data:`TARGETS`).
    axle : str
        'front', 'rear' or 'both'.
    unit : str
        The unit it is given and shown in.
    low, high, baseline : float
        Range and baseline vehicle's value, SI.
    """

    name: str
    target: str
    axle: str
    unit: str
    low: float
    high: float
    baseline: float

    @property
    def factor(self) -> float:
        """SI value of one ``unit``."""
        return UNITS[self.unit][1]

    def in_unit(self, value_si: Any) -> Any:
        """An SI value in the variable's unit."""
        return value_si * (1.0 / self.factor)

    @property
    def label(self) -> str:
        """``name[_unit]``: the name every report shows (``gas_volume_front_l``)."""
        return '_'.join(p for p in (self.name, unit_suffix(self.unit)) if p)

    def span(self) -> str:
        """``'0.1-0.6 L'``: the range in the variable's unit, for messages."""
        unit = '' if UNITS[self.unit][0] == 'dimensionless' else f' {self.unit}'
        return f'{self.in_unit(self.low):g}-{self.in_unit(self.high):g}{unit}'

    @property
    def axles(self) -> tuple[str, ...]:
        """The axles it sets."""
        return AXLES if self.axle == 'both' else (self.axle,)


def _general_variable(i: int, d: Any, source: str) -> Variable:
    """Read and check entry ``i`` of the ``variables`` list."""
    keys = ('name', 'target', 'axle', 'unit', 'low', 'high', 'baseline')
    where = f'variables[{i}]'
    if not isinstance(d, dict):
        raise _design_space_error(source, where, f'expected a mapping with keys {list(keys)}')
    if isinstance(d.get('name'), str):
        where = f'variables[{i}] ({d["name"]})'
    unknown = sorted(set(map(str, d)) - set(keys))
    missing = [k for k in keys if k not in d]
    if unknown or missing:
        raise _design_space_error(source, where, (f'unknown key(s) {unknown}; ' if unknown
                                                  else '') + (f'missing key(s) {missing}; '
                                                              if missing else '')
                                  + f'valid keys: {list(keys)}')
    name = d['name']
    if not isinstance(name, str) or not name.isidentifier():
        raise _design_space_error(source, f'{where}.name', 'expected a name of letters, '
                                  f'digits and underscores, got {name!r}')
    target = d['target']
    if target not in TARGETS:
        raise _design_space_error(source, f'{where}.target', f'unknown target {target!r}; '
                                  f'the built-in model offers {list(TARGETS)}')
    axle = d['axle']
    if axle not in VARIABLE_AXLES:
        raise _design_space_error(source, f'{where}.axle', f'{axle!r} is not one of '
                                  f'{list(VARIABLE_AXLES)}')
    quantity = TARGETS[target][0]
    unit = str(d['unit'])
    if unit not in UNITS or UNITS[unit][0] != quantity:
        raise _design_space_error(source, f'{where}.unit', f'{unit!r} is not a unit of '
                                  f'{quantity} (target {target}; known units: '
                                  f'{known_units(quantity)})')
    values = {}
    for k in ('low', 'high', 'baseline'):
        v = d[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise _design_space_error(source, f'{where}.{k}', f'expected a finite number, '
                                      f'got {v!r}')
        values[k] = float(v)
    lowest = 0.0 if target in ZERO_LOW_TARGETS else None
    if not (values['low'] < values['high']
            and (values['low'] > 0.0 if lowest is None else values['low'] >= lowest)):
        need = '0 <= low < high' if lowest is not None else '0 < low < high'
        raise _design_space_error(source, f'{where}.low', f'empty or invalid range: need '
                                  f'{need}, got low {values["low"]:g} and high '
                                  f'{values["high"]:g} {unit}')
    if not values['low'] <= values['baseline'] <= values['high']:
        raise _design_space_error(source, f'{where}.baseline', f'{values["baseline"]:g} '
                                  f'lies outside {values["low"]:g}-{values["high"]:g} {unit}')
    factor = UNITS[unit][1]
    return Variable(name, target, axle, unit, values['low'] * factor,
                    values['high'] * factor, values['baseline'] * factor)


def _presets(d: Any, variables: Mapping[str, Variable],
             source: str) -> dict[int, tuple[str, tuple[Variable, ...]]]:
    """Read and check the ``presets`` section: n -> (preset name, its variables)."""
    if not isinstance(d, dict):
        raise _design_space_error(source, 'presets', 'expected a mapping of preset names to '
                                  'lists of variable names')
    out: dict[int, tuple[str, tuple[Variable, ...]]] = {}
    for name, entries in d.items():
        where = f'presets.{name}'
        if not isinstance(entries, list) or not entries:
            raise _design_space_error(source, where, 'expected a non-empty list of variable '
                                      'names of the variables section')
        unknown = [e for e in entries if e not in variables]
        if unknown:
            raise _design_space_error(source, where, f'unknown variable(s) {unknown}; the '
                                      f'variables section has {list(variables)}')
        if len(set(entries)) != len(entries):
            raise _design_space_error(source, where, 'a variable is listed twice')
        chosen = tuple(variables[e] for e in entries)
        driven = [(v.target, a) for v in chosen for a in v.axles]
        twice = sorted({f'{t} {a}' for t, a in driven if driven.count((t, a)) > 1})
        clash = [f'{a}: dpsf with dpsf_compression or dpsf_rebound' for a in AXLES
                 if ('dpsf', a) in driven
                 and {('dpsf_compression', a), ('dpsf_rebound', a)} & set(driven)]
        if twice or clash:
            raise _design_space_error(source, where, 'two variables drive the same setting ('
                                      + ', '.join(twice + clash) + ')')
        n = len(chosen)
        if n in PAPER_SIZES:
            raise _design_space_error(source, where, f'{n} variables: 2 and 4 are the '
                                      "paper's designs (eqs. 5, 7, the damper and spring "
                                      'sections); give the preset another size')
        if n in out:
            raise _design_space_error(source, where, f'a second preset of {n} variables '
                                      f'({out[n][0]}): a design is chosen by its number of '
                                      'variables')
        out[n] = (str(name), chosen)
    return out


def _design_space_error(source: str, where: str, message: str) -> ValueError:
    return ValueError(f'{source}: {where}: {message}')


def _variable(role: str, d: Any, source: str) -> DesignVariable:
    """Read and check the ``damper`` or ``spring`` section."""
    allowed = ('name', 'unit', 'front', 'rear') + (('quantity',) if role == 'spring' else ())
    if not isinstance(d, dict):
        raise _design_space_error(source, role, 'expected a mapping with keys '
                                  f'{list(allowed)}')
    unknown = sorted(set(map(str, d)) - set(allowed))
    missing = [k for k in allowed if k not in d and k != 'quantity']
    if unknown or missing:
        raise _design_space_error(source, role, (f'unknown key(s) {unknown}; ' if unknown
                                                 else '') + (f'missing key(s) {missing}; '
                                                             if missing else '')
                                  + f'valid keys: {list(allowed)}')
    name = d['name']
    if not isinstance(name, str) or not name.isidentifier():
        raise _design_space_error(source, f'{role}.name', f'expected a name of letters, digits '
                                  f'and underscores, got {name!r}')
    quantity = 'dimensionless' if role == 'damper' else str(d.get('quantity', 'volume'))
    if role == 'spring' and quantity not in SPRING_QUANTITIES:
        raise _design_space_error(source, 'spring.quantity', f'{quantity!r} is not one of '
                                  f'{list(SPRING_QUANTITIES)}')
    unit = str(d['unit'])
    if unit not in UNITS or UNITS[unit][0] != quantity:
        what = ('the damper variable is a scale factor' if role == 'damper'
                else f'the spring quantity is {quantity}')
        raise _design_space_error(source, f'{role}.unit', f'{unit!r} is not a unit of '
                                  f'{quantity} ({what}; known units: {known_units(quantity)})')
    factor = UNITS[unit][1]
    ranges = {}
    for axle in AXLES:
        r = d[axle]
        where = f'{role}.{axle}'
        if not isinstance(r, dict) or set(r) != {'low', 'high', 'baseline'}:
            raise _design_space_error(source, where, 'expected {low: ..., high: ..., '
                                      f'baseline: ...}} in {unit}, got {r!r}')
        values = {}
        for k in ('low', 'high', 'baseline'):
            v = r[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise _design_space_error(source, f'{where}.{k}',
                                          f'expected a finite number, got {v!r}')
            values[k] = float(v)
        if not 0.0 < values['low'] < values['high']:
            raise _design_space_error(source, where, f'need 0 < low < high, got low '
                                      f'{values["low"]:g} and high {values["high"]:g} {unit}')
        if not values['low'] <= values['baseline'] <= values['high']:
            raise _design_space_error(source, f'{where}.baseline', f'{values["baseline"]:g} '
                                      f'lies outside {values["low"]:g}-{values["high"]:g} '
                                      f'{unit}')
        ranges[axle] = AxleRange(*(values[k] * factor for k in ('low', 'high', 'baseline')))
    return DesignVariable(role, name, quantity, unit, ranges['front'], ranges['rear'])


@dataclass(frozen=True)
class DesignSpace:
    """The design variables: names, units, ranges and baseline (config/design_space.yaml).

    Attributes
    ----------
    damper, spring : DesignVariable
        The damper scale factor and the spring variable, each on both axles.
    source : str
        Where it was read from, for messages.
    """

    damper: DesignVariable
    spring: DesignVariable
    source: str = DESIGN_SPACE_FILE
    presets: Mapping[int, tuple[str, tuple[Variable, ...]]] = field(default_factory=dict)
    """Designs beyond the paper's by their number of variables: n -> (name, variables)."""
    catalogue: tuple[Variable, ...] = ()
    """Every entry of the ``variables`` section, in order."""

    @classmethod
    def from_mapping(cls, d: Any, source: str = DESIGN_SPACE_FILE) -> DesignSpace:
        """Read and check a design space given as a parsed YAML mapping.

        Raises
        ------
        ValueError
            Unknown or missing keys, a unit that does not fit, a range with low >= high
            or low <= 0, or a baseline outside its range; the message names the key.
        """
        if (not isinstance(d, dict) or not {'damper', 'spring'} <= set(d)
                or not set(d) <= {'damper', 'spring', 'variables', 'presets'}):
            keys = sorted(d) if isinstance(d, dict) else type(d).__name__
            raise ValueError(f'{source}: expected the sections damper and spring (and '
                             f'optionally variables and presets), got {keys}')
        entries = d.get('variables') or []
        if not isinstance(entries, list):
            raise _design_space_error(source, 'variables', 'expected a list of variables')
        catalogue = tuple(_general_variable(i, e, source) for i, e in enumerate(entries))
        by_name: dict[str, Variable] = {}
        for i, v in enumerate(catalogue):
            if v.name in by_name:
                raise _design_space_error(source, f'variables[{i}].name', f'{v.name!r} is '
                                          'given twice')
            by_name[v.name] = v
        presets = _presets(d['presets'], by_name, source) if 'presets' in d else {}
        return cls(_variable('damper', d['damper'], source),
                   _variable('spring', d['spring'], source), source, presets, catalogue)

    @property
    def sizes(self) -> tuple[int, ...]:
        """The numbers of variables a design may have: 2, 4 and the presets'."""
        return tuple(sorted(set(PAPER_SIZES) | set(self.presets)))

    def check_size(self, n_vars: int) -> None:
        """Raise ValueError naming the sizes on offer when ``n_vars`` is not one."""
        if n_vars not in self.sizes:
            extra = ', '.join(f'{n} ({name})' for n, (name, _) in sorted(self.presets.items()))
            raise ValueError('n_vars must be 2 or 4 (paper section 5.1)'
                             + (f' or a preset of {self.source}: {extra}' if extra else '')
                             + f', got {n_vars!r}')

    def design_variables(self, n_vars: int) -> tuple[Variable, ...]:
        """The variables of an n-variable design in x's order, each with its range.

        For 2 and 4 variables they are the paper's (eqs. 5, 7: targets 'dpsf' and
        'gas_volume'), from the damper and spring sections.
        """
        self.check_size(n_vars)
        if n_vars in self.presets:
            return self.presets[n_vars][1]
        out = []
        for var, axle in self.variables(n_vars):
            r = var.axle(axle or 'front')
            target = 'dpsf' if var.role == 'damper' else 'gas_volume'
            name = '_'.join(p for p in (var.name, axle or '') if p)
            out.append(Variable(name, target, axle or 'both', var.unit, r.low, r.high,
                                r.baseline))
        return tuple(out)

    def as_dict(self) -> dict[str, Any]:
        """The design space as config/design_space.yaml writes it (its own units)."""
        def section(v: DesignVariable) -> dict[str, Any]:
            out: dict[str, Any] = {'name': v.name, 'unit': v.unit}
            if v.role == 'spring':
                out['quantity'] = v.quantity
            for axle in AXLES:
                r = v.axle(axle)
                out[axle] = {k: v.in_unit(getattr(r, k)) for k in ('low', 'high', 'baseline')}
            return out
        out = {'damper': section(self.damper), 'spring': section(self.spring)}
        if self.catalogue:
            out['variables'] = [
                {'name': v.name, 'target': v.target, 'axle': v.axle, 'unit': v.unit,
                 **{k: v.in_unit(getattr(v, k)) for k in ('low', 'high', 'baseline')}}
                for v in self.catalogue]
        if self.presets:
            out['presets'] = {name: [v.name for v in vs] for name, vs in self.presets.values()}
        return out

    def variables(self, n_vars: int) -> list[tuple[DesignVariable, str | None]]:
        """The variables of an n-variable design in order, with their axle (None: both).

        Raises
        ------
        ValueError
            n_vars not 2 or 4, or a 2-variable design (eq. 5: both axles alike) of a
            variable whose front and rear entries differ.
        """
        if n_vars not in VARIABLE_NAMES:
            self.check_size(n_vars)
            raise ValueError(f'a {n_vars}-variable design is a preset of general variables: '
                             'use design_variables()')
        if n_vars == 4:
            return [(self.damper, 'front'), (self.spring, 'front'), (self.damper, 'rear'),
                    (self.spring, 'rear')]
        for v in (self.damper, self.spring):
            if v.front != v.rear:
                raise ValueError(
                    f'{self.source}: a 2-variable design (eq. 5) sets both axles alike, but '
                    f'the front and rear entries of {v.name} differ ({v.span("front")}, '
                    f'baseline {v.in_unit(v.front.baseline):g}; {v.span("rear")}, baseline '
                    f'{v.in_unit(v.rear.baseline):g}): use 4 variables or make them equal')
        return [(self.damper, None), (self.spring, None)]

    def names(self, n_vars: int) -> tuple[str, ...]:
        """Physical names of an n-variable design with units (``gas_volume_front_l``)."""
        if n_vars in self.presets:
            return tuple(v.label for v in self.presets[n_vars][1])
        return tuple(v.label(axle) for v, axle in self.variables(n_vars))

    def units(self, n_vars: int) -> tuple[str, ...]:
        """The unit of each variable of an n-variable design (``'-'``, ``'L'``...)."""
        return tuple(v.unit for v in self.design_variables(n_vars))

    def physical_names(self, n_vars: int | None = None) -> tuple[str, ...]:
        """The names every report shows: the four per-axle ones for the paper's designs
        (a 2-variable design too), a preset's own names for its size.
        """  # noqa: D205
        if n_vars is not None and n_vars in self.presets:
            return self.names(n_vars)
        return self.names(4)

    def physical_units(self, n_vars: int | None = None) -> tuple[str, ...]:
        """The unit of each of :meth:`physical_names` (``'-'``, ``'L'``, ``'kN.m/rad'``)."""
        if n_vars is not None and n_vars in self.presets:
            return self.units(n_vars)
        return self.units(4)

    def bounds(self, n_vars: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper physical bounds (n_vars,), SI."""
        if n_vars in self.presets:
            vs = self.presets[n_vars][1]
            return np.array([v.low for v in vs]), np.array([v.high for v in vs])
        pairs = [(v.axle(axle or 'front').low, v.axle(axle or 'front').high)
                 for v, axle in self.variables(n_vars)]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def to_physical(self, x: np.ndarray, n_vars: int | None = None) -> AxleSettings:
        """Normalised designs to physical axle settings (inverse of eq. 4).

        Parameters
        ----------
        x : array_like
            Shape ``(n,)`` or ``(batch, n)`` with n = 2 (eq. 5) or 4 (eq. 7).
        n_vars : int, optional
            Expected number of variables; inferred from the last axis when omitted.

        Returns
        -------
        AxleSettings
            Arrays of shape (batch,).  A 2-variable design gives identical front and
            rear settings (eq. 5).

        Raises
        ------
        ValueError
            As :func:`validate_design`, or as :meth:`variables`.
        """
        if n_vars is None:
            shape = np.shape(x)
            if len(shape) not in (1, 2) or shape[-1] not in self.sizes:
                raise ValueError(
                    f'design must have shape (n,) or (batch, n) with n in {self.sizes} '
                    f'variables (paper eqs. 5, 7, and the presets of {self.source}), got '
                    f'shape {shape}'
                )
            n_vars = int(shape[-1])
        self.check_size(n_vars)
        arr = validate_design(x, n_vars)
        low, high = self.bounds(n_vars)
        v = denormalise(arr, low, high)
        if n_vars in self.presets:
            return self._preset_settings(self.presets[n_vars][1], v)
        if n_vars == 2:
            dpsf = {'front': v[:, 0], 'rear': v[:, 0]}
            spring = {'front': v[:, 1], 'rear': v[:, 1]}
        else:
            dpsf = {'front': v[:, 0], 'rear': v[:, 2]}
            spring = {'front': v[:, 1], 'rear': v[:, 3]}
        return AxleSettings.of(dpsf, spring, self.spring.quantity)

    def _preset_settings(self, variables: tuple[Variable, ...], v: np.ndarray
                         ) -> AxleSettings:
        """Axle settings of a preset's physical values v (batch, n), SI: the settings the
        preset does not drive keep the damper and spring sections' baselines.
        """  # noqa: D205
        batch = v.shape[0]
        dpsf = {a: np.full(batch, self.damper.axle(a).baseline) for a in AXLES}
        spring = {a: np.full(batch, self.spring.axle(a).baseline) for a in AXLES}
        extra: dict[str, np.ndarray] = {}
        for j, var in enumerate(variables):
            for a in var.axles:
                if var.target == 'dpsf':
                    dpsf[a] = v[:, j].copy()
                elif var.target == 'dpsf_compression':
                    dpsf[a] = v[:, j].copy()
                    extra.setdefault(f'dpsf_rebound_{a}',
                                     np.full(batch, self.damper.axle(a).baseline))
                elif var.target == 'gas_volume':
                    spring[a] = v[:, j].copy()
                else:
                    extra[f'{var.target}_{a}'] = v[:, j].copy()
        return AxleSettings.of(dpsf, spring, self.spring.quantity, extra)

    def preset_values(self, settings: AxleSettings, n_vars: int) -> np.ndarray:
        """The physical values (batch, n_vars), SI, a preset's variables take in
        ``settings`` (the inverse of :meth:`to_physical` for a preset).
        """  # noqa: D205
        cols = []
        for var in self.presets[n_vars][1]:
            a = var.axles[0]
            if var.target in ('dpsf', 'dpsf_compression'):
                cols.append(settings.dpsf(a))
            elif var.target == 'gas_volume':
                cols.append(settings.spring(a))
            elif var.target == 'dpsf_rebound':
                cols.append(settings.dpsf_rebound(a))
            else:
                value = settings.extra.get(f'{var.target}_{a}')
                cols.append(np.full(settings.batch_size, var.baseline) if value is None
                            else np.asarray(value, dtype=float))
        return np.stack(cols, axis=1)

    def from_physical(self, settings: AxleSettings, n_vars: int) -> np.ndarray:
        """Physical axle settings to normalised designs, eq. 4.

        Returns
        -------
        np.ndarray
            Shape (batch, n_vars).  Values are not clipped to ``[X_LOWER, X_UPPER]``:
            the range's low end maps to x = 0 by eq. 4.

        Raises
        ------
        ValueError
            If n_vars is not 2 or 4, the spring is of another quantity, a value is not
            finite or lies outside its range, or, for n_vars = 2, front and rear
            settings differ.
        """
        if n_vars in self.presets:
            values = self.preset_values(settings, n_vars)
            for j, var in enumerate(self.presets[n_vars][1]):
                r = DesignVariable('preset', var.name, TARGETS[var.target][0], var.unit,
                                   AxleRange(var.low, var.high, var.baseline),
                                   AxleRange(var.low, var.high, var.baseline))
                _check_physical(var.label, values[:, j], var.low, var.high, r, self.source)
            low, high = self.bounds(n_vars)
            return normalise(values, low, high)
        self.variables(n_vars)  # checks n_vars (and equal axles for 2 variables)
        if settings.spring_quantity != self.spring.quantity:
            raise ValueError(f'the settings have a spring {settings.spring_quantity}, the '
                             f'design space ({self.source}) a spring {self.spring.quantity}')
        columns = {}
        for axle in AXLES:
            for var, value in ((self.damper, settings.dpsf(axle)),
                               (self.spring, settings.spring(axle))):
                r = var.axle(axle)
                columns[(var.role, axle)] = _check_physical(
                    var.label(axle), value, r.low, r.high, var, self.source)
        shapes = {c.shape for c in columns.values()}
        if len(shapes) != 1:
            raise ValueError(f'AxleSettings arrays must share one batch shape, got {shapes}')
        if n_vars == 2:
            if not (np.array_equal(columns['damper', 'front'], columns['damper', 'rear'])
                    and np.array_equal(columns['spring', 'front'], columns['spring', 'rear'])):
                raise ValueError('a 2-variable design needs identical front and rear settings '
                                 '(paper eq. 5); use n_vars=4')
            order = [('damper', 'front'), ('spring', 'front')]
        else:
            order = [('damper', 'front'), ('spring', 'front'), ('damper', 'rear'),
                     ('spring', 'rear')]
        low, high = self.bounds(n_vars)
        return normalise(np.stack([columns[k] for k in order], axis=1), low, high)

    def baseline_settings(self) -> AxleSettings:
        """The baseline vehicle's settings (batch of one)."""
        return AxleSettings.of({a: self.damper.axle(a).baseline for a in AXLES},
                               {a: self.spring.axle(a).baseline for a in AXLES},
                               self.spring.quantity)

    def baseline_x(self, n_vars: int) -> np.ndarray:
        """The baseline vehicle as a normalised design (n_vars,).

        A preset's baseline at the low end of its range (no front anti-roll bar) is taken
        as the paper's lower bound x = 0.001 (eqs. 6, 8), as a start point would be.
        """
        if n_vars in self.presets:
            vs = self.presets[n_vars][1]
            x = np.array([(v.baseline - v.low) / (v.high - v.low) for v in vs])
            return np.clip(x, X_LOWER, X_UPPER)
        return self.from_physical(self.baseline_settings(), n_vars)[0]

    def physical_values(self, x: Any) -> dict[str, float]:
        """One normalised design in physical units, by name.

        Units at the edge: each value in its variable's unit (``gas_volume_front_l`` in
        litres).  The paper's designs give the four per-axle names (a 2-variable design
        front and rear alike); a preset its own variables.
        """
        xv = np.asarray(x, dtype=float)
        n = int(np.shape(xv)[-1]) if xv.ndim else -1
        if n in self.presets:
            vs = self.presets[n][1]
            low, high = self.bounds(n)
            v = denormalise(validate_design(xv, n)[0], low, high)
            return {var.label: float(var.in_unit(v[j])) for j, var in enumerate(vs)}
        settings = self.to_physical(xv)
        out = {}
        for axle in AXLES:
            out[self.damper.label(axle)] = self.damper.in_unit(float(settings.dpsf(axle)[0]))
            out[self.spring.label(axle)] = self.spring.in_unit(float(settings.spring(axle)[0]))
        return {name: out[name] for name in self.physical_names()}

    def x_from_values(self, values: Mapping[str, float], n_vars: int) -> np.ndarray:
        """A normalised design (n_vars,) from physical values by name, in their units.

        Parameters
        ----------
        values : mapping
            Every name of :meth:`names` (``dpsf``, ``gas_volume_l`` for 2 variables;
            ``dpsf_front``, ``gas_volume_front_l``... for 4) to its value.

        Returns
        -------
        np.ndarray
            x by eq. 4; a value at the low end of its range (x = 0) is taken as the
            paper's lower bound x = 0.001 (eqs. 6, 8).

        Raises
        ------
        ValueError
            A missing or unknown name, or a value outside its range (the message gives
            the range in the variable's unit).
        """
        variables = self.design_variables(n_vars)
        names = self.names(n_vars)
        unknown = sorted(set(values) - set(names))
        missing = [n for n in names if n not in values]
        if unknown or missing:
            raise ValueError(('unknown name(s) ' + ', '.join(unknown) + '; ' if unknown else '')
                             + ('missing ' + ', '.join(missing) + '; ' if missing else '')
                             + f'a {n_vars}-variable start needs ' + ', '.join(names)
                             + f' ({self.source})')
        x = []
        for var, name in zip(variables, names):
            value = float(values[name]) * var.factor
            if not np.isfinite(value) or not var.low <= value <= var.high:
                raise ValueError(f'{name} = {values[name]!r} lies outside its range '
                                 f'{var.span()} ({self.source})')
            x.append((value - var.low) / (var.high - var.low))
        return np.clip(np.array(x), X_LOWER, X_UPPER)


def load_design_space(path: str | Path | None = None) -> DesignSpace:
    """The design space of config/design_space.yaml (or of ``path``).

    Raises
    ------
    ValueError
        The file is not a valid design space (see :meth:`DesignSpace.from_mapping`).
    """
    if path is None:
        return DesignSpace.from_mapping(read_yaml(config_dir() / DESIGN_SPACE_FILE),
                                        f'config/{DESIGN_SPACE_FILE}')
    return DesignSpace.from_mapping(read_yaml(path), str(path))


def _space(space: DesignSpace | None) -> DesignSpace:
    return space if space is not None else load_design_space()


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
    if isinstance(n_vars, bool) or not isinstance(n_vars, (int, np.integer)) or n_vars < 1:
        raise ValueError(f'n_vars must be a positive number of variables, got {n_vars!r}')
    try:
        arr = np.array(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'design vector is not numeric: {x!r}') from exc
    if arr.ndim == 1:
        arr = arr[np.newaxis, :]
    if arr.ndim != 2 or arr.shape[1] != n_vars:
        raise ValueError(
            f'design must have shape ({n_vars},) or (batch, {n_vars}) for the '
            f'{n_vars}-variable problem {VARIABLE_NAMES.get(n_vars, "")}, got shape '
            f'{np.shape(x)}'
        )
    if arr.shape[0] == 0:
        raise ValueError('design batch is empty')
    names = VARIABLE_NAMES.get(n_vars, tuple(f'variable {i}' for i in range(n_vars)))
    bad = ~np.isfinite(arr)
    if bad.any():
        b, i = np.argwhere(bad)[0]
        raise ValueError(f'design {b}: variable x[{i}] ({names[i]}) is not finite: '
                         f'{float(arr[b, i])}')
    out = (arr < X_LOWER) | (arr > X_UPPER)
    if out.any():
        b, i = np.argwhere(out)[0]
        raise ValueError(
            f'design {b}: variable x[{i}] ({names[i]}) = {float(arr[b, i])} is outside the '
            f'bounds [{X_LOWER}, {X_UPPER}] (paper eqs. 6, 8)'
        )
    return arr


def to_physical(x: np.ndarray, n_vars: int | None = None,
                space: DesignSpace | None = None) -> AxleSettings:
    """Convert normalised designs to physical axle settings (inverse of eq. 4).

    Parameters
    ----------
    x : array_like
        Shape ``(n,)`` or ``(batch, n)`` with n = 2 (eq. 5) or 4 (eq. 7).
    n_vars : int, optional
        Expected number of variables; inferred from the last axis when omitted.
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).

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
    return _space(space).to_physical(x, n_vars)


def _check_physical(name: str, value: np.ndarray, low: float, high: float,
                    var: DesignVariable, source: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f'{name} must be a 1-D array over the batch, got shape {arr.shape}')
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f'{name}[{i}] is not finite: {float(arr[i])}')
    out = (arr < low) | (arr > high)
    if out.any():
        i = int(np.argmax(out))
        raise ValueError(f'{name}[{i}] = {var.in_unit(arr[i]):g} is outside its range '
                         f'{var.in_unit(low):g}-{var.in_unit(high):g} {var.unit} ({source})')
    return arr


def from_physical(settings: AxleSettings, n_vars: int,
                  space: DesignSpace | None = None) -> np.ndarray:
    """Convert physical axle settings to normalised designs, eq. 4.

    Parameters
    ----------
    settings : AxleSettings
        Physical settings, arrays of shape (batch,).
    n_vars : int
        2 (front and rear must then be equal, eq. 5) or 4 (eq. 7).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).

    Returns
    -------
    np.ndarray
        Shape (batch, n_vars).  Values are not clipped to ``[X_LOWER, X_UPPER]``: the
        range's low end maps to x = 0 by eq. 4.

    Raises
    ------
    ValueError
        If n_vars is not 2 or 4, a value is not finite or lies outside its range, or,
        for n_vars = 2, front and rear settings differ.
    """
    return _space(space).from_physical(settings, n_vars)


def baseline_design(n_vars: int) -> np.ndarray:
    """The baseline vehicle's settings (config/design_space.yaml) as a normalised design."""
    return load_design_space().baseline_x(n_vars)
