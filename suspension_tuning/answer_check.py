"""The answer checked at a tighter solver tolerance (no rclpy).

An optimiser on a model integrated at a loose error tolerance (a multibody code at its
default, the built-in variable-step model at Adams' 1e-3) decides feasibility with the
integrator's bias: on the 4-variable ride the tyre-hop constraints of the noisy model's
optimum are about 0.015 lower than the converged solution's (docs/noise_study.md).
:func:`check_design` runs the reported design once more by Dormand-Prince 5(4) at the
tightened tolerance of config/vehicle.yaml ``integration.check`` (same output grid);
:func:`suspension_tuning.tuning.check_summary` gives the two verdicts.  The run counts
as a paid full run.  An answer the check finds infeasible is continued
(``integration.check.continue_by``): on the check's model itself from the answer
(``tighter_model``, :func:`check_options`' model with its metrics and inputs) or on the
run's model with the constraints shifted by the check's offset (``shift``).
An FMU is checked by the tolerance of FMI's ``setupExperiment`` where the FMU supports
it; this module serves the built-in model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from suspension_tuning.paths import config_dir, read_yaml

#: The check model's key in config/optimiser.yaml ``noise_levels`` (per scenario).
CHECK_INTEGRATOR = 'check'


@dataclass(frozen=True)
class CheckSettings:
    """Settings of the check run (config/vehicle.yaml ``integration.check``).

    ``rtol``, ``atol``: DOPRI5's error tolerances; ``gtol``: the check's feasibility
    tolerance on g; ``continuations``: shifted continuations at most; ``continue_by``:
    how a run whose answer the check finds infeasible goes on
    (:data:`suspension_tuning.tuning.CONTINUE_BY`); ``last_iterate_gap``: relative f
    by which a run's answer may lie above its last iterate, infeasible on the run's
    model, before the run goes on from that iterate on the check's model (0: never;
    ``tuning.optimise``'s ``check_last_gap``); ``refine_noise_stop``: a run the noise
    test ended on a model noisier than the check's goes on from its answer on the
    check's model (``check_refine_noise_stop``).
    """

    rtol: float
    atol: float
    gtol: float = 5e-3
    continuations: int = 2
    continue_by: str = 'shift'
    last_iterate_gap: float = 0.0
    refine_noise_stop: bool = False

    def __post_init__(self) -> None:
        """Positive, finite tolerances, a known continuation (ValueError naming the key)."""
        from suspension_tuning.tuning import CONTINUE_BY

        for name in ('rtol', 'atol'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f'integration.check.{name} must be positive and finite, '
                                 f'got {value}')
        if not (np.isfinite(self.last_iterate_gap) and self.last_iterate_gap >= 0.0):
            raise ValueError(f'integration.check.last_iterate_gap must be >= 0 and finite, '
                             f'got {self.last_iterate_gap}')
        if self.continue_by not in CONTINUE_BY:
            raise ValueError(f'integration.check.continue_by must be one of '
                             f'{", ".join(CONTINUE_BY)}, got {self.continue_by!r}')


def load_check_settings(path: str | Path | None = None) -> CheckSettings:
    """The check's tolerances from config/vehicle.yaml (``integration.check``)."""
    d = read_yaml(Path(path) if path is not None else config_dir() / 'vehicle.yaml')
    check = d['integration'].get('check')
    if check is None:
        raise ValueError('config/vehicle.yaml has no integration.check (rtol, atol)')
    return CheckSettings(float(check['rtol']), float(check['atol']),
                         float(check.get('gtol', 5e-3)), int(check.get('continuations', 2)),
                         str(check.get('continue_by', 'shift')),
                         float(check.get('last_iterate_gap', 0.0)),
                         _flag(check.get('refine_noise_stop', False),
                               'integration.check.refine_noise_stop'))


def _flag(value: Any, key: str) -> bool:
    """A YAML boolean (ValueError naming the key for anything else)."""
    if not isinstance(value, bool):
        raise ValueError(f'{key} must be true or false, got {value!r}')
    return value


def check_design(scenario: str, n_vars: int, x: ArrayLike,
                 settings: CheckSettings | None = None) -> tuple[float, np.ndarray]:
    """f and g of one normalised design at the check's tighter tolerance (one full run)."""
    res = _check_run(scenario, n_vars, x, settings)
    return float(res.f[0]), np.asarray(res.g[0], float).copy()


def _check_run(scenario: str, n_vars: int, x: ArrayLike, settings: CheckSettings | None,
               condition: Any = None) -> Any:
    """Designs' runs at the check's tolerance (in ``condition``: its vehicle, speeds).

    ``x``: one design (n,) or a batch (m, n).
    """
    from suspension_tuning.conditions import condition_params, condition_scenarios
    from suspension_tuning.vehicle.params import load_vehicle_params, with_integrator
    from suspension_tuning.vehicle.runs import run_full

    settings = load_check_settings() if settings is None else settings
    params = with_integrator(load_vehicle_params(), 'variable_step', rtol=settings.rtol,
                             atol=settings.atol)
    # 'mixed': in-process valve controllers (the same bits as over ROS); no conditions
    return run_full(scenario, np.atleast_2d(np.asarray(x, float)),
                    params=condition_params(condition, params), n_vars=n_vars,
                    config=None if condition is None else condition_scenarios(condition),
                    integrator='variable_step')


def check_options(scenario: str, n_vars: int, settings: CheckSettings | None = None,
                  inputs: Callable[[Any], Any] | None = None) -> dict[str, Any]:
    """``tuning.optimise``'s check arguments for the built-in model of a scenario.

    ``check_model`` (designs (1, n) -> ``FullEvaluation`` at the tighter tolerance, with
    the named metrics and the simplified model's inputs), ``check_gtol``,
    ``check_continuations``, ``check_continue_by``, ``check_last_gap``,
    ``check_refine_noise_stop`` (config/vehicle.yaml
    ``integration.check``) and ``check_noise``, the check model's noise levels (f, g)
    (config/optimiser.yaml ``noise_levels``, integrator ``check``) for a run continued
    on it: what the coordinator passes for the built-in model, and an in-process run
    that must reach the same bits.  ``inputs``: scenario result -> what the scenario's
    simplified gradient takes (default the result itself, as in-process gradients take
    it; the coordinator packs it as the simulation node does).
    """
    from suspension_tuning.evaluation import metric_table
    from suspension_tuning.tuning import FullEvaluation, noise_levels

    settings = load_check_settings() if settings is None else settings

    def model(designs: ArrayLike) -> FullEvaluation:
        x = np.atleast_2d(np.asarray(designs, float))
        res = _check_run(scenario, n_vars, x, settings)
        names, table = metric_table(res.metrics, len(x))
        return FullEvaluation(np.asarray(res.f, float).copy(),
                              np.asarray(res.g, float).copy(),
                              inputs=res if inputs is None else inputs(res),
                              metric_names=names, metrics=table)

    return {'check_model': model, 'check_gtol': settings.gtol,
            'check_continuations': settings.continuations,
            'check_continue_by': settings.continue_by,
            'check_last_gap': settings.last_iterate_gap,
            'check_refine_noise_stop': settings.refine_noise_stop,
            'check_noise': noise_levels(scenario, CHECK_INTEGRATOR)}


def check_condition_options(scenario: str, n_vars: int,
                            settings: CheckSettings | None = None) -> dict[str, Any]:
    """:func:`~suspension_tuning.tuning.optimise_conditions`'s check arguments (built-in).

    ``check_model`` ((1, n) design, conditions) -> one ``FullEvaluation`` per condition
    (f, g and the named metrics) at the tighter tolerance, the design run in every
    condition (its payload, speeds and road), ``check_gtol`` and ``check_continuations``
    (config/vehicle.yaml ``integration.check``).
    """
    from suspension_tuning.evaluation import metric_table
    from suspension_tuning.tuning import FullEvaluation

    settings = load_check_settings() if settings is None else settings

    def model(designs: ArrayLike, conditions: Any) -> list[FullEvaluation]:
        x = np.atleast_2d(np.asarray(designs, float))[0]
        out = []
        for condition in conditions:
            res = _check_run(scenario, n_vars, x, settings, condition)
            names, table = metric_table(res.metrics, 1)
            out.append(FullEvaluation(np.asarray(res.f, float), np.asarray(res.g, float),
                                      metric_names=names, metrics=table))
        return out

    return {'check_model': model, 'check_gtol': settings.gtol,
            'check_continuations': settings.continuations}
