"""4S4 valve-state controller and solenoid valve model (no rclpy).

The 4S4 strut has two gas accumulators and two damper packs; solenoid valves select
the soft or the stiff spring and the low or the high damping (paper section 3).  The
controller here decides the state of the front and the rear axle from the vehicle
state (lateral acceleration, roll rate, steering rate) with hysteresis and a minimum
dwell time; the valve model then makes a commanded change take effect 50-100 ms later,
longer at lower strut gas pressure ("Valve switching times vary between 50 and 100
milliseconds depending on system pressure", paper section 3).

Everything is stepped on integer control periods so that a closed-loop run through
ROS topics and the same run in-process give identical results.

Notes
-----
Thresholds and delays are read from ``config/valve_controller.yaml``, where each
number carries its source.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

from suspension_tuning.paths import config_dir, read_yaml

SPRING_SOFT = 0
SPRING_STIFF = 1
DAMPING_LOW = 0
DAMPING_HIGH = 1

#: (front_spring, front_damping, rear_spring, rear_damping) of the two modes.
RIDE_STATE = (SPRING_SOFT, DAMPING_LOW, SPRING_SOFT, DAMPING_LOW)
HANDLING_STATE = (SPRING_STIFF, DAMPING_HIGH, SPRING_STIFF, DAMPING_HIGH)

DEFAULT_CONFIG = config_dir() / 'valve_controller.yaml'


@dataclass(frozen=True)
class ValveControllerParams:
    """Thresholds of the mode decision and the valve delay model (SI units)."""

    lateral_acceleration_on_mps2: float = 2.0
    lateral_acceleration_off_mps2: float = 1.0
    roll_rate_on_deg_s: float = 12.0
    roll_rate_off_deg_s: float = 6.0
    steering_rate_on_deg_s: float = 10.0
    steering_rate_off_deg_s: float = 4.0
    min_dwell_s: float = 1.0
    delay_min_s: float = 0.050
    delay_max_s: float = 0.100
    pressure_low_pa: float = 1.5e6
    pressure_high_pa: float = 4.0e6
    control_period_s: float = 0.010

    def __post_init__(self) -> None:
        """Check the ordering of thresholds and the delay range."""
        for name in ('lateral_acceleration', 'roll_rate', 'steering_rate'):
            on = getattr(self, f'{name}_on_' + _unit(name))
            off = getattr(self, f'{name}_off_' + _unit(name))
            if not 0.0 <= off <= on:
                raise ValueError(f'{name}: need 0 <= off ({off}) <= on ({on})')
        if not 0.0 < self.delay_min_s <= self.delay_max_s:
            raise ValueError('need 0 < delay_min_s <= delay_max_s')
        if not self.pressure_low_pa < self.pressure_high_pa:
            raise ValueError('need pressure_low_pa < pressure_high_pa')
        if self.control_period_s <= 0.0:
            raise ValueError('control_period_s must be positive')

    @classmethod
    def from_dict(cls, values: dict) -> ValveControllerParams:
        """Build from a mapping, ignoring keys that are not parameters."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: float(v) for k, v in values.items() if k in names})

    @classmethod
    def from_yaml(cls, path: str | Path = DEFAULT_CONFIG) -> ValveControllerParams:
        """Read the ``ros__parameters`` of the valve_controller node's YAML file."""
        data = read_yaml(path)
        for node in data.values():
            if isinstance(node, dict) and 'ros__parameters' in node:
                return cls.from_dict(node['ros__parameters'])
        raise ValueError(f'{path}: no ros__parameters section')


def _unit(name: str) -> str:
    return 'mps2' if name == 'lateral_acceleration' else 'deg_s'


def valve_delay_s(pressure_pa: float, params: ValveControllerParams) -> float:
    """Switching delay of a solenoid valve at a strut gas pressure.

    Linear between ``delay_max_s`` at ``pressure_low_pa`` (and below) and
    ``delay_min_s`` at ``pressure_high_pa`` (and above): 50-100 ms, longer at lower
    pressure (paper section 3).

    Parameters
    ----------
    pressure_pa : float
        Mean gas pressure of the axle's struts, Pa.
    params : ValveControllerParams
        Delay range and pressure range.

    Returns
    -------
    float
        Delay, s.
    """
    span = params.pressure_high_pa - params.pressure_low_pa
    share = min(max((pressure_pa - params.pressure_low_pa) / span, 0.0), 1.0)
    return params.delay_max_s - share * (params.delay_max_s - params.delay_min_s)


@dataclass
class ValveEvent:
    """A commanded or an actual change of one axle's valves."""

    step: int
    axle: str  # 'front' or 'rear'
    kind: str  # 'command' or 'actual'
    state: tuple[int, int]  # (spring, damping)


class ValveController:
    """Mode decision with hysteresis and dwell, plus the delayed valve actuators.

    Call :meth:`update` once per control period with the vehicle state; it returns the
    commanded and the actual state ``(front_spring, front_damping, rear_spring,
    rear_damping)``.  The actual state is what the strut model must use.

    Parameters
    ----------
    params : ValveControllerParams
        Thresholds, dwell time, delay model and control period.
    initial : tuple of int
        Initial (commanded = actual) state, default the ride state.
    """

    def __init__(self, params: ValveControllerParams | None = None,
                 initial: tuple[int, int, int, int] = RIDE_STATE) -> None:
        self.params = params or ValveControllerParams()
        self.commanded = tuple(initial)
        self.actual = tuple(initial)
        self.handling = tuple(initial) == HANDLING_STATE
        self._last_switch_step = -10**9
        # Per axle: (landing step, target (spring, damping)) of a pending change.
        self._pending: dict[str, tuple[int, tuple[int, int]] | None] = {
            'front': None, 'rear': None}
        self.events: list[ValveEvent] = []

    def _wants_handling(self, lateral_acceleration_mps2: float, roll_rate_radps: float,
                        steering_rate_radps: float, level: str) -> bool:
        p = self.params
        ay = abs(lateral_acceleration_mps2)
        roll = math.degrees(abs(roll_rate_radps))
        steer = math.degrees(abs(steering_rate_radps))
        return (ay > getattr(p, f'lateral_acceleration_{level}_mps2')
                or roll > getattr(p, f'roll_rate_{level}_deg_s')
                or steer > getattr(p, f'steering_rate_{level}_deg_s'))

    def update(self, step: int, lateral_acceleration_mps2: float, roll_rate_radps: float,
               steering_rate_radps: float,
               strut_pressure_pa: tuple[float, float, float, float]
               ) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Advance one control period.

        Parameters
        ----------
        step : int
            Control-step index (time = step x control_period_s).
        lateral_acceleration_mps2 : float
            Body lateral acceleration, m/s^2.
        roll_rate_radps : float
            Body roll rate, rad/s.
        steering_rate_radps : float
            Front road-wheel steer rate, rad/s.
        strut_pressure_pa : tuple of 4 float
            Gas pressure FL, FR, RL, RR, Pa.

        Returns
        -------
        commanded, actual : tuple of 4 int
            Valve states (front_spring, front_damping, rear_spring, rear_damping).
        """
        values = (lateral_acceleration_mps2, roll_rate_radps, steering_rate_radps,
                  *strut_pressure_pa)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'vehicle state must be finite, got {values}')
        p = self.params
        dwell_steps = round(p.min_dwell_s / p.control_period_s)
        dwelt = step - self._last_switch_step >= dwell_steps
        if not self.handling and self._wants_handling(
                lateral_acceleration_mps2, roll_rate_radps, steering_rate_radps, 'on'):
            self._command(step, HANDLING_STATE, strut_pressure_pa)
        elif self.handling and dwelt and not self._wants_handling(
                lateral_acceleration_mps2, roll_rate_radps, steering_rate_radps, 'off'):
            self._command(step, RIDE_STATE, strut_pressure_pa)
        self._land(step)
        return self.commanded, self.actual

    def update_from_state(self, step: int, state: dict) -> tuple[int, ...]:
        """Advance one period from a VehicleState-like mapping; return the actual state."""
        return self.update(step, state['lateral_acceleration_mps2'], state['roll_rate_radps'],
                           state['steering_rate_radps'], tuple(state['strut_pressure_pa']))[1]

    def _command(self, step: int, state: tuple[int, int, int, int],
                 pressure_pa: tuple[float, float, float, float]) -> None:
        self.handling = state == HANDLING_STATE
        self.commanded = state
        self._last_switch_step = step
        axles = {'front': (state[0:2], 0.5 * (pressure_pa[0] + pressure_pa[1])),
                 'rear': (state[2:4], 0.5 * (pressure_pa[2] + pressure_pa[3]))}
        for axle, (target, pressure) in axles.items():
            self.events.append(ValveEvent(step, axle, 'command', tuple(target)))
            delay_steps = math.ceil(valve_delay_s(pressure, self.params)
                                    / self.params.control_period_s - 1e-9)
            self._pending[axle] = (step + delay_steps, tuple(target))

    def _land(self, step: int) -> None:
        actual = list(self.actual)
        for index, axle in enumerate(('front', 'rear')):
            pending = self._pending[axle]
            if pending is not None and step >= pending[0]:
                self._pending[axle] = None
                if tuple(actual[2 * index:2 * index + 2]) != pending[1]:
                    actual[2 * index:2 * index + 2] = pending[1]
                    self.events.append(ValveEvent(step, axle, 'actual', pending[1]))
        self.actual = tuple(actual)
