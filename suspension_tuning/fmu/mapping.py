"""The mapping file of an FMU worker: which FMU variables carry what (docs/fmu.md).

:func:`load_mapping` reads and checks the YAML file alone (names, numbers, units,
required channels); :class:`suspension_tuning.fmu.model.FmuModel` then checks it
against the FMU.  Every problem is a :class:`MappingError` naming the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from suspension_tuning.fmu.units import UNITS, known_units
from suspension_tuning.vehicle.design import DesignSpace, load_design_space

CORNERS = ('fl', 'fr', 'rl', 'rr')
#: Keys of a design entry that maps the variable linearly onto the FMU parameter.
LINEAR_MAP_KEYS = ('name', 'scale', 'offset', 'unit')
#: Output channels: dimension, per wheel, and the scenarios needing them.
OUTPUTS: dict[str, tuple[str, bool, tuple[str, ...]]] = {
    'acc_driver': ('acceleration', False, ('ride',)),
    'acc_passenger': ('acceleration', False, ('ride',)),
    'roll': ('angle', False, ('handling',)),
    'roll_rate': ('angular_velocity', False, ('handling',)),
    'tyre_fz': ('force', True, ('ride', 'handling')),
    'steer': ('angle', False, ('handling',)),
    'slip_angle': ('angle', True, ('handling',)),
    'x': ('length', False, ()),
    'speed': ('velocity', False, ()),
}
SCENARIO_KEYS = {
    'common': ('start_time_s', 'stop_time_s', 'step_size_s', 'speed_kmh', 'speed_parameter',
               'parameters', 'design', 'outputs'),
    'ride': ('settle_s', 'road'),
    'handling': ('windows',),
}
ROAD_KEYS = ('road', 'wheelbase_m', 'start_rear_axle_at_m', 'contact_length_m', 'inputs',
             'unit')


class MappingError(ValueError):
    """A mapping file that cannot be used (the message names the key; one line each)."""


class _Problems:
    """Collects every problem of a mapping, so that one message lists them all."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def take(self, fn: Any, *args: Any, default: Any = None, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)``; on a MappingError its lines are kept, ``default`` returned."""
        try:
            return fn(*args, **kwargs)
        except MappingError as error:
            self.lines.extend(str(error).splitlines())
            return default


class _UniqueKeyLoader(yaml.SafeLoader):
    """A YAML loader that refuses a key given twice in one mapping (YAML keeps the last)."""


def _unique_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise MappingError(f'line {key_node.start_mark.line + 1}: key {key!r} given twice '
                               f'(first on line {seen[key] + 1}); YAML would keep only the last')
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                 _unique_mapping)


@dataclass(frozen=True)
class VariableRef:
    """One FMU variable the mapping names.

    Attributes
    ----------
    name : str
        The FMU's variable name.
    quantity : str
        Dimension the tool expects (``units.DIMENSIONS``).
    unit : str or None
        Unit the mapping states (used where the FMU declares none).
    where : str
        Key path in the mapping, for messages.
    scale, offset : float or None
        A design entry's linear map: the FMU parameter gets ``offset + scale * v``, v the
        design variable in its unit of config/design_space.yaml, in ``unit`` (None: the
        variable itself, converted to the FMU's unit).
    """

    name: str
    quantity: str
    unit: str | None
    where: str
    scale: float | None = None
    offset: float = 0.0


@dataclass(frozen=True)
class RoadInputs:
    """Road elevation under each wheel that the worker feeds the FMU (ride).

    ``road`` is a key of config/road.yaml (None: the ride scenario's road of
    config/scenarios.yaml); the rear axle starts at ``start_rear_axle_at_m`` and the
    front axle ``wheelbase_m`` ahead, both at the scenario's speed; each track is
    averaged over ``contact_length_m`` (0: point follower).
    """

    road: str | None
    wheelbase_m: float
    start_rear_axle_at_m: float
    contact_length_m: float
    inputs: dict[str, VariableRef]

    def variables(self) -> dict[str, tuple[VariableRef, tuple[str, ...]]]:
        """Each FMU input with the corners it takes: several corners get their mean."""
        out: dict[str, tuple[VariableRef, tuple[str, ...]]] = {}
        for corner, ref in self.inputs.items():
            first, corners = out.get(ref.name, (ref, ()))
            out[ref.name] = (first, (*corners, corner))
        return out


@dataclass(frozen=True)
class ScenarioMapping:
    """How one scenario runs on the FMU."""

    name: str
    start_time_s: float
    stop_time_s: float
    step_size_s: float
    speed_kmh: float
    speed_parameter: VariableRef | None
    parameters: dict[str, float | int | bool]
    design: dict[str, VariableRef]
    outputs: dict[str, VariableRef]
    settle_s: float = 0.0
    road: RoadInputs | None = None
    windows: dict[str, tuple[float, float]] | None = None

    @property
    def n_steps(self) -> int:
        """Communication steps from start to stop time."""
        return int(round((self.stop_time_s - self.start_time_s) / self.step_size_s))


@dataclass(frozen=True)
class FmuMapping:
    """A checked mapping file."""

    scenarios: dict[str, ScenarioMapping]
    path: Path | None = None
    text: str = field(default='', repr=False)
    #: The vehicle's total mass, kg (optional): the start-up plausibility check
    #: compares the static tyre loads with it.
    vehicle_mass_kg: float | None = None
    #: The design space whose variables the design section maps (default
    #: config/design_space.yaml).
    space: DesignSpace | None = field(default=None, repr=False)


def _keys(d: Any, where: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    if not isinstance(d, dict):
        raise MappingError(f'{where}: expected a mapping of keys, got {type(d).__name__}')
    unknown = sorted(set(map(str, d)) - set(allowed))
    if unknown:
        raise MappingError(f'{where}: unknown key(s) {unknown}; valid keys: {list(allowed)}')
    missing = [k for k in required if k not in d]
    if missing:
        raise MappingError(f'{where}: missing key(s) {missing}')
    return d


def _number(d: dict, key: str, where: str, default: float | None = None,
            positive: bool = False, minimum: float | None = None) -> float:
    """``d[key]`` as a finite float (``default`` when absent; None: required)."""
    if key not in d:
        if default is None:
            raise MappingError(f'{where}.{key}: missing')
        return default
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MappingError(f'{where}.{key}: expected a finite number, got {value!r}')
    if positive and value <= 0:
        raise MappingError(f'{where}.{key}: must be > 0, got {value!r}')
    if minimum is not None and value < minimum:
        raise MappingError(f'{where}.{key}: must be >= {minimum}, got {value!r}')
    return float(value)


def _ref(value: Any, quantity: str, where: str) -> VariableRef:
    """A variable entry: ``name`` or ``{name: ..., unit: ...}``."""
    if isinstance(value, str):
        name, unit = value, None
    else:
        d = _keys(value, where, ('name', 'unit'), ('name',))
        name, unit = d['name'], d.get('unit')
    if not isinstance(name, str) or not name:
        raise MappingError(f'{where}.name: expected an FMU variable name, got {name!r}')
    if unit is not None:
        unit = str(unit)
        if unit not in UNITS or UNITS[unit][0] != quantity:
            raise MappingError(f'{where}.unit: {unit!r} is not a unit of {quantity} this tool '
                               f'knows ({known_units(quantity)})')
    return VariableRef(name, quantity, unit, where)


def _corners(value: Any, quantity: str, where: str,
             per_axle: bool = False) -> dict[str, VariableRef]:
    """Per-wheel entry: ``{fl: name, fr: name, rl: name, rr: name, unit: ...}``.

    With ``per_axle`` (road inputs) ``{front: name, rear: name}`` stands for both
    wheels of each axle.  Every problem of the entry is listed together.
    """
    axles = ('front', 'rear') if per_axle else ()
    d = _keys(value, where, (*CORNERS, *axles, 'unit'))
    given = dict(d)
    for axle, pair in zip(axles, (('fl', 'fr'), ('rl', 'rr'))):
        if axle in given:
            both = [c for c in pair if c in given]
            if both:
                raise MappingError(f'{where}: {axle} and {"/".join(both)} both given; '
                                   f'{axle} stands for {" and ".join(pair)}')
            given.update({c: given[axle] for c in pair})
    missing = [c for c in CORNERS if c not in given]
    if missing:
        raise MappingError(f'{where}: missing key(s) {missing}' + (
            ' (or front/rear, one input per axle)' if per_axle else ''))
    unit = d.get('unit')
    if unit is not None and (str(unit) not in UNITS or UNITS[str(unit)][0] != quantity):
        raise MappingError(f'{where}.unit: {unit!r} is not a unit of {quantity} this tool '
                           f'knows ({known_units(quantity)})')
    problems = _Problems()
    refs = {c: problems.take(_ref, given[c] if unit is None or not isinstance(given[c], str)
                             else {'name': given[c], 'unit': unit}, quantity, f'{where}.{c}')
            for c in CORNERS}
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    return refs


def design_quantities(space: DesignSpace) -> dict[str, str]:
    """The design section's required keys (``dpsf_front``, ``gas_volume_front``...).

    With their quantities: the paper's variables, which every design size sets.
    """
    return {var.key(axle): var.quantity for axle in ('front', 'rear')
            for var in (space.damper, space.spring)}


def optional_design_quantities(space: DesignSpace) -> dict[str, str]:
    """The design section's optional keys: the design space's ``variables`` by name.

    With their quantities (``anti_roll_bar_rear``: torsional_stiffness...).  A design of
    a preset needs each of its variables mapped.
    """
    from suspension_tuning.vehicle.design import TARGETS
    return {v.name: TARGETS[v.target][0] for v in space.catalogue}


def _linear_map(d: dict, where: str) -> VariableRef:
    """A design entry ``{name, scale, offset, unit}``: the FMU parameter is linear in it."""
    d = _keys(d, where, LINEAR_MAP_KEYS, ('name', 'scale', 'unit'))
    problems = _Problems()
    name = d['name']
    if not isinstance(name, str) or not name:
        problems.lines.append(f'{where}.name: expected an FMU variable name, got {name!r}')
    scale = problems.take(_number, d, 'scale', where)
    if scale == 0.0:
        problems.lines.append(f'{where}.scale: must not be 0 (the parameter would not '
                              'follow the design)')
    offset = problems.take(_number, d, 'offset', where, 0.0)
    unit = d['unit']
    if not isinstance(unit, str):
        problems.lines.append(f'{where}.unit: expected the FMU parameter\'s unit (e.g. '
                              f"'N.s/m', 'bar', '-'), got {unit!r}")
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    quantity = UNITS[unit][0] if unit in UNITS else ''
    return VariableRef(name, quantity, unit, where, scale, offset)


def _design(value: Any, where: str, space: DesignSpace) -> dict[str, VariableRef]:
    required = design_quantities(space)
    quantities = {**required, **{k: q for k, q in optional_design_quantities(space).items()
                                 if k not in required}}
    keys = tuple(quantities)
    d = _keys(value, where, keys, tuple(required))
    problems = _Problems()
    refs = {}
    for k in (k for k in keys if k in d):
        if isinstance(d[k], dict) and ('scale' in d[k] or 'offset' in d[k]):
            refs[k] = problems.take(_linear_map, d[k], f'{where}.{k}')
        else:
            refs[k] = problems.take(_ref, d[k], quantities[k], f'{where}.{k}')
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    return refs


def _outputs(value: Any, name: str, where: str) -> dict[str, VariableRef]:
    """The scenario's output channels; every problem listed, duplicates refused."""
    problems = _Problems()
    d = _keys(value, where, tuple(OUTPUTS))
    out: dict[str, VariableRef] = {}
    for key, entry in d.items():
        quantity, per_wheel, _ = OUTPUTS[key]
        if per_wheel:
            for c, ref in problems.take(_corners, entry, quantity, f'{where}.{key}',
                                        default={}).items():
                out[f'{key}_{c}'] = ref
        else:
            ref = problems.take(_ref, entry, quantity, f'{where}.{key}')
            if ref is not None:
                out[key] = ref
    missing = [k for k, (_, _, needed) in OUTPUTS.items() if name in needed
               and k not in d]
    if missing:
        problems.lines.append(f'{where}: the {name} scenario needs output(s) {missing}')
    by_name: dict[str, list[str]] = {}
    for ref in out.values():
        by_name.setdefault(ref.name, []).append(ref.where)
    for variable, places in by_name.items():
        if len(places) > 1:
            problems.lines.append(
                f'{where}: FMU variable {variable!r} is mapped to {len(places)} outputs '
                f'({", ".join(places)}); each output needs its own variable (a model with '
                'one seat or one force per axle must still output one per seat and wheel)')
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    return out


def _parameters(value: Any, where: str) -> dict[str, float | int | bool]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise MappingError(f'{where}: expected a mapping of FMU parameter names to values')
    for key, v in value.items():
        if not isinstance(v, (bool, int, float)) or (
                isinstance(v, float) and not math.isfinite(v)):
            raise MappingError(f'{where}.{key}: expected a number or true/false, got {v!r}')
    return {str(k): v for k, v in value.items()}


def _road(value: Any, where: str) -> RoadInputs:
    d = _keys(value, where, ROAD_KEYS, ('wheelbase_m', 'inputs'))
    road = d.get('road')
    if road is not None and not isinstance(road, str):
        raise MappingError(f'{where}.road: expected a key of config/road.yaml, got {road!r}')
    inputs = dict(d['inputs']) if isinstance(d['inputs'], dict) else d['inputs']
    if isinstance(inputs, dict) and 'unit' in d:
        inputs['unit'] = d['unit']
    problems = _Problems()
    numbers = (problems.take(_number, d, 'wheelbase_m', where, positive=True),
               problems.take(_number, d, 'start_rear_axle_at_m', where, 0.5, minimum=0.0),
               problems.take(_number, d, 'contact_length_m', where, 0.0, minimum=0.0))
    refs = problems.take(_corners, inputs, 'length', f'{where}.inputs', per_axle=True)
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    return RoadInputs(road=road, wheelbase_m=numbers[0], start_rear_axle_at_m=numbers[1],
                      contact_length_m=numbers[2], inputs=refs)


def _window(value: Any, where: str) -> tuple[float, float]:
    if (not isinstance(value, (list, tuple)) or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            or not value[1] > value[0]):
        raise MappingError(f'{where}: expected [start_s, end_s] with end > start, got {value!r}')
    return float(value[0]), float(value[1])


def _scenario(name: str, d: Any, design: Any, where: str,
              space: DesignSpace) -> ScenarioMapping | None:
    """One scenario's mapping; its problems go to ``problems`` (None when there are any)."""
    problems = _Problems()
    d = _keys(d, where, (*SCENARIO_KEYS['common'], *SCENARIO_KEYS[name]),
              ('stop_time_s', 'step_size_s', 'speed_kmh', 'outputs'))
    start = problems.take(_number, d, 'start_time_s', where, 0.0)
    stop = problems.take(_number, d, 'stop_time_s', where)
    step = problems.take(_number, d, 'step_size_s', where, positive=True)
    speed = problems.take(_number, d, 'speed_kmh', where, positive=True)
    if None not in (start, stop, step):
        if stop <= start:
            problems.lines.append(f'{where}.stop_time_s: must be after start_time_s '
                                  f'({start} s)')
        else:
            n = (stop - start) / step
            if abs(n - round(n)) > 1e-6 * max(1.0, n) or round(n) < 3:
                problems.lines.append(f'{where}.step_size_s: {step} s must divide stop - start '
                                      f'({stop - start} s) into at least 3 steps')
    if 'design' in d:
        design = d['design']
        design_where = f'{where}.design'
    else:
        design_where = 'design'
    design_refs = None
    if design is None:
        problems.lines.append(f'{where}: no design section (top-level or in the scenario)')
    else:
        design_refs = problems.take(_design, design, design_where, space)
    windows = None
    if name == 'handling' and d.get('windows') is not None:
        w = problems.take(_keys, d['windows'], f'{where}.windows',
                          ('first_lane_change_s', 'manoeuvre_s'),
                          ('first_lane_change_s', 'manoeuvre_s'))
        if w is not None:
            windows = {k: problems.take(_window, v, f'{where}.windows.{k}')
                       for k, v in w.items()}
    outputs = problems.take(_outputs, d['outputs'], name, f'{where}.outputs', default={})
    if name == 'handling' and windows is None and 'x' not in outputs and 'outputs' in d:
        problems.lines.append(
            f'{where}: the handling metrics need their time windows: give windows '
            '(first_lane_change_s, manoeuvre_s) or an x output (position along the track, '
            'config/scenarios.yaml)')
    settle = 0.0
    if name == 'ride':
        settle = problems.take(_number, d, 'settle_s', where, 0.0, minimum=0.0, default=0.0)
        if None not in (start, stop, step) and settle >= stop - start - 2 * step:
            problems.lines.append(f'{where}.settle_s: {settle} s leaves nothing of the run')
    speed_param = d.get('speed_parameter')
    speed_ref = None if speed_param is None else problems.take(
        _ref, speed_param, 'velocity', f'{where}.speed_parameter')
    parameters = problems.take(_parameters, d.get('parameters'), f'{where}.parameters',
                               default={})
    twice = sorted(set(parameters) & {ref.name for ref in (design_refs or {}).values()})
    if twice:
        problems.lines.append(f'{where}.parameters: {twice} also receive design variables')
    road = (problems.take(_road, d['road'], f'{where}.road')
            if d.get('road') is not None else None)
    if problems.lines:
        raise MappingError('\n'.join(problems.lines))
    return ScenarioMapping(
        name=name, start_time_s=start, stop_time_s=stop, step_size_s=step, speed_kmh=speed,
        speed_parameter=speed_ref, parameters=parameters, design=design_refs,
        outputs=outputs, settle_s=settle, road=road, windows=windows)


def parse_mapping(text: str, path: Path | None = None,
                  space: DesignSpace | None = None) -> FmuMapping:
    """Check a mapping given as YAML text (see docs/fmu.md).

    ``space``: the design space whose variables the design section maps (default
    config/design_space.yaml): its keys are ``<name>_front`` and ``<name>_rear`` of the
    damper and the spring variable.

    Raises
    ------
    MappingError
        Every problem found, one line each, naming the key.
    """
    source = str(path) if path is not None else 'mapping'
    space = space if space is not None else load_design_space()
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader
    except MappingError as error:
        raise MappingError(f'{source}: {error}') from None
    except yaml.YAMLError as error:
        raise MappingError(f'{source}: not valid YAML: {error}') from None
    d = _keys(data, source, ('design', 'scenarios', 'vehicle_mass_kg'), ('scenarios',))
    problems = _Problems()
    mass = (problems.take(_number, d, 'vehicle_mass_kg', 'mapping', positive=True)
            if 'vehicle_mass_kg' in d else None)
    scen = _keys(d['scenarios'], 'scenarios', ('ride', 'handling'))
    if not scen:
        raise MappingError('scenarios: name at least one of ride, handling')
    scenarios = {name: problems.take(_scenario, name, body, d.get('design'),
                                     f'scenarios.{name}', space) for name, body in scen.items()}
    if problems.lines:
        raise MappingError(f'{source}: {len(problems.lines)} problem(s):\n  '
                           + '\n  '.join(problems.lines))
    return FmuMapping(scenarios, path, text, mass, space)


def load_mapping(path: str | Path, space: DesignSpace | None = None) -> FmuMapping:
    """Read and check a mapping file (``space``: as :func:`parse_mapping`).

    Raises
    ------
    MappingError
        Unreadable file, bad YAML, unknown or missing keys, bad numbers or units.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as error:
        raise MappingError(f'fmu_mapping {p}: cannot read it ({error.strerror})') from None
    return parse_mapping(text, p, space)
