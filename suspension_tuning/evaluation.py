"""Full-model evaluation of designs as the graph exchanges it (no rclpy).

The simulation node and in-process runs both go through :func:`evaluate`, so a
design gives the same bits either way.  Requests arrive as flat arrays (ROS
messages have no 2-D arrays): :func:`parse_designs` checks them and says exactly
what is wrong (wrong length, NaN, out of bounds, unknown scenario).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from suspension_tuning.metric_names import METRIC_NAMES, TYRES  # noqa: F401
from suspension_tuning.vehicle.design import DesignSpace, load_design_space, validate_design
from suspension_tuning.vehicle.mixed import run_mixed
from suspension_tuning.vehicle.params import (
    load_scenarios_config,
    load_vehicle_params,
    with_integrator,
)
from suspension_tuning.vehicle.runs import SCENARIOS as MODEL_SCENARIOS
from suspension_tuning.vehicle.scenarios import ScenarioResult, run_scenario

Array = NDArray[np.float64]
@dataclass
class DesignEvaluation:
    """Objective, constraints and named metrics of a batch of designs.

    Attributes
    ----------
    f : ndarray, shape (m,)
        Objective, eq. 9 or eq. 10.
    g : ndarray, shape (m, 4)
        Tyre-hop constraints FL, FR, RL, RR, eq. 11 (<= 0 feasible).
    metric_names : list of str
        Names with units; per-tyre metrics are split into ``<name>_fl`` etc.
    metrics : ndarray, shape (m, len(metric_names))
        Metric values.
    result : ScenarioResult
        The full scenario result (time histories for telemetry and the simplified
        models).
    """

    f: Array
    g: Array
    metric_names: list[str]
    metrics: Array
    result: ScenarioResult


def scenarios() -> tuple[str, ...]:
    """Names of the full-model scenarios ('mixed': closed-loop valve control)."""
    return MODEL_SCENARIOS


def parse_designs(scenario: str, n_vars: int, flat: Sequence[float],
                  space: DesignSpace | None = None) -> Array:
    """Check a request and reshape its flat, row-major designs to (m, n_vars).

    Raises
    ------
    ValueError
        Unknown scenario, n_vars not 2 or 4 or a preset's size of ``space`` (default
        config/design_space.yaml), a length that is not a positive multiple
        of n_vars, NaN or infinite values, or values outside 0.001..1 (eqs. 6, 8).
    """
    if scenario not in scenarios():
        raise ValueError(f'unknown scenario {scenario!r}; valid: {", ".join(scenarios())}')
    (space if space is not None else load_design_space()).check_size(n_vars)
    values = np.asarray(flat, dtype=float)
    if values.size == 0 or values.size % n_vars:
        raise ValueError(f'designs must hold a positive multiple of n_vars = {n_vars} '
                         f'values (row-major designs), got {values.size}')
    return validate_design(values.reshape(-1, n_vars), n_vars)


def metric_table(metrics: dict[str, np.ndarray], batch: int) -> tuple[list[str], Array]:
    """Flatten named metrics of shape (m,) or (m, 4) into names and an (m, k) table."""
    names: list[str] = []
    columns: list[np.ndarray] = []
    for name, value in metrics.items():
        value = np.asarray(value, dtype=float).reshape(batch, -1)
        if value.shape[1] == 1:
            names.append(name)
            columns.append(value[:, 0])
        else:
            labels = TYRES if value.shape[1] == 4 else range(value.shape[1])
            for column, label in zip(value.T, labels):
                names.append(f'{name}_{label}')
                columns.append(column)
    return names, np.column_stack(columns) if columns else np.zeros((batch, 0))


def evaluate(scenario: str, designs: Array, controllers: list | None = None,
             integrator: str | None = None, road: str = '', condition: str = '',
             **kwargs: Any) -> DesignEvaluation:
    """Run the full model on a batch of designs (m, n_vars).

    Parameters
    ----------
    scenario : str
        'ride', 'handling' or 'mixed' (see :func:`scenarios`).
    designs : ndarray, shape (m, n_vars)
        Normalised designs, already checked by :func:`parse_designs`.
    controllers : list of callables, optional
        Valve controllers of the 'mixed' scenario, one per design (default in-process;
        see :func:`suspension_tuning.vehicle.mixed.run_mixed`).
    integrator : str, optional
        'fixed_step' or 'variable_step' (default config/vehicle.yaml, fixed_step).
    road : str
        The road of the ride and mixed scenarios in place of config/scenarios.yaml's: a
        road name, a road file or an entry as YAML
        (:func:`~suspension_tuning.vehicle.road.resolve_road`); '' = the configured one.
        The handling scenario runs on its smooth road whatever this says.
    condition : str
        An operating condition as text (:meth:`suspension_tuning.conditions.Condition.
        as_text`): the ride at its speed, with its payload, on its road (before
        ``road``), the handling lane change at its manoeuvre speed with its payload;
        '' = none.  Ride and handling.
    **kwargs
        Passed to :func:`suspension_tuning.vehicle.scenarios.run_scenario` (or
        :func:`~suspension_tuning.vehicle.mixed.run_mixed`): ``params``, ``space`` (the
        design space, default config/design_space.yaml)...
    """
    if integrator is not None:
        params = kwargs.get('params') or load_vehicle_params()
        kwargs['params'] = with_integrator(params, integrator)
    if condition:
        from suspension_tuning.conditions import (
            CONDITION_SCENARIOS,
            Condition,
            condition_params,
            condition_scenarios,
        )

        if scenario not in CONDITION_SCENARIOS:
            raise ValueError(f'operating conditions are for the ride and handling scenarios, '
                             f'not {scenario!r}')
        parsed = Condition.from_text(condition)
        kwargs['params'] = condition_params(parsed, kwargs.get('params'))
        kwargs['config'] = condition_scenarios(parsed, kwargs.get('config'))
    if scenario == 'mixed':
        result = run_mixed(designs, controllers, road=road or None, **kwargs)
    else:
        if road:
            config = copy.deepcopy(kwargs.get('config') or load_scenarios_config())
            config['ride']['road'] = road
            kwargs['config'] = config
        result = run_scenario(scenario, designs, **kwargs)
    names, table = metric_table(result.metrics, len(designs))
    return DesignEvaluation(f=np.asarray(result.f, float), g=np.asarray(result.g, float),
                            metric_names=names, metrics=table, result=result)


def in_process_model(scenario: str, integrator: str | None = None,
                     space: DesignSpace | None = None) -> Callable[[Array], Any]:
    """The full model of ``scenario`` in-process, as ``tuning.optimise`` calls it.

    Returns a callable designs (m, n) -> ``tuning.FullEvaluation`` with the named
    metrics (what extra constraints bound) and the scenario result as the simplified
    model's inputs; 'mixed' runs with in-process valve controllers.  ``integrator``:
    'fixed_step' or 'variable_step' (None or '': config/vehicle.yaml's).  ``space``:
    the design space (default config/design_space.yaml).
    """
    from suspension_tuning.tuning import FullEvaluation

    if scenario not in scenarios():
        raise ValueError(f'unknown scenario {scenario!r}; valid: {", ".join(scenarios())}')

    def run(designs: Array) -> FullEvaluation:
        result = evaluate(scenario, np.atleast_2d(np.asarray(designs, dtype=float)),
                          integrator=integrator or None, space=space)
        return FullEvaluation(f=result.f, g=result.g, inputs=result.result,
                              metric_names=result.metric_names, metrics=result.metrics)

    return run


def in_process_condition_model(integrator: str | None = None, scenario: str = 'ride'
                               ) -> Callable[[Array, Any], list]:
    """The built-in full model over conditions, in-process (one design-batch per condition).

    ``scenario``: 'ride' or 'handling'; the scenario result is the simplified model's
    inputs (``FullEvaluation.inputs``, those of the first design).
    """
    from suspension_tuning.tuning import FullEvaluation

    def run(designs: Array, conditions: Sequence[Any]) -> list[FullEvaluation]:
        out = []
        for condition in conditions:
            result = evaluate(scenario, np.atleast_2d(np.asarray(designs, float)),
                              integrator=integrator or None, condition=condition.as_text())
            out.append(FullEvaluation(f=result.f, g=result.g, inputs=result.result,
                                      metric_names=result.metric_names,
                                      metrics=result.metrics))
        return out

    return run


def in_process_condition_gradients(conditions: Any, n_vars: int,
                                   cache_dir: str | None = None,
                                   n_samples: int | None = None,
                                   scenario: str = 'ride') -> dict[str, Any]:
    """The scaled simplified gradient of every condition, each calibrated in it.

    One eq. 25 calibration per condition (N full runs in that condition, config/
    simplified_models.yaml ``scaling``), kept in ``cache_dir`` (default
    ``~/.cache/suspension_tuning/calibration``) under a key that holds the condition.
    ``n_samples`` 0: none, unit scaling in every condition (as the coordinator runs a
    case whose ``scaling.run_samples`` is 0; the run's correction maps the slopes).

    Returns
    -------
    dict
        Condition name -> :class:`~suspension_tuning.optim.simplified_gradient.
        SimplifiedGradient`, whose attribute ``calibration_runs`` holds the full runs its
        calibration spent now (0 when loaded from the cache).
    """
    import hashlib
    import json
    from pathlib import Path

    from suspension_tuning.optim.scaling import Scaling, scaling_key
    from suspension_tuning.optim.simplified_gradient import (
        SimplifiedGradient,
        calibrate,
        calibration_settings,
    )

    directory = Path(cache_dir) if cache_dir else (
        Path.home() / '.cache' / 'suspension_tuning' / 'calibration')
    out: dict[str, Any] = {}
    # 0: none, unit scaling (the run's correction maps the slopes)
    n_samples, seed = calibration_settings(n_samples) if n_samples != 0 else (0, None)
    for condition in getattr(conditions, 'conditions', conditions):
        text = condition.as_text()
        scaling, runs = None, 0
        if n_samples:
            key = scaling_key(scenario, n_vars, n_samples, seed)
            key['condition'] = text
            digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
            path = directory / f'condition_{scenario}_{n_vars}var_{digest}.json'
            if path.exists():
                try:
                    scaling = Scaling.load(path, expected_key=key)
                except ValueError:
                    scaling = None
            if scaling is None:
                scaling = calibrate(scenario, n_vars, n_samples, seed, condition=text)
                runs = n_samples
                path.parent.mkdir(parents=True, exist_ok=True)
                scaling.save(path)
        gradient = SimplifiedGradient(scenario, n_vars, scaling, condition=text)
        gradient.calibration_runs = runs
        out[condition.name] = gradient
    return out
