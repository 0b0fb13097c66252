"""One entry to the built-in full model for every scenario.

The ride and handling scenarios are open-loop runs (:mod:`.scenarios`); the mixed one
closes the loop through the 4S4 valve controller (:mod:`.mixed`, which builds on
:mod:`.scenarios`).  A study, a calibration or the answer check that may run any of them
calls :func:`run_full`, so the dispatch lives here once.  Valve controllers over ROS
and another road: :func:`suspension_tuning.evaluation.evaluate`.
"""

from __future__ import annotations

import numpy as np

from .design import DesignSpace, validate_design
from .mixed import load_mixed_config, run_mixed
from .params import VehicleParams, load_vehicle_params, with_integrator
from .scenarios import SCENARIOS as OPEN_LOOP_SCENARIOS
from .scenarios import ScenarioResult, run_scenario

#: The closed-loop scenario: the valve controller switches the 4S4 during the run.
CLOSED_LOOP_SCENARIO = 'mixed'
#: Every scenario of the built-in full model.
SCENARIOS = (*OPEN_LOOP_SCENARIOS, CLOSED_LOOP_SCENARIO)


def run_full(
    name: str,
    x: np.ndarray,
    params: VehicleParams | None = None,
    n_vars: int | None = None,
    config: dict | None = None,
    integrator: str | None = None,
    space: DesignSpace | None = None,
) -> ScenarioResult:
    """Simulate any scenario of the built-in full model for one or many designs.

    Parameters
    ----------
    name : {'ride', 'handling', 'mixed'}
        Scenario; 'mixed' runs with in-process valve controllers (the same bits as the
        valve_controller node's).
    x : np.ndarray
        Normalised design(s), shape (n_vars,) or (batch, n_vars) (paper eqs. 4-8;
        0.001 <= x <= 1).
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).
    n_vars : int, optional
        Number of design variables (default: the length of x's last axis).
    config : dict, optional
        Scenario configuration (default config/scenarios.yaml; 'mixed':
        config/mixed.yaml).
    integrator : str, optional
        'fixed_step' or 'variable_step' (default ``params.integrator.method``).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).

    Returns
    -------
    ScenarioResult
        f (batch,), g (batch, 4), metrics and histories.

    Raises
    ------
    ValueError
        Unknown scenario, a bad design vector, or a run whose state turns non-finite.
    """
    if name != CLOSED_LOOP_SCENARIO:
        if name not in OPEN_LOOP_SCENARIOS:
            raise ValueError(f'unknown scenario {name!r}; valid scenarios: '
                             f'{", ".join(SCENARIOS)}')
        return run_scenario(name, x, params, n_vars, config, integrator, space=space)
    params = with_integrator(params if params is not None else load_vehicle_params(), integrator)
    n = n_vars if n_vars is not None else (int(np.shape(x)[-1]) if np.ndim(x) else -1)
    return run_mixed(validate_design(x, n), params=params,
                     config=config if config is not None else load_mixed_config(), space=space)
