"""The optimisers an engineer would try instead of the paper's method, on a budget.

Each adapter minimises f(x) subject to g(x) <= 0 within box bounds, from a given start,
spending at most ``budget`` evaluations of the (expensive) problem, and keeps every
design it evaluated in order (:class:`CountedProblem`).  Nothing here knows the
vehicle: :func:`suspension_tuning.studies.common.run_peer` runs the adapters on the
full model, and test/test_peers.py on an analytic problem with a known optimum.

* ``cobyla`` - SciPy's COBYLA (Powell's linear-approximation trust region, the PRIMA
  implementation), constraints -g >= 0 and the bounds;
* ``cobyqa`` - SciPy's COBYQA (Ragonneau and Zhang's quadratic-model trust region), g
  as a nonlinear constraint ``g <= 0`` and the bounds;
* ``nomad`` - NOMAD 4's Mesh Adaptive Direct Search (PyNomadBBO), the constraints as
  progressive-barrier outputs (``PB``), built for noisy constrained black boxes;
* ``optuna_tpe`` - Optuna's TPE sampler with the constraints of each trial
  (``Trial.set_constraint``: constrained Bayesian optimisation by tree-structured Parzen
  estimators), the start enqueued as its first trial.

Optuna's GP sampler is left out: it needs PyTorch, whose PyPI wheels for Linux pull
in the CUDA libraries (gigabytes) for a study that runs on CPUs; TPE is Optuna's
default and its constrained sampler.

A start is the same x0 as Dynamic-Q's.  Every distinct design evaluated is one run
(the objective and the constraints at one x come from one run); an optimiser that asks
for a design again gets the cached value at no cost.  The adapters need the study's
extra packages (requirements-study.txt, :func:`install_study_extra`).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: The peers, in the order of the tables.
PEERS = ('cobyla', 'cobyqa', 'nomad', 'optuna_tpe')
PEER_LABELS = {
    'cobyla': 'COBYLA (SciPy)',
    'cobyqa': 'COBYQA (SciPy)',
    'nomad': 'NOMAD 4 MADS (PyNomadBBO)',
    'optuna_tpe': 'Optuna TPE with constraints',
}
#: Full runs each peer may spend on one start.
PEER_BUDGET = 300
#: Initial trust-region radius of COBYLA and COBYQA, normalised units: Dynamic-Q's
#: initial move limit (config/optimiser.yaml ``vehicle`` rho0 = 0.3, a third of the box),
#: so that every method takes its first steps on the same scale.
INITIAL_RADIUS = 0.3
#: Seed of Optuna's TPE sampler (the runs are reproducible).
OPTUNA_SEED = 0
#: The study's extra requirements (not needed by the product).
STUDY_REQUIREMENTS = Path(__file__).resolve().parents[2] / 'requirements-study.txt'
#: Import name of each extra package.
EXTRA_MODULES = {'optuna': 'optuna', 'nomad': 'PyNomad'}


class StopRunError(Exception):
    """Raised when an optimiser asks for a run after its run was ended."""


class BudgetExhaustedError(StopRunError):
    """Raised when an optimiser asks for one more run than the budget allows."""


@dataclass
class CountedProblem:
    """f and g of designs: every distinct design is one run, cached, within a budget.

    Parameters
    ----------
    fun : callable
        x (n,) -> (f, g (m,)), g <= 0 feasible.
    lower, upper : array_like
        Box bounds; a design outside them is clipped onto them before it is run.
    budget : int
        Runs allowed; one more raises :class:`BudgetExhaustedError`.
    stop_when : callable, optional
        Called with each new evaluation record; True ends the run there (every later
        request raises :class:`StopRunError`), e.g. once the run's answer is good enough.

    Attributes
    ----------
    evaluations : list of dict
        Every run in order: ``n_full_runs`` (counting it), ``f``, ``max_violation``
        (max(0, max g)), ``x``, ``g``.
    """

    fun: Callable[[Array], tuple[float, Array]]
    lower: ArrayLike
    upper: ArrayLike
    budget: int = PEER_BUDGET
    stop_when: Callable[[dict[str, Any]], bool] | None = None
    evaluations: list[dict[str, Any]] = field(default_factory=list)
    stopped: str = ''
    _cache: dict[bytes, tuple[float, Array]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        """Bounds as arrays."""
        self.lower = np.asarray(self.lower, float)
        self.upper = np.asarray(self.upper, float)

    @property
    def n_runs(self) -> int:
        """Runs so far."""
        return len(self.evaluations)

    def __call__(self, x: ArrayLike) -> tuple[float, Array]:
        """f and g at x (one run unless x was run before)."""
        x = np.clip(np.asarray(x, float).ravel(), self.lower, self.upper)
        key = x.tobytes()
        if key not in self._cache:
            if self.stopped:
                raise StopRunError(self.stopped)
            if self.n_runs >= self.budget:
                raise BudgetExhaustedError(f'budget of {self.budget} runs spent')
            f, g = self.fun(x)
            g = np.atleast_1d(np.asarray(g, float)).copy()
            self._cache[key] = (float(f), g)
            self.evaluations.append({
                'n_full_runs': self.n_runs + 1, 'f': float(f),
                'max_violation': float(max(0.0, np.max(g))) if g.size else 0.0,
                'x': x.tolist(), 'g': g.tolist()})
            if self.stop_when is not None and self.stop_when(self.evaluations[-1]):
                self.stopped = f'stopped after {self.n_runs} runs: stop condition met'
        return self._cache[key]

    def f(self, x: ArrayLike) -> float:
        """f only."""
        return self(x)[0]

    def g(self, x: ArrayLike) -> Array:
        """g only."""
        return self(x)[1]


@dataclass
class PeerResult:
    """One peer's run from one start.

    Attributes
    ----------
    method : str
        One of :data:`PEERS`.
    evaluations : list of dict
        The problem's :attr:`CountedProblem.evaluations`.
    message : str
        Why it stopped (its own message, or the budget).
    wall_time_s : float
        Wall time of the run.
    """

    method: str
    evaluations: list[dict[str, Any]]
    message: str
    wall_time_s: float

    def best_feasible(self, gtol: float = 0.0) -> dict[str, Any] | None:
        """The evaluated design with the lowest f among those with max g <= gtol."""
        feasible = [e for e in self.evaluations if e['max_violation'] <= gtol]
        return min(feasible, key=lambda e: e['f']) if feasible else None


# ---------------------------------------------------------------------- the adapters
def _scipy(method: str, problem: CountedProblem, x0: Array) -> str:
    from scipy.optimize import Bounds, NonlinearConstraint, minimize

    bounds = Bounds(problem.lower, problem.upper)
    if method == 'COBYLA':
        res = minimize(problem.f, x0, method='COBYLA', bounds=bounds,
                       constraints=[{'type': 'ineq', 'fun': lambda x: -problem.g(x)}],
                       options={'rhobeg': INITIAL_RADIUS, 'maxiter': problem.budget})
    else:
        res = minimize(problem.f, x0, method='COBYQA', bounds=bounds,
                       constraints=[NonlinearConstraint(problem.g, -np.inf, 0.0)],
                       options={'initial_tr_radius': INITIAL_RADIUS,
                                'maxfev': problem.budget})
    return str(res.message)


def _nomad(problem: CountedProblem, x0: Array) -> str:
    import PyNomad

    n_constraints = len(problem(x0)[1])  # the start: NOMAD's own first evaluation hits it

    def blackbox(point: Any) -> int:
        x = [point.get_coord(i) for i in range(point.size())]
        try:
            f, g = problem(x)
        except StopRunError:
            return 0  # a failed evaluation, not run: NOMAD goes on to its MAX_BB_EVAL
        if not np.isfinite(f):
            return 0  # a run that failed (counted): a failed evaluation for NOMAD
        point.setBBO(' '.join(repr(float(v)) for v in (f, *g)).encode('utf-8'))
        return 1

    params = [f'BB_OUTPUT_TYPE OBJ{" PB" * n_constraints}',
              f'MAX_BB_EVAL {problem.budget}', 'DISPLAY_DEGREE 0',
              'NB_THREADS_PARALLEL_EVAL 1']
    result = PyNomad.optimize(blackbox, list(map(float, x0)), problem.lower.tolist(),
                              problem.upper.tolist(), params)
    stop = result.get('stop_reason', '') if isinstance(result, dict) else ''
    return f'NOMAD: {stop}'.strip() if stop else 'NOMAD stopped'


def _optuna_tpe(problem: CountedProblem, x0: Array, seed: int = OPTUNA_SEED) -> str:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(seed=seed)  # constraints: Trial.set_constraint
    study = optuna.create_study(direction='minimize', sampler=sampler)
    names = [f'x{i}' for i in range(len(x0))]
    study.enqueue_trial(dict(zip(names, map(float, x0))))
    trials = 0
    # A trial that asks for a design run before costs nothing: allow a few of them.
    while (problem.n_runs < problem.budget and not problem.stopped
           and trials < 4 * problem.budget):
        trial = study.ask()
        x = [trial.suggest_float(name, lo, hi)
             for name, lo, hi in zip(names, problem.lower, problem.upper)]
        f, g = problem(x)
        trials += 1
        if not np.isfinite(f):  # a run that failed (counted): a failed trial for TPE
            study.tell(trial, state=optuna.trial.TrialState.FAIL)
            continue
        for k, value in enumerate(g):
            trial.set_constraint(f'g{k}', float(value))
        study.tell(trial, f)
    return f'{trials} trials'


def run_adapter(method: str, problem: CountedProblem, x0: ArrayLike) -> PeerResult:
    """Run one peer on ``problem`` from ``x0`` until it stops or the budget is spent.

    Raises
    ------
    ValueError
        Unknown method.
    ModuleNotFoundError
        The peer's package is not installed (the message says how to install it).
    """
    if method not in PEERS:
        raise ValueError(f'unknown peer {method!r}; valid: {", ".join(PEERS)}')
    module = EXTRA_MODULES.get(method.split('_')[0])
    if module is not None and importlib.util.find_spec(module) is None:
        raise ModuleNotFoundError(
            f'{method} needs the study extra: .venv/bin/python -m pip install -r '
            f'{STUDY_REQUIREMENTS.name} (make study installs it)')
    x0 = np.clip(np.asarray(x0, float).ravel(), problem.lower, problem.upper)
    t0 = time.perf_counter()
    try:
        if method == 'cobyla':
            message = _scipy('COBYLA', problem, x0)
        elif method == 'cobyqa':
            message = _scipy('COBYQA', problem, x0)
        elif method == 'nomad':
            message = _nomad(problem, x0)
        else:
            message = _optuna_tpe(problem, x0)
    except StopRunError as stop:
        message = str(stop)
    if problem.stopped:
        message = problem.stopped
    return PeerResult(method, list(problem.evaluations), message, time.perf_counter() - t0)


def minimise(method: str, fun: Callable[[Array], tuple[float, Array]], x0: ArrayLike,
             lower: Sequence[float], upper: Sequence[float],
             budget: int = PEER_BUDGET) -> PeerResult:
    """One peer on f, g (x -> (f, g), g <= 0 feasible) from ``x0`` within the bounds and
    ``budget`` evaluations.
    """  # noqa: D205
    return run_adapter(method, CountedProblem(fun, lower, upper, budget), x0)


# ---------------------------------------------------------------------- the extra
def missing_study_packages() -> list[str]:
    """Import names of the study's extra packages that are not installed."""
    return [m for m in EXTRA_MODULES.values() if importlib.util.find_spec(m) is None]


def install_study_extra(log: Callable[[str], None] = print) -> None:
    """Install requirements-study.txt into this interpreter when a package is missing.

    Raises
    ------
    RuntimeError
        pip failed (its output is in the message).
    """
    missing = missing_study_packages()
    if not missing:
        return
    log(f'installing the study extra ({", ".join(missing)} missing): '
        f'pip install -r {STUDY_REQUIREMENTS.name}')
    out = subprocess.run([sys.executable, '-m', 'pip', 'install', '-q', '-r',
                          str(STUDY_REQUIREMENTS)], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f'pip install -r {STUDY_REQUIREMENTS} failed:\n{out.stderr}')
    importlib.invalidate_caches()

