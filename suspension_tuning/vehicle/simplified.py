"""Entry point of the simplified models (section 6): inputs captured from a full run.

:class:`SimplifiedInputs` holds what a simplified model needs from the full model's run at
the current design (the paper feeds the handling model the full model's steering and slip
angles [P s.6.1]; the ride model's road is the scenario's seeded road, known in advance, so
ride needs nothing from the run).  The ROS gradient node can cache one per iterate.

:func:`run_simplified` evaluates f (eq. 9 or 10) and g (eq. 11, FL, FR, RL, RR) of a batch
of designs with the pitch-plane ride model or the handling model.  Models are cached per
process (building the ride road costs one road synthesis).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .design import DesignSpace
from .handling_model import HandlingInputs, HandlingModel
from .pitch_plane import PitchPlaneModel

SIMPLIFIED_SCENARIOS = ('ride', 'handling')


@dataclass(frozen=True)
class SimplifiedInputs:
    """Inputs of a simplified model, captured from one full-model scenario run.

    Attributes
    ----------
    scenario : str
        'ride' or 'handling'.
    x : np.ndarray or None
        Normalised design of the full run they came from (n_vars,), for bookkeeping.
    handling : HandlingInputs or None
        Steering, slip angles, speed and metric windows (handling only).
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
        if self.scenario == 'handling' and not isinstance(self.handling, HandlingInputs):
            raise ValueError('handling SimplifiedInputs need HandlingInputs (steer, slip angles)')

    @classmethod
    def from_scenario_result(cls, result, index: int = 0) -> SimplifiedInputs:
        """Capture the inputs from a ``scenarios.ScenarioResult`` (design ``index``).

        Handling: the decimated histories 't_s', 'steer_rad', 'slip_angle_rad', the mean
        speed over the run and the metric windows 't_first_lane_change_s',
        't_manoeuvre_s'.  Ride: only the design (the road comes from config).
        """
        name = result.name
        x = np.asarray(result.x, dtype=float)[index].copy()
        if name == 'ride':
            return cls('ride', x)
        if name != 'handling':
            raise ValueError(f'no simplified model for scenario {name!r}')
        h, m = result.histories, result.metrics
        inputs = HandlingInputs(
            t_s=np.asarray(h['t_s'], dtype=float),
            speed_mps=float(np.mean(h['speed_mps'][index])),
            steer_rad=np.asarray(h['steer_rad'][index], dtype=float),
            slip_angle_rad=np.asarray(h['slip_angle_rad'][index], dtype=float),
            first_lane_change_s=tuple(m['t_first_lane_change_s'][index]),
            manoeuvre_s=tuple(m['t_manoeuvre_s'][index]),
        )
        return cls('handling', x, inputs)


@functools.lru_cache(maxsize=16)
def pitch_plane_model(road: str = '', condition: str = '') -> PitchPlaneModel:
    """The pitch-plane model (config files), built once per process, road and condition.

    ``road``: the ride road in place of config/scenarios.yaml's (a road name, a road
    file or an entry as YAML, :func:`~suspension_tuning.vehicle.road.resolve_road`).
    ``condition``: an operating condition as text
    (:meth:`suspension_tuning.conditions.Condition.as_text`): its speed, payload and road
    (the eq. 15-24 model's inputs follow them); '' = none.
    """
    if not road and not condition:
        return PitchPlaneModel()
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
    return PitchPlaneModel(params, RideSetup.from_scenario_config(params, scenarios))


@functools.lru_cache(maxsize=16)
def handling_model(condition: str = '') -> HandlingModel:
    """The handling model (config files), built once per process and condition.

    ``condition``: an operating condition as text (:func:`pitch_plane_model`): its
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
    scenario : {'ride', 'handling'}
        Scenario.
    x : array_like
        Normalised designs (n_vars,) or (batch, n_vars) in [0.001, 1].
    n_vars : int
        2 or 4.
    inputs : SimplifiedInputs, optional
        Required for 'handling' (captured from the full model's run).
    road : str
        Ride road in place of the configured one (:func:`pitch_plane_model`).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).
    condition : str
        An operating condition as text (:func:`pitch_plane_model`,
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
        return pitch_plane_model(road, condition).evaluate(x, n_vars, space)
    if inputs is None or inputs.handling is None:
        raise ValueError('the handling model needs SimplifiedInputs from a full handling run')
    if inputs.scenario != 'handling':
        raise ValueError(f'inputs are for scenario {inputs.scenario!r}, not handling')
    return handling_model(condition).evaluate(x, n_vars, inputs.handling, space)
