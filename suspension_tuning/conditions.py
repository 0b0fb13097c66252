"""Operating conditions: the speeds, payloads and roads one tuning covers (no rclpy).

A *condition set* (config/conditions.yaml, or a file ``tune --conditions FILE`` names)
lists operating points.  Each condition has a name, a speed, a payload (its mass and
the longitudinal position of its centre of gravity), a road, a manoeuvre speed and a
weight: the ride runs at the speed on the road, the handling lane change at the
manoeuvre speed (default config/scenarios.yaml's, 65 km/h), both with the payload.  The
optimisation (:func:`suspension_tuning.tuning.optimise_conditions`) runs the full model
of the goal's scenario in every condition at each design and minimises the weighted
mean of the per-condition objectives or the worst of them.

The payload is a point mass on the body (sprung mass) at the height
config/vehicle.yaml ``payload.cg_height_m``.  :func:`with_payload` moves the sprung
mass, its centre of gravity and its inertias; the static axle loads, the struts' static
gas pressure (``(p - p_atm) A_p = static load``, physics-reference 3.2) and the tyres'
static loads follow from them, since the model derives each from the sprung mass and
the centre of gravity (:class:`~suspension_tuning.vehicle.params.VehicleParams`).

:func:`load_conditions` checks a file when a program starts: an unknown road, a payload
outside config/vehicle.yaml's limits, an empty set, weights that do not sum to a
positive number, or a speed the vehicle does not reach (its top speed, or a road too
short for the run at that speed) is a :class:`ConditionError` naming the file, the
condition and the key.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from suspension_tuning.paths import config_dir, read_yaml
from suspension_tuning.vehicle.params import (
    VehicleParams,
    load_scenarios_config,
    load_vehicle_params,
)

KMH = 1.0 / 3.6
#: Forms of the objective over a condition set: the weighted mean, or the worst case
#: (min-max, posed in epigraph form).
CONDITION_FORMS = ('worst', 'mean')
#: The default condition set.
DEFAULT_FILE = 'conditions.yaml'
#: Keys of one condition in a file.
CONDITION_KEYS = ('name', 'speed_kmh', 'payload', 'road', 'manoeuvre_speed_kmh', 'weight')
#: Scenarios a condition set is for.
CONDITION_SCENARIOS = ('ride', 'handling')
PAYLOAD_KEYS = ('mass_kg', 'behind_front_axle_m')


class ConditionError(ValueError):
    """A condition set that cannot be used; the message names file, condition and key."""


@dataclass(frozen=True)
class Condition:
    """One operating point (ride: speed, payload, road; handling: manoeuvre speed, payload).

    Attributes
    ----------
    name : str
        Unique name (a label in results and bags).
    speed_kmh : float
        Constant forward speed [km/h].
    payload_kg : float
        Mass loaded into the vehicle beyond config/vehicle.yaml ``mass.total_kg`` [kg].
    payload_behind_front_axle_m : float
        Longitudinal position of the payload's centre of gravity behind the front axle [m].
    road : str
        The ride road (a road of config/road.yaml, a road file or an entry as YAML);
        '' = the one config/scenarios.yaml names.
    weight : float
        Weight in the weighted mean (>= 0).
    manoeuvre_speed_kmh : float
        Speed of the handling scenario's double lane change [km/h]; 0 = the one
        config/scenarios.yaml names (``handling.speed_kmh``).
    """

    name: str
    speed_kmh: float
    payload_kg: float = 0.0
    payload_behind_front_axle_m: float = 0.0
    road: str = ''
    weight: float = 1.0
    manoeuvre_speed_kmh: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        """The condition as a file writes it (run configurations, JSON)."""
        payload: dict[str, float] = {'mass_kg': self.payload_kg}
        if self.payload_kg > 0.0:
            payload['behind_front_axle_m'] = self.payload_behind_front_axle_m
        out = {'name': self.name, 'speed_kmh': self.speed_kmh, 'payload': payload,
               'road': self.road, 'weight': self.weight}
        if self.manoeuvre_speed_kmh > 0.0:  # only when set: older texts stay the same
            out['manoeuvre_speed_kmh'] = self.manoeuvre_speed_kmh
        return out

    def as_text(self) -> str:
        """The condition as one JSON line (how a service request carries it)."""
        return json.dumps(self.as_dict(), sort_keys=True)

    @classmethod
    def from_text(cls, text: str) -> Condition:
        """A condition from :meth:`as_text` (ValueError naming what is wrong)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise ConditionError(f'condition {text!r} is not JSON: {error}') from None
        return parse_condition(data, 'request: ', payload_limits(), road_length=False)


@dataclass(frozen=True)
class ConditionSet:
    """Conditions of one optimisation and where they came from."""

    conditions: tuple[Condition, ...]
    source: str = ''

    @property
    def names(self) -> list[str]:
        """Condition names in order."""
        return [c.name for c in self.conditions]

    @property
    def weights(self) -> list[float]:
        """Weights normalised to sum 1."""
        total = sum(c.weight for c in self.conditions)
        return [c.weight / total for c in self.conditions]

    def __len__(self) -> int:
        return len(self.conditions)

    def as_dict(self) -> dict[str, Any]:
        """What a run configuration records: the source and every condition."""
        return {'source': self.source, 'conditions': [c.as_dict() for c in self.conditions]}

    def as_text(self) -> str:
        """The set as one JSON text (the Optimise goal's ``conditions``)."""
        return json.dumps(self.as_dict(), sort_keys=True)

    @classmethod
    def from_text(cls, text: str) -> ConditionSet:
        """A set from :meth:`as_text`, or a file path (ValueError naming the problem)."""
        text = str(text).strip()
        if not text.startswith('{'):
            return load_conditions(text)
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise ConditionError(f'conditions: not JSON ({error})') from None
        source = str(data.get('source', '')) if isinstance(data, dict) else ''
        return parse_conditions(data, source or 'goal conditions')


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConditionError(f'{where}: expected a number, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ConditionError(f'{where}: expected a finite number, got {value}')
    return value


def payload_limits(params: VehicleParams | None = None,
                   path: str | Path | None = None) -> dict[str, float]:
    """config/vehicle.yaml ``payload``: largest mass [kg], position range [m], cg height [m]."""
    params = params if params is not None else load_vehicle_params()
    path = Path(path) if path is not None else config_dir() / 'vehicle.yaml'
    d = read_yaml(path)
    section = d['payload']
    gvm = float(section['gross_vehicle_mass_kg'])
    return {'max_mass_kg': gvm - params.mass_total_kg,
            'gross_vehicle_mass_kg': gvm,
            'min_behind_front_axle_m': float(section['behind_front_axle_min_m']),
            'max_behind_front_axle_m': float(section['behind_front_axle_max_m']),
            'cg_height_m': float(section['cg_height_m']),
            'top_speed_kmh': float(d['longitudinal']['top_speed_kmh'])}


def with_payload(params: VehicleParams, mass_kg: float, behind_front_axle_m: float,
                 cg_height_m: float | None = None) -> VehicleParams:
    """Vehicle parameters with a payload on the body (a point mass).

    Parameters
    ----------
    params : VehicleParams
        The unladen vehicle.
    mass_kg : float
        Payload mass [kg] (0: ``params`` unchanged).
    behind_front_axle_m : float
        Its centre of gravity behind the front axle [m].
    cg_height_m : float, optional
        Its height above the ground [m] (default config/vehicle.yaml
        ``payload.cg_height_m``).

    Returns
    -------
    VehicleParams
        Sprung and total mass raised by ``mass_kg``; the sprung centre of gravity moved
        to the mass-weighted mean of the two (a, b, cg height); the sprung pitch and roll
        inertias and the yaw inertia about the new centre of gravity by the parallel-axis
        theorem (the payload as a point mass); the seats at their places on the body.
        The static strut and tyre loads (``VehicleParams.static_*``), hence the gas
        springs' static pressure, follow.
    """
    if mass_kg == 0.0:
        return params
    if cg_height_m is None:
        cg_height_m = payload_limits(params)['cg_height_m']
    m_s, m_p = params.mass_sprung_kg, float(mass_kg)
    m_new = m_s + m_p
    a_old, h_old = params.a_m, params.cg_height_m
    a_new = (m_s * a_old + m_p * behind_front_axle_m) / m_new
    h_new = (m_s * h_old + m_p * cg_height_m) / m_new
    dx_s, dz_s = a_new - a_old, h_new - h_old
    dx_p, dz_p = behind_front_axle_m - a_new, cg_height_m - h_new
    i_pitch = (params.i_pitch_sprung_kgm2 + m_s * (dx_s ** 2 + dz_s ** 2)
               + m_p * (dx_p ** 2 + dz_p ** 2))
    i_roll = params.i_roll_sprung_kgm2 + m_s * dz_s ** 2 + m_p * dz_p ** 2
    i_yaw = params.i_yaw_total_kgm2 + m_s * dx_s ** 2 + m_p * dx_p ** 2
    # seats stay where they are on the body: their distance behind the front axle
    driver_behind = a_old - params.driver_x_m
    passenger_behind = a_old - params.passenger_x_m
    return replace(
        params, mass_total_kg=params.mass_total_kg + m_p, mass_sprung_kg=m_new,
        a_m=a_new, b_m=params.wheelbase_m - a_new, cg_height_m=h_new,
        i_pitch_sprung_kgm2=i_pitch, i_roll_sprung_kgm2=i_roll, i_yaw_total_kgm2=i_yaw,
        driver_x_m=a_new - driver_behind, passenger_x_m=a_new - passenger_behind)


def condition_params(condition: Condition | None,
                     params: VehicleParams | None = None) -> VehicleParams:
    """The vehicle of a condition (its payload on ``params``, default config/*.yaml)."""
    params = params if params is not None else load_vehicle_params()
    if condition is None:
        return params
    return with_payload(params, condition.payload_kg, condition.payload_behind_front_axle_m)


def condition_scenarios(condition: Condition | None,
                        config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """config/scenarios.yaml with the condition's ride speed, road and run length.

    The ride run covers the configured averaging distance at the condition's speed:
    the settling time stays (the W_b filter's, in seconds), the averaging time is the
    configured one times configured speed / condition speed, so each condition averages
    over the same stretch of road.  The handling scenario's lane change runs at the
    condition's manoeuvre speed, when it names one (the run is laid out in metres: its
    duration follows).
    """
    config = copy.deepcopy(dict(config) if config is not None else load_scenarios_config())
    if condition is None:
        return config
    ride = config['ride']
    speed0, settle, duration = (float(ride['speed_kmh']), float(ride['settle_s']),
                                float(ride['duration_s']))
    ride['speed_kmh'] = float(condition.speed_kmh)
    ride['duration_s'] = settle + (duration - settle) * speed0 / float(condition.speed_kmh)
    if condition.road:
        ride['road'] = condition.road
    if condition.manoeuvre_speed_kmh > 0.0:
        config['handling']['speed_kmh'] = float(condition.manoeuvre_speed_kmh)
    return config


def check_condition(condition: Condition, where: str = '',
                    limits: Mapping[str, float] | None = None,
                    road_length: bool = True,
                    lengths: dict[str, float] | None = None) -> None:
    """Check one condition against the vehicle's limits and its road.

    Raises
    ------
    ConditionError
        ``<where>condition '<name>': <key>: <what is wrong>``.
    """
    limits = limits if limits is not None else payload_limits()
    head = f"{where}condition '{condition.name}'"
    if not condition.name:
        raise ConditionError(f'{where}a condition without a name')
    if not condition.speed_kmh > 0.0:
        raise ConditionError(f'{head}: speed_kmh: must be positive, got {condition.speed_kmh}')
    if condition.speed_kmh > limits['top_speed_kmh']:
        raise ConditionError(
            f"{head}: speed_kmh: {condition.speed_kmh:g} km/h is above the vehicle's top "
            f"speed {limits['top_speed_kmh']:g} km/h (config/vehicle.yaml "
            'longitudinal.top_speed_kmh)')
    if not 0.0 <= condition.payload_kg <= limits['max_mass_kg'] + 1e-9:
        raise ConditionError(
            f"{head}: payload.mass_kg: {condition.payload_kg:g} kg is outside 0-"
            f"{limits['max_mass_kg']:g} kg (gross vehicle mass "
            f"{limits['gross_vehicle_mass_kg']:g} kg less the vehicle's mass; "
            'config/vehicle.yaml payload)')
    lo, hi = limits['min_behind_front_axle_m'], limits['max_behind_front_axle_m']
    if condition.payload_kg > 0.0 and not lo <= condition.payload_behind_front_axle_m <= hi:
        raise ConditionError(
            f"{head}: payload.behind_front_axle_m: {condition.payload_behind_front_axle_m:g} m "
            f'is outside the load space {lo:g}-{hi:g} m behind the front axle '
            '(config/vehicle.yaml payload)')
    manoeuvre = condition.manoeuvre_speed_kmh
    if not (math.isfinite(manoeuvre) and manoeuvre >= 0.0):
        raise ConditionError(f'{head}: manoeuvre_speed_kmh: must be positive, got {manoeuvre}')
    if manoeuvre > limits['top_speed_kmh']:
        raise ConditionError(
            f"{head}: manoeuvre_speed_kmh: {manoeuvre:g} km/h is above the vehicle's top "
            f"speed {limits['top_speed_kmh']:g} km/h (config/vehicle.yaml "
            'longitudinal.top_speed_kmh)')
    if not (math.isfinite(condition.weight) and condition.weight >= 0.0):
        raise ConditionError(f'{head}: weight: must be a number >= 0, got {condition.weight}')
    if condition.road:
        from suspension_tuning.vehicle.road import resolve_road
        try:
            resolve_road(condition.road)
        except (ValueError, KeyError, OSError) as error:
            text = str(error.args[0]) if isinstance(error, KeyError) else str(error)
            raise ConditionError(f'{head}: road: {text}') from None
    if road_length:
        _check_road_length(condition, head, {} if lengths is None else lengths)


def _check_road_length(condition: Condition, head: str, lengths: dict[str, float]) -> None:
    """The road must carry the run at the condition's speed (the model's own test)."""
    from suspension_tuning.vehicle.scenarios import _ride_road, ride_road_spec

    params = condition_params(condition)
    ride = condition_scenarios(condition)['ride']
    if condition.road not in lengths:
        try:
            lengths[condition.road] = _ride_road(ride_road_spec(ride),
                                                 params.tyre.contact_length_m)[1]
        except (ValueError, KeyError, OSError) as error:
            text = str(error.args[0]) if isinstance(error, KeyError) else str(error)
            raise ConditionError(f'{head}: road: {text}') from None
    road_len = lengths[condition.road]
    run = float(ride['speed_kmh']) * KMH * float(ride['duration_s'])
    need = float(ride['start_rear_axle_at_m']) + params.b_m + params.a_m + run
    if need > road_len:
        raise ConditionError(
            f"{head}: speed_kmh: the vehicle cannot hold {condition.speed_kmh:g} km/h over "
            f'the run on its road: the run needs {need:.0f} m, the road is {road_len:.0f} m '
            '(a longer road, or a lower speed)')


def parse_condition(item: Any, where: str, limits: Mapping[str, float], k: int = 0,
                    lengths: dict[str, float] | None = None,
                    road_length: bool = True) -> Condition:
    """One condition from its mapping (a file's list item), checked.

    ``lengths`` caches road lengths by road across a set (a road is synthesised once).
    """
    if not isinstance(item, Mapping):
        raise ConditionError(f'{where}conditions[{k}]: expected a mapping, got {item!r}')
    name = str(item.get('name', '') or '').strip()
    head = f"{where}condition '{name}'" if name else f'{where}conditions[{k}]'
    if not name:
        raise ConditionError(f'{head}: missing key name')
    unknown = set(item) - set(CONDITION_KEYS)
    if unknown:
        raise ConditionError(f'{head}: {sorted(unknown)[0]}: unknown key; valid: '
                             f'{", ".join(CONDITION_KEYS)}')
    if 'speed_kmh' not in item:
        raise ConditionError(f'{head}: missing key speed_kmh')
    speed = _number(item['speed_kmh'], f'{head}: speed_kmh')
    payload = item.get('payload') or {}
    if not isinstance(payload, Mapping) or set(payload) - set(PAYLOAD_KEYS):
        raise ConditionError(f'{head}: payload: expected a mapping of '
                             f'{", ".join(PAYLOAD_KEYS)}, got {payload!r}')
    mass = _number(payload.get('mass_kg', 0.0), f'{head}: payload.mass_kg')
    if mass > 0.0 and 'behind_front_axle_m' not in payload:
        raise ConditionError(f'{head}: missing key payload.behind_front_axle_m')
    position = _number(payload.get('behind_front_axle_m', 0.0),
                       f'{head}: payload.behind_front_axle_m')
    road = item.get('road', '')
    if road is None:
        road = ''
    if not isinstance(road, str):
        road = json.dumps(road)  # an entry of its own, as YAML (flow) mapping text
    weight = _number(item.get('weight', 1.0), f'{head}: weight')
    manoeuvre = 0.0
    if item.get('manoeuvre_speed_kmh') is not None:
        manoeuvre = _number(item['manoeuvre_speed_kmh'], f'{head}: manoeuvre_speed_kmh')
        if not manoeuvre > 0.0:
            raise ConditionError(f'{head}: manoeuvre_speed_kmh: must be positive, got '
                                 f'{manoeuvre:g}')
    condition = Condition(name, speed, mass, position, road, weight, manoeuvre)
    check_condition(condition, where, limits, road_length, lengths)
    return condition


def parse_conditions(data: Any, source: str) -> ConditionSet:
    """A condition set from a parsed file's mapping (``conditions:`` list).

    Raises
    ------
    ConditionError
        Naming ``source``, the condition and the key.
    """
    where = f'{source}: '
    if not isinstance(data, Mapping) or 'conditions' not in data:
        raise ConditionError(f'{where}missing key conditions (a list of operating points)')
    items = data['conditions']
    if not isinstance(items, Sequence) or isinstance(items, str) or not items:
        raise ConditionError(f'{where}conditions: the set is empty; list at least one '
                             'condition (name, speed_kmh, payload, road, weight)')
    limits = payload_limits()
    conditions: list[Condition] = []
    lengths: dict[str, float] = {}
    for k, item in enumerate(items):
        condition = parse_condition(item, where, limits, k, lengths)
        if condition.name in (c.name for c in conditions):
            raise ConditionError(f"{where}condition '{condition.name}': name: used by an "
                                 'earlier condition')
        conditions.append(condition)
    if not sum(c.weight for c in conditions) > 0.0:
        raise ConditionError(f'{where}conditions: the weights sum to '
                             f'{sum(c.weight for c in conditions):g}; they must sum to a '
                             'positive number')
    return ConditionSet(tuple(conditions), source)


def load_conditions(path: str | Path | None = None) -> ConditionSet:
    """Read and check a condition set (default config/conditions.yaml).

    Raises
    ------
    ConditionError
        A file that cannot be read or parsed, or a condition that cannot be used: one
        line naming the file, the condition and the key.
    """
    path = Path(path) if path is not None else config_dir() / DEFAULT_FILE
    try:
        source = str(path.resolve().relative_to(config_dir().resolve().parent))
    except ValueError:
        source = str(path)
    if not path.is_file():
        raise ConditionError(f'{source}: no such file')
    try:
        data = read_yaml(path)
    except OSError as error:
        raise ConditionError(f'{source}: cannot read it ({error.strerror or error})') from None
    except ValueError as error:
        text = str(error)
        raise ConditionError(text if text.startswith(str(path)) else f'{source}: {text}'
                             ) from None
    return parse_conditions(data, source)


def check_form(form: str) -> str:
    """The objective's form over the set: 'worst' (default for '') or 'mean'."""
    form = form or 'worst'
    if form not in CONDITION_FORMS:
        raise ValueError(f'unknown condition form {form!r}; valid: {", ".join(CONDITION_FORMS)}')
    return form
