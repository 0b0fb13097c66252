"""Entry point of the simplified models (section 6): inputs captured from a full run.

:class:`SimplifiedInputs` holds what a simplified model needs from the full model's run at
the current design (the paper feeds the handling model the full model's steering and slip
angles [P s.6.1]; the ride model's road is the scenario's seeded road, known in advance, so
ride needs nothing from the run).  The ROS gradient node can cache one per iterate.

:func:`run_simplified` evaluates f (eq. 9 or 10) and g (eq. 11, FL, FR, RL, RR) of a batch
of designs with the pitch-plane ride model or the handling model.  Models are cached per
process (building the ride road costs one road synthesis).

The 'mixed' scenario (rough road, then the double lane change, the 4S4 valves switched
by the controller) has no model of its own in the paper; its simplified model is the two
the paper has, each in the state the valve controller engages there
(:func:`run_mixed_simplified`): a ride model (by default the roll-and-pitch one,
:func:`ride_model_kind`) on the paving at the mixed scenario's speed and length in the
ride state, the handling model on the lane change in
the handling state, with f their mean as the full scenario's f (eqs. 9, 10) and g eq. 11
over both parts, weighted by their durations.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .design import (
    AXLES,
    AxleSettings,
    DesignSpace,
    load_design_space,
    to_physical,
    validate_design,
)
from .handling_model import HandlingInputs, HandlingModel
from .metrics import TYRE_HOP_MAX_FRACTION
from .pitch_plane import PitchPlaneModel, load_simplified_config
from .roll_pitch import RollPitchModel

SIMPLIFIED_SCENARIOS = ('ride', 'handling', 'mixed')
#: Scenarios whose simplified model needs inputs captured from the full model's run.
INPUT_SCENARIOS = ('handling', 'mixed')


@dataclass(frozen=True)
class SimplifiedInputs:
    """Inputs of a simplified model, captured from one full-model scenario run.

    Attributes
    ----------
    scenario : str
        'ride', 'handling' or 'mixed'.
    x : np.ndarray or None
        Normalised design of the full run they came from (n_vars,), for bookkeeping.
    handling : HandlingInputs or None
        Steering, slip angles, speed and metric windows (handling and mixed: the lane
        change).
    """

    scenario: str
    x: np.ndarray | None = None
    handling: HandlingInputs | None = None

    def __post_init__(self) -> None:
        """Check the scenario name and that handling inputs are present when needed."""
        if self.scenario not in SIMPLIFIED_SCENARIOS:
            raise ValueError(
                f'unknown scenario {self.scenario!r}; valid: {", ".join(SIMPLIFIED_SCENARIOS)}'
            )
        if self.scenario in INPUT_SCENARIOS and not isinstance(self.handling, HandlingInputs):
            raise ValueError(f'{self.scenario} SimplifiedInputs need HandlingInputs (steer, '
                             'slip angles)')

    @classmethod
    def from_scenario_result(cls, result, index: int = 0) -> SimplifiedInputs:
        """Capture the inputs from a ``scenarios.ScenarioResult`` (design ``index``).

        Handling: the decimated histories 't_s', 'steer_rad', 'slip_angle_rad', the mean
        speed over the run and the metric windows 't_first_lane_change_s',
        't_manoeuvre_s'.  Mixed: the same from the lane change, starting the handling
        scenario's lead-in (config/scenarios.yaml ``handling.lead_in_m``) before lane 1,
        on the smooth road after the paving.  Ride: only the design (the road comes from
        config).
        """
        name = result.name
        x = np.asarray(result.x, dtype=float)[index].copy()
        if name == 'ride':
            return cls('ride', x)
        if name not in INPUT_SCENARIOS:
            raise ValueError(f'no simplified model for scenario {name!r}')
        h, m = result.histories, result.metrics
        t = np.asarray(h['t_s'], dtype=float)
        manoeuvre = tuple(m['t_manoeuvre_s'][index])
        first = 0
        if name == 'mixed':
            from .params import load_scenarios_config

            speed = float(np.mean(h['speed_mps'][index]))
            lead_s = float(load_scenarios_config()['handling']['lead_in_m']) / speed
            first = int(np.searchsorted(t, manoeuvre[0] - lead_s))
        inputs = HandlingInputs(
            t_s=t[first:],
            speed_mps=float(np.mean(h['speed_mps'][index][first:])),
            steer_rad=np.asarray(h['steer_rad'][index][first:], dtype=float),
            slip_angle_rad=np.asarray(h['slip_angle_rad'][index][:, first:], dtype=float),
            first_lane_change_s=tuple(m['t_first_lane_change_s'][index]),
            manoeuvre_s=manoeuvre,
        )
        return cls(name, x, inputs)


#: Design-variable targets that act in roll only: the pitch-plane model cannot see them.
ROLL_TARGETS = ('anti_roll_bar',)
#: config/simplified_models.yaml ``ride_model`` (other than 'auto') -> the model's class.
RIDE_MODEL_CLASSES = {'pitch_plane': PitchPlaneModel, 'roll_pitch': RollPitchModel}


def ride_model_kind(n_vars: int, space: DesignSpace | None = None,
                    scenario: str = 'ride') -> str:
    """The simplified ride model for a design: 'pitch_plane' or 'roll_pitch'.

    config/simplified_models.yaml ``ride_model``; 'auto' picks the roll-and-pitch model
    for the mixed scenario's paving (the paper has no model of that scenario) and, on
    the ride scenario, when a design variable acts in roll only (:data:`ROLL_TARGETS`);
    else the paper's pitch-plane model.
    """
    kind = load_simplified_config()['ride_model']
    if kind != 'auto':
        return kind
    if scenario == 'mixed':
        return 'roll_pitch'
    space = space if space is not None else load_design_space()
    targets = {v.target for v in space.design_variables(n_vars)}
    return 'roll_pitch' if targets & set(ROLL_TARGETS) else 'pitch_plane'


@functools.lru_cache(maxsize=16)
def ride_model(road: str = '', condition: str = '',
               kind: str = 'pitch_plane') -> PitchPlaneModel | RollPitchModel:
    """The ride model (config files), built once per process, road, condition and kind.

    ``road``: the ride road in place of config/scenarios.yaml's (a road name, a road
    file or an entry as YAML, :func:`~suspension_tuning.vehicle.road.resolve_road`).
    ``condition``: an operating condition as text
    (:meth:`suspension_tuning.conditions.Condition.as_text`): its speed, payload and road
    (the eq. 15-24 model's inputs follow them); '' = none.  ``kind``: 'pitch_plane'
    (eqs. 15-24) or 'roll_pitch' (:class:`~.roll_pitch.RollPitchModel`).
    """
    model = RIDE_MODEL_CLASSES[kind]
    if not road and not condition:
        return model()
    from .params import load_scenarios_config, load_vehicle_params
    from .pitch_plane import RideSetup

    params = load_vehicle_params()
    scenarios = load_scenarios_config()
    if road:
        scenarios['ride']['road'] = road
    if condition:
        from suspension_tuning.conditions import (
            Condition,
            condition_params,
            condition_scenarios,
        )

        parsed = Condition.from_text(condition)
        params = condition_params(parsed, params)
        scenarios = condition_scenarios(parsed, scenarios)
    return model(params, RideSetup.from_scenario_config(params, scenarios))


@functools.lru_cache(maxsize=16)
def handling_model(condition: str = '') -> HandlingModel:
    """The handling model (config files), built once per process and condition.

    ``condition``: an operating condition as text (:func:`ride_model`): its
    payload (mass, centre of gravity, inertias); its manoeuvre speed reaches the model
    through the full run's inputs.  '' = none.
    """
    if not condition:
        return HandlingModel()
    from suspension_tuning.conditions import Condition, condition_params

    return HandlingModel(condition_params(Condition.from_text(condition)))


def run_simplified(
    scenario: str, x: np.ndarray, n_vars: int, inputs: SimplifiedInputs | None = None,
    road: str = '',
    space: DesignSpace | None = None,
    condition: str = '',
) -> dict[str, np.ndarray]:
    """Evaluate the simplified model of a scenario for a batch of designs.

    Parameters
    ----------
    scenario : {'ride', 'handling', 'mixed'}
        Scenario.
    x : array_like
        Normalised designs (n_vars,) or (batch, n_vars) in [0.001, 1].
    n_vars : int
        2 or 4, or a preset's size.
    inputs : SimplifiedInputs, optional
        Required for 'handling' and 'mixed' (captured from the full model's run).
    road : str
        Ride road in place of the configured one (:func:`ride_model`).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).
    condition : str
        An operating condition as text (:func:`ride_model`,
        :func:`handling_model`).

    Returns
    -------
    dict
        'f' (batch,), 'g' (batch, 4) and the model's metrics.
    """
    if scenario not in SIMPLIFIED_SCENARIOS:
        raise ValueError(
            f'unknown scenario {scenario!r}; valid: {", ".join(SIMPLIFIED_SCENARIOS)}'
        )
    if scenario == 'ride':
        kind = ride_model_kind(n_vars, space)
        return ride_model(road, condition, kind).evaluate(x, n_vars, space)
    if inputs is None or inputs.handling is None:
        raise ValueError(f'the {scenario} simplified model needs SimplifiedInputs from a full '
                         f'{scenario} run')
    if inputs.scenario != scenario:
        raise ValueError(f'inputs are for scenario {inputs.scenario!r}, not {scenario}')
    if scenario == 'mixed':
        if condition:
            raise ValueError('the mixed scenario runs without an operating condition')
        return run_mixed_simplified(x, n_vars, inputs.handling, road, space)
    return handling_model(condition).evaluate(x, n_vars, inputs.handling, space)


@functools.lru_cache(maxsize=8)
def mixed_ride_model(road: str = '', kind: str = 'roll_pitch'
                     ) -> PitchPlaneModel | RollPitchModel:
    """A ride model on the mixed scenario's paving (config/mixed.yaml).

    ``kind``: 'roll_pitch' (:class:`~.roll_pitch.RollPitchModel`) or 'pitch_plane'
    (eqs. 15-24).

    The ride scenario's road (or ``road``) at the mixed scenario's speed, for as long as
    the full run stays on the paving (``rough_length_m``; at least one second after the
    ``settle_s`` W_b settling), so the eq. 9 window is the full run's.
    """
    from .mixed import load_mixed_config
    from .params import load_scenarios_config, load_vehicle_params
    from .pitch_plane import RideSetup

    cfg = load_mixed_config()
    params = load_vehicle_params()
    scenarios = load_scenarios_config()
    ride = scenarios['ride']
    if road:
        ride['road'] = road
    speed = float(cfg['speed_kmh']) / 3.6
    settle = float(cfg['settle_s'])
    ride.update(speed_kmh=float(cfg['speed_kmh']), settle_s=settle,
                duration_s=max(float(cfg['rough_length_m']) / speed, settle + 1.0))
    return RIDE_MODEL_CLASSES[kind](params, RideSetup.from_scenario_config(params, scenarios))


def mixed_handling_settings(settings: AxleSettings) -> AxleSettings:
    """The handling-state settings the mixed scenario's full run gives each design.

    The full run puts a design's generic settings (``dpsf``, ``gas_volume`` and their
    compression/rebound halves) in the ride state and keeps the handling state at
    config/strut_4s4.yaml's baseline unless the design sets it explicitly
    (``gas_volume_stiff``, ``dpsf_high``; ``SuspensionSetting.from_design`` in mode
    'ride', whose stiff volume is capped at the soft one); anti-roll bars act in both
    states.  This is that handling state, as one-state settings for the handling model.
    """
    from .full_model import SuspensionSetting
    from .params import load_vehicle_params

    full = SuspensionSetting.from_design(settings, 'ride', load_vehicle_params())
    dpsf = {a: full.dpsf_high[:, j] for j, a in enumerate(AXLES)}
    spring = {a: full.gas_volume_stiff_m3[:, j] for j, a in enumerate(AXLES)}
    extra = {a: v for a, v in settings.extra.items() if a.startswith('anti_roll_bar')}
    extra.update({f'dpsf_rebound_{a}': full.dpsf_high_rebound[:, j]
                  for j, a in enumerate(AXLES)})
    return AxleSettings.of(dpsf, spring, 'volume', extra)


def run_mixed_simplified(x: np.ndarray, n_vars: int, inputs: HandlingInputs, road: str = '',
                         space: DesignSpace | None = None) -> dict[str, np.ndarray]:
    """The mixed scenario's simplified model: the paper's two, each in its valve state.

    A ride model on the paving (:func:`mixed_ride_model`, :func:`ride_model_kind`)
    in the ride state and the handling model (eqs. 12-14) on the lane change (``inputs``
    from the full mixed run) in the handling state (:func:`mixed_handling_settings`).
    f = (f_ride + f_hand) / 2 as the full run's (eqs. 9, 10); g (eq. 11) from the
    fraction of time each tyre is off the ground over both windows,
    ``(p_r T_r + p_h T_h) / (T_r + T_h)``, with T_r the ride window after the settling
    and T_h the manoeuvre window: the full run's g also counts the smooth road between
    them, where no tyre lifts, so its g is lower by a near-constant amount that eq. 25's
    offset takes up.

    Returns
    -------
    dict
        'f' (batch,), 'g' and 'g_soft' (batch, 4) FL, FR, RL, RR, and the metrics of
        both models ('a_rms_driver_mps2', 'a_rms_passenger_mps2', 'roll_first_peak_deg',
        'roll_rate_rms_deg_s').
    """
    xb = validate_design(x, n_vars)
    paving = mixed_ride_model(road, ride_model_kind(n_vars, space, 'mixed'))
    ride = paving.evaluate(xb, n_vars, space)
    hand = handling_model().evaluate_settings(
        mixed_handling_settings(to_physical(xb, n_vars, space)), inputs)
    t_ride = paving.setup.duration_s - paving.setup.settle_s
    t_hand = inputs.manoeuvre_s[1] - inputs.manoeuvre_s[0]
    out = {k: v for k, v in ride.items() if k not in GROUPED}
    out.update({k: v for k, v in hand.items() if k not in GROUPED})
    out['f'] = 0.5 * (np.asarray(ride['f']) + np.asarray(hand['f']))
    for key in ('g', 'g_soft'):  # eq. 11 and its smooth count (metrics.py), alike
        p_ride = np.asarray(ride[key]) / 10.0 + TYRE_HOP_MAX_FRACTION
        p_hand = np.asarray(hand[key]) / 10.0 + TYRE_HOP_MAX_FRACTION
        p = (p_ride * t_ride + p_hand * t_hand) / (t_ride + t_hand)
        out[key] = 10.0 * (p - TYRE_HOP_MAX_FRACTION)
    return out


#: Outputs of both simplified models that the mixed model combines, not copies.
GROUPED = ('f', 'g', 'g_soft')
