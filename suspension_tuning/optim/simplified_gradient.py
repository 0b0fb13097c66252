"""Gradients from the eq. 25-scaled simplified models (Thoresson et al. 2009, section 6).

* :func:`simplified_values` - objective and constraints of the simplified model of a
  scenario for a batch of designs, optionally scaled by eq. 25.
* :func:`calibrate` - the eq. 25 scaling from N full-model samples (default 30 [P]):
  one batched full run of the samples, the simplified model at the same designs (for
  handling each sample uses the inputs captured from its own full run, as at an
  iterate), then :func:`scaling.fit_scaling`.  :func:`load_or_calibrate` keeps it in a
  JSON file keyed by scenario, n_vars, n_samples, seed and config hash.
* :class:`SimplifiedGradient` - central differences of the scaled simplified model: the
  gradient of f and the Jacobian of g from ONE batch of the 2n stencil points of
  ``finite_diff.central_difference`` (shifted inside the bounds, never outside).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from suspension_tuning.optim.finite_diff import central_difference
from suspension_tuning.optim.scaling import Scaling, fit_scaling, sample_design_space, scaling_key
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER, DesignSpace, validate_design
from suspension_tuning.vehicle.handling_model import HandlingInputs
from suspension_tuning.vehicle.pitch_plane import load_simplified_config
from suspension_tuning.vehicle.simplified import (
    INPUT_SCENARIOS,
    SIMPLIFIED_SCENARIOS,
    SimplifiedInputs,
    run_simplified,
)

Array = NDArray[np.float64]


def as_simplified_inputs(scenario: str, inputs: Any) -> SimplifiedInputs | None:
    """Normalise what a caller passes as the full model's inputs.

    Accepts None (ride), :class:`SimplifiedInputs`, :class:`HandlingInputs`, a
    ``scenarios.ScenarioResult`` (first design) or any object with a ``result`` attribute
    holding one (e.g. ``evaluation.DesignEvaluation``).  Ride needs no inputs: anything
    but a SimplifiedInputs of another scenario is accepted and ignored.
    """
    if inputs is None:
        if scenario in INPUT_SCENARIOS:
            raise ValueError(f'the {scenario} gradient needs the full model inputs (steer, '
                             'slip)')
        return SimplifiedInputs(scenario)
    if isinstance(inputs, SimplifiedInputs):
        if inputs.scenario != scenario:
            raise ValueError(f'inputs are for scenario {inputs.scenario!r}, not {scenario!r}')
        return inputs
    if scenario == 'ride':
        return SimplifiedInputs('ride')  # the ride road comes from config: nothing needed
    if isinstance(inputs, HandlingInputs):
        return SimplifiedInputs(scenario, None, inputs)
    result = getattr(inputs, 'result', inputs)
    if hasattr(result, 'histories') and hasattr(result, 'name'):
        return as_simplified_inputs(scenario, SimplifiedInputs.from_scenario_result(result))
    raise ValueError(f'cannot use {type(inputs).__name__} as simplified-model inputs')


def simplified_values(
    scenario: str,
    x: ArrayLike,
    n_vars: int,
    inputs: Any = None,
    scaling: Scaling | None = None,
    road: str = '',
    space: DesignSpace | None = None,
    condition: str = '',
) -> Array:
    """Simplified-model values (batch, 1 + 4): objective then constraints FL..RR.

    The constraints are the tyre-hop measure that config/simplified_models.yaml
    ``tyre_hop_gradient.measure`` names: 'soft' (the default,
    :func:`~suspension_tuning.vehicle.metrics.soft_tyre_hop_constraints`, smooth in the
    design) or 'count' (eq. 11 as the full model counts it).  Scaled by eq. 25 when
    ``scaling`` is given.  ``road``: the ride road in place of the configured one.
    ``space``: the design space (default config/design_space.yaml).  ``condition``: an
    operating condition as text (its speed, payload and road; handling: its payload).
    """
    inp = as_simplified_inputs(scenario, inputs)
    out = run_simplified(scenario, x, n_vars, inp, road, space, condition)
    vals = np.column_stack([out['f'], out[constraint_measure_key()]])
    return scaling.apply(vals) if scaling is not None else vals


def constraint_measure_key() -> str:
    """Key of the simplified models' output that gives the constraints: 'g' or 'g_soft'."""
    measure = load_simplified_config()['tyre_hop_gradient']['measure']
    if measure not in ('soft', 'count'):
        raise ValueError(f"config/simplified_models.yaml tyre_hop_gradient.measure must be "
                         f"'soft' or 'count', got {measure!r}")
    return 'g_soft' if measure == 'soft' else 'g'


def calibration_settings(n_samples: int | None = None, seed: int | None = None
                         ) -> tuple[int, int]:
    """Number of samples and LHS seed of the eq. 25 calibration, defaults from config.

    What a calibration's key needs (:func:`~suspension_tuning.optim.scaling.scaling_key`),
    without sampling the designs (a maximin Latin hypercube: ~7 ms).

    Returns
    -------
    (N, seed)
        ``n_samples`` and ``seed``, or config/simplified_models.yaml ``scaling`` values
        where None.
    """
    cfg = load_simplified_config()['scaling']
    return (int(cfg['n_samples'] if n_samples is None else n_samples),
            int(cfg['seed'] if seed is None else seed))


def default_calibration_samples(scenario: str, n_vars: int) -> int:
    """Eq. 25 samples a tuning run spends by default on a case: 0 = none (unit scaling).

    config/simplified_models.yaml ``scaling.run_samples`` per scenario and number of
    variables (chosen by measured paid full runs, docs/corrected_gradients.md); a case
    it does not list takes ``scaling.n_samples``.
    """
    cfg = load_simplified_config()['scaling']
    by_size = (cfg.get('run_samples') or {}).get(scenario) or {}
    return int(by_size.get(int(n_vars), cfg['n_samples']))


def run_calibration_samples(scenario: str, n_vars: int, requested: int | None = None) -> int:
    """The eq. 25 samples of a run: ``requested``, or the case's default when it is
    None or negative.

    Raises
    ------
    ValueError
        ``requested`` is 1 (eq. 25 needs two samples at least; 0 means none).
    """  # noqa: D205
    if requested is None or int(requested) < 0:
        return default_calibration_samples(scenario, n_vars)
    if int(requested) == 1:
        raise ValueError('calibration_samples 1: eq. 25 needs at least 2 samples (0: no '
                         'calibration, unit scaling; -1: the default of config/'
                         'simplified_models.yaml scaling.run_samples)')
    return int(requested)


def calibration_designs(
    n_vars: int, n_samples: int | None = None, seed: int | None = None
) -> tuple[Array, int, int]:
    """Sample designs of the eq. 25 calibration (config/simplified_models.yaml scaling).

    Returns
    -------
    (x (N, n_vars), N, seed)
    """
    cfg = load_simplified_config()['scaling']
    n_samples, seed = calibration_settings(n_samples, seed)
    x = sample_design_space(
        n_vars, n_samples, seed, bool(cfg['include_corners']), int(cfg['lhs_candidates'])
    )
    return x, n_samples, seed


def fit_calibration(
    scenario: str,
    n_vars: int,
    x: Array,
    full_f: ArrayLike,
    full_g: ArrayLike,
    inputs: list[SimplifiedInputs] | None,
    key: dict[str, Any],
    road: str = '',
    space: DesignSpace | None = None,
    condition: str = '',
) -> Scaling:
    """Eq. 25 fit from full-model values at the calibration designs.

    The simplified model runs at the same designs; for handling each sample uses the
    inputs captured from its own full run (``inputs[i]``), as at an iterate.  ``key``
    is the calibration's :func:`~suspension_tuning.optim.scaling.scaling_key`, kept
    with the scaling (the caller has it already: it names the cache file).  ``road``:
    the ride road of the full-model samples, which the pitch-plane model drives too.
    ``space``: the design space (default config/design_space.yaml).  ``condition``: the
    operating condition of the samples as text, which the simplified model runs in.
    """
    full = np.column_stack([np.asarray(full_f, dtype=float), np.asarray(full_g, dtype=float)])
    if scenario == 'ride':
        simp = simplified_values('ride', x, n_vars, road=road, space=space,
                                 condition=condition)
    else:
        if inputs is None or len(inputs) != len(x):
            raise ValueError(f'the {scenario} calibration needs the full model inputs per '
                             'sample')
        simp = np.vstack(
            [simplified_values(scenario, x[i], n_vars, inputs[i], road=road, space=space)
             for i in range(len(x))]
        )
    return fit_scaling(x, full, simp, key=key)


def calibrate(
    scenario: str,
    n_vars: int,
    n_samples: int | None = None,
    seed: int | None = None,
    run_full=None,
    model_fingerprint: str | None = None,
    space: DesignSpace | None = None,
    condition: str = '',
) -> Scaling:
    """Fit the eq. 25 scaling from N full-model samples over the design space.

    Parameters
    ----------
    scenario : {'ride', 'handling'}
        Scenario.
    n_vars : int
        2 or 4.
    n_samples, seed : int, optional
        Number of samples and LHS seed (default config/simplified_models.yaml scaling).
    run_full : callable, optional
        ``run_full(scenario, x (N, n)) -> ScenarioResult`` (default
        ``scenarios.run_scenario``); all N designs go in one batch.
    model_fingerprint : str, optional
        Fingerprint of the model ``run_full`` runs, for the key (default the built-in
        model's, :func:`suspension_tuning.model_identity.builtin_fingerprint`).
    space : DesignSpace, optional
        The design space of the simplified models (default config/design_space.yaml;
        ``run_full`` must use the same).
    condition : str, optional
        An operating condition as text
        (:meth:`suspension_tuning.conditions.Condition.as_text`); the default
        ``run_full`` runs in it, the simplified model too, and the key holds it.

    Returns
    -------
    Scaling
        With the samples, both models' values and the key.
    """
    x, n_samples, seed = calibration_designs(n_vars, n_samples, seed)
    if run_full is None:
        from suspension_tuning.conditions import (
            Condition,
            condition_params,
            condition_scenarios,
        )
        from suspension_tuning.vehicle.runs import run_full as run_model

        parsed = Condition.from_text(condition) if condition else None

        def run_full(name: str, designs: Array) -> Any:
            return run_model(name, designs, condition_params(parsed), space=space,
                             config=None if parsed is None else condition_scenarios(parsed))
    res = run_full(scenario, x)
    inputs = [SimplifiedInputs.from_scenario_result(res, i) for i in range(n_samples)]
    key = scaling_key(scenario, n_vars, n_samples, seed, model_fingerprint)
    if condition:
        key['condition'] = condition
    return fit_calibration(scenario, n_vars, x, res.f, res.g, inputs, key, space=space,
                           condition=condition)


def load_or_calibrate(
    path: str | Path,
    scenario: str,
    n_vars: int,
    n_samples: int | None = None,
    seed: int | None = None,
) -> tuple[Scaling, bool]:
    """Load the scaling from ``path`` if its key matches, else calibrate and save it.

    Returns
    -------
    (Scaling, bool)
        The scaling and whether it was loaded from the cache.
    """
    n_samples, seed = calibration_settings(n_samples, seed)
    key = scaling_key(scenario, n_vars, n_samples, seed)
    path = Path(path)
    if path.exists():
        try:
            return Scaling.load(path, expected_key=key), True
        except ValueError:
            pass  # stale or unreadable cache: recalibrate below
    sc = calibrate(scenario, n_vars, n_samples, seed)
    sc.save(path)
    return sc, False


class SimplifiedGradient:
    """Central-difference gradient source on the scaled simplified model.

    Parameters
    ----------
    scenario : {'ride', 'handling'}
        Scenario.
    n_vars : int
        2 or 4.
    scaling : Scaling, optional
        Eq. 25 scaling (unscaled simplified gradients without it).
    step : float, optional
        Central-difference half step in normalised units (default
        config/simplified_models.yaml gradient.step, 0.025).
    road : str, optional
        Ride road in place of config/scenarios.yaml's (a road name, a road file or an
        entry as YAML); empty = the configured one.
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).
    condition : str, optional
        An operating condition as text (its speed, payload and road); '' = none.

    Notes
    -----
    ``__call__(x, inputs)`` matches ``tuning.SimplifiedGradient``: it returns
    ``(df (n,), dg (4, n), values (5,))``, the gradients and the scaled values at x
    itself (what the first-order correction of ``optim.correction`` compares with the
    full model), from one batch of 2n + 1 simplified runs, counted in ``n_runs``.
    """

    def __init__(
        self,
        scenario: str,
        n_vars: int,
        scaling: Scaling | None = None,
        step: float | None = None,
        road: str = '',
        space: DesignSpace | None = None,
        condition: str = '',
    ) -> None:
        if scenario not in SIMPLIFIED_SCENARIOS:
            raise ValueError(f'unknown scenario {scenario!r}; valid: '
                             f'{", ".join(map(repr, SIMPLIFIED_SCENARIOS))}')
        validate_design(np.full(n_vars, X_UPPER), n_vars)
        if scaling is not None:
            for k, v in (('scenario', scenario), ('n_vars', n_vars)):
                if k in scaling.key and scaling.key[k] != v:
                    raise ValueError(f'scaling is for {k}={scaling.key[k]!r}, not {v!r}')
        self.scenario = scenario
        self.road = str(road)
        self.condition = str(condition)
        if self.condition and scenario not in ('ride', 'handling'):
            raise ValueError('operating conditions are for the ride and handling scenarios')
        self.n_vars = int(n_vars)
        self.scaling = scaling
        self.space = space
        step = load_simplified_config()['gradient']['step'] if step is None else step
        if not (np.isfinite(step) and 0.0 < step <= 0.25):
            raise ValueError(f'step must lie in (0, 0.25], got {step}')
        self.step = float(step)
        self.lower = np.full(self.n_vars, X_LOWER)
        self.upper = np.full(self.n_vars, X_UPPER)
        self.n_runs = 0
        self.n_calls = 0

    def values(self, x: ArrayLike, inputs: Any = None) -> Array:
        """Scaled simplified values (batch, 5) at designs x (counted as runs)."""
        xb = validate_design(x, self.n_vars)
        self.n_runs += xb.shape[0]
        return simplified_values(self.scenario, xb, self.n_vars, inputs, self.scaling,
                                 self.road, self.space, self.condition)

    def __call__(self, x: ArrayLike, inputs: Any = None) -> tuple[Array, Array, Array]:
        """Gradient of f (n,), Jacobian of g (4, n) and the values (5,) at x.

        One batch of 2n + 1 runs: the central-difference stencil and x itself.
        """
        x1 = validate_design(x, self.n_vars)
        if x1.shape[0] != 1:
            raise ValueError(f'gradient needs one design, got {x1.shape[0]}')
        inp = as_simplified_inputs(self.scenario, inputs)
        centre: list[Array] = []

        def stencil_and_centre(points: Array) -> Array:
            values = self.values(np.vstack([points, x1]), inp)
            centre.append(values[-1])
            return values[:-1]

        jac = central_difference(stencil_and_centre, x1[0], self.step, self.lower,
                                 self.upper)
        self.n_calls += 1
        return jac[0], jac[1:], centre[0]
