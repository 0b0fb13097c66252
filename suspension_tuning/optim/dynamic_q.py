"""Dynamic-Q: successive spherical quadratic approximations solved by LFOPC.

Snyman and Hay (2002) define Dynamic-Q as "applying a Dynamic trajectory
optimisation algorithm to successive spherical Quadratic approximations of
the actual optimisation problem".  The problem (seed paper eqs. 1-3) is::

    minimise f(x)  subject to  g_j(x) <= 0,  h_k(x) = 0,  lower <= x <= upper.

At the iterate x^i the subproblem P[i] (physics-reference 1.2) is::

    min  f~(x) = f^i + grad f^i . (x - x^i) + a/2 ||x - x^i||^2
    s.t. g~_j(x) = g_j^i + grad g_j^i . (x - x^i) + b_j/2 ||x - x^i||^2 <= 0
         h~_k(x) = h_k^i + grad h_k^i . (x - x^i) + c_k/2 ||x - x^i||^2 = 0
         ||x - x^i||^2 - rho^2 <= 0                      (move limit)
         lower <= x <= upper                             (linear, exact)

with the curvatures from the previous point x^{i-1} (Snyman and Hay)::

    a = 2 [f(x^{i-1}) - f^i - grad f^i . (x^{i-1} - x^i)] / ||x^{i-1} - x^i||^2

(b_j, c_k alike) and a = b_j = c_k = 0 at the first iteration [R].  The
subproblem's solution is the next iterate: no line search, so one
evaluation of (f, g, h) and one gradient evaluation per iteration.  When an
iteration is worse (feasible iterates: f increased; otherwise: the largest
violation did not decrease) the move limit is multiplied by
``rho_reduction`` (1/2) and, by default, the step is still accepted as in
the book; option ``worse_step='reject'`` re-solves from the same iterate with
the smaller move limit instead.  An iteration that returns to an earlier iterate
(within ``xtol / 100``) also halves the move limit [E]: with gradients that are a function of x
(the simplified models without the secant correction) the loop would otherwise
repeat the same cycle of iterates to the iteration limit.

Changed from the recalled rule (physics-reference 1.3 [R] only reduces the
move limit): after a step that was not worse and reached the move limit,
the move limit is doubled (``rho_growth`` = 2, no upper limit by default).
Reason, from the analytic tests (SciPy-style defaults, analytic gradients):
with reduction only, Rosenbrock from (-1.2, 1) inside [-2, 2]^2 stalled at
f = 0.116 after 100 iterations with rho = 0.0023 (each worse step in the
curved valley halves rho for good), and HS6 needed 50 iterations; with
growth they need 59 and 11.  A constrained quadratic with its minimum 2.2
from the start and rho0 = 0.3 needed 10 iterations with growth capped at
rho0 and 5 without the cap.  ``worse_step='reject'`` was tried as the
default and failed HS6 and the interior Rosenbrock within 100 iterations,
so 'accept' (the book's rule) stays the default.

Pieces that are our own choices [E] (physics-reference 1.3 and 1.6 mark the
published rules as recalled [R]; the analytic tests decide):

* Each subproblem is solved in the scaled variable d = (x - x^i) / rho, so
  the move limit is the unit ball, and the objective and each constraint
  are divided by their change across the ball (rho ||grad|| + |curv| rho^2 / 2,
  or 1 when that is zero).  Dividing a constraint by a positive number keeps
  its feasible set and the subproblem's minimiser unchanged; it makes the
  subproblem O(1), as LFOPC's fixed penalty parameters (1e2, 1e4) and its
  step limit delta = 1 require (Snyman 2000 asks for O(1) constraints).
* Curvatures are clipped to [-curvature_cap, curvature_cap] (noise guard,
  physics-reference 1.2 [E]).
* With ``worse_step='reject'`` the rejected trial point gives fresh
  curvatures along the rejected step (same interpolation formula, with the
  trial point in place of x^{i-1}), so the re-solved subproblem is not the
  old one in a smaller ball only.
* Constraint curvatures from another model's slopes
  (``surrogate_constraint_curvature``).  The interpolation formula gives
  b_j = 2 [g_j(x^{i-1}) - g_j^i - grad g_j^i . dx] / ||dx||^2.  When g
  comes from the full model and grad g from a simplified one, the bracket
  holds the slope error times the step, so |b_j| grows as 1/||dx||: on the
  4-variable ride |b| ||dx|| stayed near 2.4 (log correlation -0.97), b
  changed sign in 14 of 28 iterations and reached the 1e3 cap, and the run
  zig-zagged along the tyre-hop boundary.  With 'zero' the constraints are
  linearised (b_j = c_k = 0) at iterates with such gradients; the objective
  keeps its interpolated curvature a.
* A run stops only after ``converge_iterations`` consecutive iterations pass
  the xtol or ftol test, each at a feasible point or within xtol of the best
  feasible point (on a staircase constraint the iterates can alternate between
  a feasible point and an infeasible one a stair away): on a noisy model one short step
  (the subproblem's solution close to x^i) or one small change of f proves
  nothing, and a single-step rule ended one ride run 64 % above its optimum.
* The iterate is clipped into the bounds after each subproblem (LFOPC's
  phase 2 ends on the active bounds only to within its gradient tolerance),
  and is checked to lie inside the bounds before every evaluation.

Interfaces: :class:`DynamicQ` is an ask/tell driver (the ROS coordinator
asks for an evaluation or a gradient, performs it however it likes, tells
the result and can stop between iterations); :func:`dynamic_q` runs it with
two callables; :func:`minimize` is the drop-in for ``scipy.optimize.minimize``
(counts as SciPy reports them: ``nfev`` every call of ``fun``, finite differences
included, ``njev`` the gradient evaluations; an ``x0`` outside the bounds is
clipped into them, as SLSQP and L-BFGS-B do).

References
----------
Snyman, J.A. & Hay, A.M. (2002), "The Dynamic-Q optimisation method: an
alternative to SQP?", Computers & Mathematics with Applications 44, 1589-1598.
Snyman, J.A. (2000), "The LFOPC leap-frog algorithm for constrained
optimisation", Computers & Mathematics with Applications 40, 1085-1096.
Thoresson, Uys, Els & Snyman (2009), Part 1, section 2 and eqs. 1-3.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Generator, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import Bounds, OptimizeResult

from suspension_tuning.optim._options import options_from_mapping
from suspension_tuning.optim.finite_diff import central_difference
from suspension_tuning.optim.lfopc import LfopOptions, lfopc

Array = NDArray[np.float64]

STATUS_MESSAGES = {
    0: 'converged: step shorter than xtol',
    1: 'converged: function change below ftol',
    2: 'stopped: move limit below rho_min',
    3: 'stopped: maximum number of iterations reached',
    4: 'stopped: move limit below rho_min at an infeasible point',
    5: 'converged: steps change f and g by no more than their noise',
    6: 'converged: a corner of the box where the gradient points out of it, no constraint '
       'active (first-order optimal)',
    99: 'stopped by the callback or the caller',
}
"""Status codes of the result (``status`` field) and their messages."""
#: The test that ended a run, by status (the result's ``stop_test``).
STOP_TESTS = {0: 'xtol', 1: 'ftol', 2: 'rho_min', 3: 'maxiter', 4: 'rho_min', 5: 'noise',
              6: 'bound_kkt', 99: 'cancelled'}
#: Status codes of a converged run (xtol, ftol, rho_min at a feasible point, noise,
#: bound-KKT): ``success`` when the point is feasible too.
CONVERGED_STATUSES = (0, 1, 2, 5, 6)

#: Values of ``DynamicQOptions.surrogate_constraint_curvature``.
SURROGATE_CURVATURES = ('interpolate', 'zero')
#: Values of ``DynamicQOptions.surrogate_objective_curvature``.
SURROGATE_OBJECTIVE_CURVATURES = ('interpolate', 'nonnegative', 'zero')
#: Gradient sources that come from another model than the values (a surrogate).
SURROGATE_SOURCES = ('simplified',)


@dataclass(frozen=True)
class DynamicQOptions:
    """Options of Dynamic-Q (config/optimiser.yaml holds them with sources).

    Attributes
    ----------
    rho0 : float
        Initial move limit (step limit), in the units of x [E: 0.3 for
        variables normalised to [0.001, 1], physics-reference 1.3].
    rho_reduction : float
        Factor applied to the move limit after a worse step [E: 1/2].
    rho_min : float
        Stop when the move limit falls below this; 0 disables the rule
        [E: 0 for analytic problems, 1e-3 for the noisy vehicle problems].
    rho_growth : float
        Factor applied to the move limit after a step that was not worse and
        reached the move limit; 1 disables growth [E: 2, see module notes].
    rho_max : float or None
        Upper limit of the move limit; None means no limit [E].
    worse_step : str
        'accept' (book: step kept, move limit reduced) or 'reject' (step
        discarded and P[i] re-solved with the reduced move limit).
    xtol : float
        Converged when ||x^{i+1} - x^i|| < xtol at a feasible point
        [E: 1e-5 for analytic tests, physics-reference 1.6].
    ftol : float
        Converged when |f^{i+1} - f^i| < ftol (1 + |f^i|) at a feasible point
        [E: 1e-8].
    gtol : float
        Feasibility tolerance on g_j and |h_k| [E: 1e-6].
    maxiter : int
        Maximum number of iterations (subproblems solved) [E: 100].
    maxiter_variables : int
        ``maxiter`` holds up to this many variables; with more, n, the iteration limit
        grows in proportion, ceil(maxiter n / maxiter_variables), so that a larger design
        keeps the iterations per variable.  0 keeps ``maxiter`` for every n [E: 0 for
        analytic problems; 4 for the vehicle, whose 30 iterations are the paper's budget
        for its 4 variables].
    curvature_cap : float
        Curvatures are clipped to [-cap, cap]; inf disables [E: inf for
        analytic problems, 1e3 for noisy ones, physics-reference 1.2].
    surrogate_constraint_curvature : str
        Curvatures b_j and c_k of the constraints at an iterate whose
        gradients came from another model than the one that gave the values
        (source 'simplified'): 'interpolate' (Snyman and Hay's formula, as for
        every other source) or 'zero' (linear constraint approximations).
        The interpolation mixes the full model's values with the other
        model's slopes: where those slopes are off, b_j absorbs the mismatch
        divided by the step length squared, so it grows as 1/step and changes
        sign from one iteration to the next (module notes) [E].
    curvature_min_step : float
        After a step shorter than this (units of x) the curvatures are not
        interpolated anew: the previous iteration's are kept.  Over a step much
        shorter than the gradients' finite-difference step, the interpolation
        divides the gradient's error by the step length [E: 0 (off) for analytic
        problems].
    converge_iterations : int
        Number of consecutive iterations, each at a feasible point or within
        xtol of the best feasible point, that must pass the xtol or ftol test
        before the run stops; 1 stops on the first
        [E: 1 for analytic problems; 2 for noisy ones, where one short step
        or one lucky function change proves nothing].
    noise_f, noise_g : float
        Noise levels of the objective and of the inequality constraints (standard
        deviation of a value from one design to a neighbouring one, in their units;
        More and Wild's ECnoise).  With ``noise_f`` > 0 a step also passes the
        convergence test (the noise test, status 5) when it changes f by at most
        ``2 noise_f`` and, with ``noise_g`` > 0, every g_j by at most ``2 noise_g``:
        its changes are then indistinguishable from the model's noise, which the
        ftol test cannot know.  0 disables [E: 0 for noise-free functions].
    bound_kkt : bool
        Also stop (status 6, the bound-KKT test) at a feasible iterate where every
        variable lies on a bound (within ``xtol``) with its derivative pointing out of
        the box (by more
        than ``ftol (1 + |f|)`` over the variable's range) and every inequality
        constraint is inactive (g_j < -max(10 gtol, 2 noise_g); no equality
        constraints): the Karush-Kuhn-Tucker conditions hold there with the bounds'
        multipliers alone (Snyman 2005, ch. 5; Nocedal and Wright 2006, thm. 12.1), and
        the steps the xtol test waits for would stay at that corner.  The gradient is
        the one the run uses (a simplified model's, corrected) [E: off for analytic
        problems; on for the vehicle, where handling optima sit at a corner].
    lfopc : dict
        Options of the LFOPC subproblem solver (see
        :class:`~suspension_tuning.optim.lfopc.LfopOptions`).
    """

    rho0: float = 0.3
    rho_reduction: float = 0.5
    rho_min: float = 0.0
    rho_growth: float = 2.0
    rho_max: float | None = None
    worse_step: str = 'accept'
    xtol: float = 1e-5
    ftol: float = 1e-8
    gtol: float = 1e-6
    maxiter: int = 100
    maxiter_variables: int = 0
    curvature_cap: float = math.inf
    surrogate_constraint_curvature: str = 'interpolate'
    surrogate_objective_curvature: str = 'interpolate'
    converge_iterations: int = 1
    curvature_min_step: float = 0.0
    noise_f: float = 0.0
    noise_g: float = 0.0
    bound_kkt: bool = False
    lfopc: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        """Check every option and its range."""
        positive = ('rho0', 'xtol', 'ftol', 'gtol')
        for name in positive:
            value = getattr(self, name)
            if not isinstance(value, int | float) or not np.isfinite(value) or value <= 0:
                raise ValueError(f'Dynamic-Q option {name} must be finite and > 0, got {value!r}')
        if not 0.0 < self.rho_reduction < 1.0:
            raise ValueError(f'rho_reduction must lie in (0, 1), got {self.rho_reduction!r}')
        if not np.isfinite(self.rho_growth) or self.rho_growth < 1.0:
            raise ValueError(f'rho_growth must be finite and >= 1, got {self.rho_growth!r}')
        if self.rho_max is not None and not (np.isfinite(self.rho_max) and self.rho_max > 0):
            raise ValueError(f'rho_max must be None or finite and > 0, got {self.rho_max!r}')
        if not np.isfinite(self.rho_min) or self.rho_min < 0:
            raise ValueError(f'rho_min must be finite and >= 0, got {self.rho_min!r}')
        if self.worse_step not in ('accept', 'reject'):
            raise ValueError(f"worse_step must be 'accept' or 'reject', got {self.worse_step!r}")
        if int(self.maxiter) != self.maxiter or self.maxiter < 0:
            raise ValueError(f'maxiter must be an integer >= 0, got {self.maxiter!r}')
        if int(self.maxiter_variables) != self.maxiter_variables or self.maxiter_variables < 0:
            raise ValueError(f'maxiter_variables must be an integer >= 0, got '
                             f'{self.maxiter_variables!r}')
        if np.isnan(self.curvature_cap) or self.curvature_cap <= 0:
            raise ValueError(
                f'curvature_cap must be > 0 (inf allowed), got {self.curvature_cap!r}'
            )
        if not (np.isfinite(self.curvature_min_step) and self.curvature_min_step >= 0):
            raise ValueError(f'curvature_min_step must be finite and >= 0, got '
                             f'{self.curvature_min_step!r}')
        if self.surrogate_objective_curvature not in SURROGATE_OBJECTIVE_CURVATURES:
            raise ValueError(f'surrogate_objective_curvature must be one of '
                             f'{", ".join(SURROGATE_OBJECTIVE_CURVATURES)}, got '
                             f'{self.surrogate_objective_curvature!r}')
        if self.surrogate_constraint_curvature not in SURROGATE_CURVATURES:
            raise ValueError(f'surrogate_constraint_curvature must be one of '
                             f'{", ".join(SURROGATE_CURVATURES)}, got '
                             f'{self.surrogate_constraint_curvature!r}')
        if int(self.converge_iterations) != self.converge_iterations or \
                self.converge_iterations < 1:
            raise ValueError(f'converge_iterations must be an integer >= 1, got '
                             f'{self.converge_iterations!r}')
        for name in ('noise_f', 'noise_g'):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not np.isfinite(value) or value < 0:
                raise ValueError(f'{name} must be finite and >= 0, got {value!r}')
        if not isinstance(self.bound_kkt, bool):
            raise ValueError(f'bound_kkt must be true or false, got {self.bound_kkt!r}')
        LfopOptions.from_mapping(self.lfopc)

    @classmethod
    def from_mapping(cls, options: DynamicQOptions | Mapping[str, Any] | None) -> DynamicQOptions:
        """Build options from a mapping; unknown keys raise ValueError."""
        return options_from_mapping(cls, options, 'Dynamic-Q', {'curvature_cap': float})

    def as_dict(self) -> dict[str, Any]:
        """Return the options as a plain dict (for records and logs)."""
        out = asdict(self)
        out['lfopc'] = dict(self.lfopc) if self.lfopc else {}
        return out


def load_options(path: str, section: str = 'analytic') -> DynamicQOptions:
    """Read Dynamic-Q options from a YAML file such as config/optimiser.yaml.

    Parameters
    ----------
    path : str
        YAML file with top-level sections of options.
    section : str
        Section name, e.g. 'analytic' or 'vehicle'.

    Returns
    -------
    DynamicQOptions
        The options of that section.
    """
    import yaml

    with open(path, encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    if not isinstance(data, dict) or section not in data:
        raise ValueError(f'no section {section!r} in {path}')
    return DynamicQOptions.from_mapping(data[section])


def _max_violation(g: Array, h: Array) -> float:
    worst = 0.0
    if g.size:
        worst = max(worst, float(np.max(g)))
    if h.size:
        worst = max(worst, float(np.max(np.abs(h))))
    return worst


def _curvature(
    f_ref: Array, f_cur: Array, grad_cur: Array, dx: Array, dx2: float, cap: float
) -> Array:
    """Spherical curvature interpolating the reference point (Snyman and Hay).

    ``f_ref``, ``f_cur``: values (k,) at the reference and current points;
    ``grad_cur``: gradients (k, n) at the current point; ``dx`` = x_ref - x_cur.
    """
    curv = 2.0 * (f_ref - f_cur - grad_cur @ dx) / dx2
    return np.clip(curv, -cap, cap)


@dataclass
class _Point:
    """One evaluated point with its values and (when known) gradients."""

    x: Array
    f: float
    g: Array
    h: Array
    df: Array | None = None
    dg: Array | None = None
    dh: Array | None = None
    source: str | None = None
    iteration: int = 0


def solve_subproblem(
    point: _Point,
    rho: float,
    a: float,
    b: Array,
    c: Array,
    lower: Array,
    upper: Array,
    lfopc_options: Mapping[str, Any] | None = None,
) -> tuple[Array, Any]:
    """Solve the spherical quadratic subproblem P[i] with LFOPC.

    Parameters
    ----------
    point : _Point
        Current iterate with f, g, h and their gradients.
    rho : float
        Move limit (radius of the trust ball), units of x.
    a, b, c : float, ndarray, ndarray
        Curvatures of f, of each g_j and of each h_k.
    lower, upper : ndarray
        Bounds (infinite entries are ignored).
    lfopc_options : mapping, optional
        LFOPC options.

    Returns
    -------
    x_new : ndarray
        Minimiser of P[i], clipped into the bounds.
    sub : LfopcResult
        LFOPC's result in the scaled variable d = (x - x^i) / rho.
    """
    x0 = point.x
    n = x0.size

    def scale(grad: Array, curv: Array) -> Array:
        s = rho * np.linalg.norm(np.atleast_2d(grad), axis=1) + 0.5 * np.abs(curv) * rho**2
        return np.where(s > 0, s, 1.0)

    sf = float(scale(point.df, np.array([a]))[0])
    lin_f = rho * point.df / sf
    quad_f = a * rho**2 / sf

    # Inequalities: c0 + G d + 0.5 q ||d||^2 <= 0, rows: g_j, move limit, bounds.
    c0_parts, G_parts, q_parts = [], [], []
    if point.g.size:
        sg = scale(point.dg, b)
        c0_parts.append(point.g / sg)
        G_parts.append(rho * point.dg / sg[:, None])
        q_parts.append(b * rho**2 / sg)
    c0_parts.append(np.array([-1.0]))
    G_parts.append(np.zeros((1, n)))
    q_parts.append(np.array([2.0]))
    eye = np.eye(n)
    lo_idx = np.flatnonzero(np.isfinite(lower))
    hi_idx = np.flatnonzero(np.isfinite(upper))
    if lo_idx.size:
        c0_parts.append((lower[lo_idx] - x0[lo_idx]) / rho)
        G_parts.append(-eye[lo_idx])
        q_parts.append(np.zeros(lo_idx.size))
    if hi_idx.size:
        c0_parts.append((x0[hi_idx] - upper[hi_idx]) / rho)
        G_parts.append(eye[hi_idx])
        q_parts.append(np.zeros(hi_idx.size))
    gc0 = np.concatenate(c0_parts)
    gG = np.vstack(G_parts)
    gq = np.concatenate(q_parts)

    def f_sub(d: Array) -> float:
        return float(lin_f @ d + 0.5 * quad_f * (d @ d))

    def grad_f_sub(d: Array) -> Array:
        return lin_f + quad_f * d

    def g_sub(d: Array) -> Array:
        return gc0 + gG @ d + 0.5 * gq * (d @ d)

    def jac_g_sub(d: Array) -> Array:
        return gG + gq[:, None] * d[None, :]

    h_sub = jac_h_sub = None
    if point.h.size:
        sh = scale(point.dh, c)
        hc0 = point.h / sh
        hG = rho * point.dh / sh[:, None]
        hq = c * rho**2 / sh

        def h_sub(d: Array) -> Array:
            return hc0 + hG @ d + 0.5 * hq * (d @ d)

        def jac_h_sub(d: Array) -> Array:
            return hG + hq[:, None] * d[None, :]

    sub = lfopc(f_sub, grad_f_sub, np.zeros(n), g_sub, jac_g_sub, h_sub, jac_h_sub, lfopc_options)
    x_new = np.clip(x0 + rho * sub.x, lower, upper)
    return x_new, sub


def _as_vector(value: Any, name: str) -> Array:
    if value is None:
        return np.zeros(0)
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f'{name} must be a 1-D vector, got shape {arr.shape}')
    return arr


def _validate_problem(
    x0: ArrayLike, lower: ArrayLike | None, upper: ArrayLike | None, clip: bool = False
) -> tuple[Array, Array, Array]:
    """Check x0 and the bounds; return x0 (clipped into the bounds if ``clip``), lo, hi.

    Raises
    ------
    ValueError
        For a non-finite x0, malformed, NaN or inverted bounds, and (unless ``clip``)
        an x0 outside the bounds.
    """
    x = np.array(x0, dtype=float)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f'x0 must be a non-empty 1-D vector, got shape {x.shape}')
    if not np.all(np.isfinite(x)):
        raise ValueError(f'x0 must be finite, got {x}')
    n = x.size
    lo = np.full(n, -np.inf) if lower is None else np.array(lower, dtype=float)
    hi = np.full(n, np.inf) if upper is None else np.array(upper, dtype=float)
    if lo.shape == ():
        lo = np.full(n, float(lo))
    if hi.shape == ():
        hi = np.full(n, float(hi))
    if lo.shape != (n,) or hi.shape != (n,):
        raise ValueError(
            f'bounds must have the length of x0 ({n}), got lower {lo.shape}, upper {hi.shape}'
        )
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
        raise ValueError('bounds must not contain NaN')
    if np.any(lo > hi):
        bad = np.flatnonzero(lo > hi)
        raise ValueError(f'bounds inverted (lower > upper) for variable(s) {bad.tolist()}')
    if clip:
        return np.clip(x, lo, hi), lo, hi
    if np.any(x < lo) or np.any(x > hi):
        bad = np.flatnonzero((x < lo) | (x > hi))
        raise ValueError(f'x0 lies outside the bounds in variable(s) {bad.tolist()}: x0 = {x}')
    return x, lo, hi


class DynamicQ:
    """Ask/tell driver of Dynamic-Q (paper convention: g <= 0 feasible).

    Usage::

        opt = DynamicQ(x0, lower, upper, options)
        while (request := opt.ask()) is not None:
            kind, x = request
            if kind == 'evaluate':
                record = opt.tell(evaluate(x))           # (f, g, h)
            else:
                record = opt.tell(gradient(x), source='simplified')  # (df, dg, dh)
            # record is the new iteration's record (or None); stop any time with
            # opt.stop('cancelled').
        result = opt.result()

    Parameters
    ----------
    x0 : array_like, shape (n,)
        Starting point, inside the bounds (may violate g and h).
    lower, upper : array_like, shape (n,), optional
        Bounds; infinite entries allowed.  Never evaluated outside.
    options : DynamicQOptions or mapping, optional
        Algorithm options.
    history : sequence of mappings, optional
        Records of an earlier run (``result.history``) to resume from; the
        run continues from the last record as if it had not stopped.
    gradient_source : str
        Name counted for gradients told without an explicit ``source``.
    counters : callable, optional
        ``counters() -> mapping`` of further counts (or counts that replace the
        driver's own, such as ``nfev``) stored in every record and in the result;
        :func:`minimize` reports the calls of the user's functions this way.
    surrogate_rule_constraints : sequence of bool or callable, optional
        Per inequality constraint: whether ``surrogate_constraint_curvature`` applies
        to it (default: to every one); or ``rule(m) -> sequence`` of the m constraints,
        for a caller that learns m from the first evaluation.  The vehicle problems
        apply it to the eq. 11 tyre-hop constraints only: a count of samples is a staircase, whose
        interpolated curvature measures the stairs; a smooth constraint (another
        scenario's objective) keeps its interpolated curvature.
    """

    def __init__(
        self,
        x0: ArrayLike,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        options: DynamicQOptions | Mapping[str, Any] | None = None,
        history: Sequence[Mapping[str, Any]] | None = None,
        gradient_source: str = 'user',
        counters: Callable[[], Mapping[str, Any]] | None = None,
        surrogate_rule_constraints: (Sequence[bool] | Callable[[int], Sequence[bool]]
                                     | None) = None,
    ) -> None:
        self.x0, self.lower, self.upper = _validate_problem(x0, lower, upper)
        self._surrogate_rows = surrogate_rule_constraints
        self._extra_counters = counters
        self.options = DynamicQOptions.from_mapping(options)
        self.default_source = gradient_source
        self.history: list[dict[str, Any]] = []
        self.nfev = 0
        self.ngev_by_source: dict[str, int] = {}
        self.status: int | None = None
        self.message = ''
        self._pending: tuple[str, Array] | None = None
        self._reply: Any = None
        self._reply_source: str | None = None
        self._best: _Point | None = None
        self._least_violating: _Point | None = None
        self._converge_count = 0
        self._noise_passed = False
        self._last_curvature: tuple[float, Array, Array] | None = None
        self._current: _Point | None = None
        self._rho = self.options.rho0
        if history:
            self._load_history(history)
        self._gen = self._run()
        self._advance(None)

    # ----------------------------------------------------------------- public
    def ask(self) -> tuple[str, Array] | None:
        """Return the pending request ('evaluate' or 'gradient', x) or None when done."""
        if self._pending is None:
            return None
        kind, x = self._pending
        return kind, x.copy()

    def _revisited(self, x: Array) -> bool:
        """Whether ``x`` returns to an iterate of the history (not recorded yet).

        With gradients that depend on x alone, an iteration that returns to an earlier
        iterate closes a cycle that would repeat to the iteration limit (the move limit
        halved on the worse step of the cycle and doubled again on the next): the move
        limit is halved instead of kept or grown.  "Returns" means within ``xtol / 100``
        in every variable: the subproblem's solution repeats an earlier one only to the
        solver's accuracy (1e-10 here).
        """
        tol = 0.01 * self.options.xtol
        return any(float(np.max(np.abs(np.asarray(r['x'], float) - x))) <= tol
                   for r in self.history)

    def tell(self, value: Any, source: str | None = None) -> dict[str, Any] | None:
        """Give the answer to the pending request.

        Parameters
        ----------
        value : tuple
            For 'evaluate': ``(f, g, h)`` (g, h may be None or empty).  For
            'gradient': ``(df, dg, dh)`` with shapes (n,), (m, n), (p, n).
        source : str, optional
            Gradient source name to count ('simplified', 'full', ...).

        Returns
        -------
        dict or None
            The record of the iteration this answer completed, else None.
        """
        if self._pending is None:
            raise RuntimeError('tell() called with no pending request (the run has finished)')
        before = len(self.history)
        self._reply_source = source
        self._advance(value)
        return self.history[-1] if len(self.history) > before else None

    def stop(self, message: str = 'stopped by the caller') -> None:
        """End the run between requests (e.g. on cancellation)."""
        if self.status is None:
            self.status = 99
            self.message = message
        self._pending = None
        self._gen.close()

    @property
    def done(self) -> bool:
        """True when no request is pending."""
        return self._pending is None

    @property
    def max_iterations(self) -> int:
        """The iteration limit: ``maxiter``, grown in proportion above ``maxiter_variables``."""
        opt = self.options
        n, n_ref = self.x0.size, int(opt.maxiter_variables)
        if n_ref <= 0 or n <= n_ref:
            return int(opt.maxiter)
        return math.ceil(int(opt.maxiter) * n / n_ref)

    @property
    def rho(self) -> float:
        """Current move limit."""
        return self._rho

    def result(self) -> OptimizeResult:
        """Return the result so far as a ``scipy.optimize.OptimizeResult``."""
        cur = self._current
        res = OptimizeResult()
        if cur is None:
            res.update(x=self.x0.copy(), success=False, status=self.status, message=self.message,
                       stop_test=STOP_TESTS.get(self.status, '') if self.status is not None
                       else '')
            res.update(self._counters(), history=list(self.history))
            return res
        viol = _max_violation(cur.g, cur.h)
        feasible = viol <= self.options.gtol
        status = self.status
        res.update(
            x=cur.x.copy(),
            fun=cur.f,
            f=cur.f,
            g=cur.g.copy(),
            h=cur.h.copy(),
            jac=None if cur.df is None else cur.df.copy(),
            max_violation=viol,
            maxcv=viol,
            success=bool(status in CONVERGED_STATUSES and feasible),
            status=status,
            stop_test=STOP_TESTS.get(status, '') if status is not None else '',
            message=self.message
            + ('' if feasible or status is None else ' (last iterate infeasible)'),
            nit=self._iteration(),
            iterations=self._iteration(),
            rho=self._rho,
            history=list(self.history),
        )
        res.update(self._counters())
        best = self._best if self._best is not None else self._least_violating
        if best is not None:
            res.update(x_best=best.x.copy(), f_best=best.f, g_best=best.g.copy(),
                       h_best=best.h.copy(), best_iteration=best.iteration,
                       best_feasible=self._best is not None,
                       max_violation_best=_max_violation(best.g, best.h))
        return res

    # ---------------------------------------------------------------- private
    def _counters(self) -> dict[str, Any]:
        ngev = int(sum(self.ngev_by_source.values()))
        counts = {
            'nfev': self.nfev,
            'n_evaluations': self.nfev,
            'ngev': ngev,
            'njev': ngev,
            'ngev_by_source': dict(self.ngev_by_source),
        }
        if self._extra_counters is not None:
            counts.update(self._extra_counters())
        return counts

    def _iteration(self) -> int:
        return max(len(self.history) - 1, 0)

    def _advance(self, value: Any) -> None:
        try:
            self._pending = self._gen.send(value)
        except StopIteration:
            self._pending = None

    def _request(self, kind: str, x: Array) -> Generator[tuple[str, Array], Any, Any]:
        if kind == 'evaluate' and (np.any(x < self.lower) or np.any(x > self.upper)):
            raise RuntimeError(f'internal error: evaluation requested outside the bounds at {x}')
        reply = yield kind, x.copy()
        return reply

    def _parse_values(self, value: Any, x: Array) -> _Point:
        try:
            f, g, h = value
        except (TypeError, ValueError) as exc:
            raise ValueError('evaluate must return a tuple (f, g, h)') from exc
        f = float(f)
        g = _as_vector(g, 'g')
        h = _as_vector(h, 'h')
        if not np.isfinite(f) or not np.all(np.isfinite(g)) or not np.all(np.isfinite(h)):
            raise ValueError(
                f'evaluate returned non-finite values at x = {x}: f={f}, g={g}, h={h}'
            )
        if self._current is not None and (
            g.size != self._current.g.size or h.size != self._current.h.size
        ):
            raise ValueError(
                f'evaluate changed the number of constraints: g {g.size} '
                f'(was {self._current.g.size}), h {h.size} (was {self._current.h.size})'
            )
        return _Point(x.copy(), f, g, h)

    def _parse_gradient(self, value: Any, point: _Point) -> None:
        try:
            df, dg, dh = value
        except (TypeError, ValueError) as exc:
            raise ValueError('gradient must return a tuple (df, dg, dh)') from exc
        n = point.x.size
        df = np.asarray(df, dtype=float).reshape(-1)
        dg = np.zeros((0, n)) if dg is None else np.asarray(dg, dtype=float)
        dh = np.zeros((0, n)) if dh is None else np.asarray(dh, dtype=float)
        dg = dg.reshape(point.g.size, n) if dg.size == point.g.size * n else dg
        dh = dh.reshape(point.h.size, n) if dh.size == point.h.size * n else dh
        if df.shape != (n,):
            raise ValueError(f'gradient of f must have shape ({n},), got {df.shape}')
        if dg.shape != (point.g.size, n) or dh.shape != (point.h.size, n):
            raise ValueError(
                f'Jacobians must have shapes ({point.g.size}, {n}) and ({point.h.size}, {n}), '
                f'got {dg.shape} and {dh.shape}'
            )
        if not (np.all(np.isfinite(df)) and np.all(np.isfinite(dg)) and np.all(np.isfinite(dh))):
            raise ValueError(f'gradient returned non-finite values at x = {point.x}')
        source = self._reply_source or self.default_source
        point.df, point.dg, point.dh, point.source = df, dg, dh, source
        self.ngev_by_source[source] = self.ngev_by_source.get(source, 0) + 1
        if self.history and np.array_equal(self.history[-1]['x'], point.x):
            rec = self.history[-1]
            rec.update(df=df.copy(), dg=dg.copy(), dh=dh.copy(), gradient_source=source)
            rec.update(self._counters())

    def _feasible(self, point: _Point) -> bool:
        return _max_violation(point.g, point.h) <= self.options.gtol

    def _update_best(self, point: _Point) -> None:
        """Keep the best feasible point, and the least violating one while none is."""
        if self._feasible(point):
            if self._best is None or point.f < self._best.f:
                self._best = point
        elif self._least_violating is None or (
                _max_violation(point.g, point.h)
                < _max_violation(self._least_violating.g, self._least_violating.h)):
            self._least_violating = point

    def _at_bound_kkt(self, point: _Point) -> bool:
        """The bound-KKT test (option ``bound_kkt``) at an iterate with its gradient."""
        opt = self.options
        if not opt.bound_kkt or point.df is None or point.h.size or not self._feasible(point):
            return False
        if point.g.size and np.max(point.g) >= -max(10.0 * opt.gtol, 2.0 * opt.noise_g):
            return False
        width = self.upper - self.lower
        if not np.all(np.isfinite(width)):
            return False
        # on a bound within xtol: the subproblem solver's iterates stop short of it
        significant = np.abs(point.df) * width > opt.ftol * (1.0 + abs(point.f))
        out = (((point.x - self.lower <= opt.xtol) & (point.df > 0.0))
               | ((self.upper - point.x <= opt.xtol) & (point.df < 0.0)))
        return bool(np.all(out & significant))

    def _within_noise(self, cur: _Point, new: _Point) -> bool:
        """The noise test: the step's signal is below the noise (``noise_f``, ``noise_g``).

        The change the gradients at ``cur`` predict along the step, ``|df . dx|`` and
        every ``|dg_j . dx|``, is at most twice the noise level of f (and of g, with
        ``noise_g`` > 0), and ``new`` is feasible within twice the noise of g while a
        feasible design is known: such a step can no longer tell better from worse.
        """
        opt = self.options
        if opt.noise_f <= 0.0 or cur.df is None or self._best is None:
            return False
        dx = new.x - cur.x
        if abs(float(cur.df @ dx)) > 2.0 * opt.noise_f:
            return False
        if _max_violation(new.g, new.h) > opt.gtol + 2.0 * opt.noise_g:
            return False
        return bool(opt.noise_g <= 0.0 or cur.g.size == 0
                    or np.max(np.abs(cur.dg @ dx)) <= 2.0 * opt.noise_g)

    def _record(
        self,
        point: _Point,
        *,
        accepted: bool,
        from_iteration: int,
        rho_used: float,
        worse: bool,
        step: float,
        curvature: dict[str, Any] | None,
        subproblem: dict[str, Any] | None,
    ) -> dict[str, Any]:
        point.iteration = len(self.history)
        rec = {
            'iteration': len(self.history),
            'x': point.x.copy(),
            'f': point.f,
            'g': point.g.copy(),
            'h': point.h.copy(),
            'max_violation': _max_violation(point.g, point.h),
            'rho': rho_used,
            'rho_next': self._rho,
            'step': step,
            'accepted': accepted,
            'worse': worse,
            'from_iteration': from_iteration,
            'curvature': curvature,
            'subproblem': subproblem,
            'df': None if point.df is None else point.df.copy(),
            'dg': None if point.dg is None else point.dg.copy(),
            'dh': None if point.dh is None else point.dh.copy(),
            'gradient_source': None,
            'converge_count': self._converge_count,
        }
        rec.update(self._counters())
        self.history.append(rec)
        return rec

    def _load_history(self, history: Sequence[Mapping[str, Any]]) -> None:
        records = [dict(r) for r in history]
        n = self.x0.size
        points = []
        for k, rec in enumerate(records):
            try:
                x = np.asarray(rec['x'], dtype=float)
                p = _Point(
                    x, float(rec['f']), _as_vector(rec['g'], 'g'), _as_vector(rec['h'], 'h')
                )
            except KeyError as exc:
                raise ValueError(f'history record {k} lacks field {exc}') from exc
            if x.shape != (n,):
                raise ValueError(f'history record {k}: x has shape {x.shape}, expected ({n},)')
            if np.any(x < self.lower) or np.any(x > self.upper):
                raise ValueError(f'history record {k}: x = {x} lies outside the bounds')
            if rec.get('df') is not None:
                p.df = np.asarray(rec['df'], dtype=float)
                p.dg = np.asarray(rec['dg'], dtype=float).reshape(p.g.size, n)
                p.dh = np.asarray(rec['dh'], dtype=float).reshape(p.h.size, n)
            p.iteration = k
            p.source = rec.get('gradient_source')
            points.append(p)
            rec['x'] = x
            records[k] = rec
        if not records[0].get('accepted', True) or records[0].get('from_iteration', -1) != -1:
            raise ValueError('history must start with the starting-point record (iteration 0)')
        last = records[-1]
        self.history = records
        self._points = points
        self.nfev = int(last.get('n_evaluations', last.get('nfev', len(records))))
        self.ngev_by_source = dict(last.get('ngev_by_source', {}))
        if 'rho_next' not in last:
            raise ValueError('history: the last record lacks field rho_next (move limit)')
        self._rho = float(last['rho_next'])
        self._converge_count = int(last.get('converge_count', 0))
        for rec in reversed(records):
            if rec.get('curvature'):
                cv = rec['curvature']
                self._last_curvature = (float(cv['a']), np.asarray(cv['b'], float),
                                        np.asarray(cv['c'], float))
                break
        for p in points:
            self._update_best(p)

    def _curvatures(self, ref: _Point | None, cur: _Point) -> tuple[float, Array, Array]:
        """Curvatures a, b, c of P[i] at ``cur`` from the reference point (module notes).

        Zero at the first iteration; the previous iteration's after a step shorter
        than ``curvature_min_step``; else Snyman and Hay's interpolation, with the
        surrogate rules where the gradients at ``cur`` came from another model.
        """
        opt = self.options
        zero = (0.0, np.zeros(cur.g.size), np.zeros(cur.h.size))
        if ref is None:
            return zero
        dx = ref.x - cur.x
        dx2 = float(dx @ dx)
        if dx2 == 0.0:
            return zero
        last = self._last_curvature
        if (math.sqrt(dx2) < opt.curvature_min_step and last is not None
                and last[1].shape == (cur.g.size,) and last[2].shape == (cur.h.size,)):
            return last[0], last[1].copy(), last[2].copy()
        cap = opt.curvature_cap
        a = float(_curvature(np.array([ref.f]), np.array([cur.f]), cur.df[None], dx, dx2,
                             cap)[0])
        b = _curvature(ref.g, cur.g, cur.dg, dx, dx2, cap)
        c = _curvature(ref.h, cur.h, cur.dh, dx, dx2, cap)
        if cur.source not in SURROGATE_SOURCES:
            return a, b, c
        if opt.surrogate_constraint_curvature == 'zero':
            b = np.where(self._surrogate_rule_mask(b.size), 0.0, b)
            c = np.zeros(cur.h.size)
        if opt.surrogate_objective_curvature == 'zero':
            a = 0.0
        elif opt.surrogate_objective_curvature == 'nonnegative':
            a = max(a, 0.0)
        return a, b, c

    def _surrogate_rule_mask(self, m: int) -> Array:
        """Which of the m inequality constraints the surrogate constraint rule applies to."""
        rows = self._surrogate_rows
        if rows is None:
            return np.ones(m, bool)
        mask = np.asarray(rows(m) if callable(rows) else rows, dtype=bool)
        if mask.shape != (m,):
            raise ValueError(f'surrogate_rule_constraints has {mask.size} entries for {m} '
                             'constraints')
        return mask

    def _run(self) -> Generator[tuple[str, Array], Any, None]:
        opt = self.options
        if self.history:
            points = self._points
            cur_idx = max(k for k, r in enumerate(self.history) if r.get('accepted', True))
            cur = points[cur_idx]
            self._current = cur
            last = self.history[-1]
            if last is not self.history[cur_idx]:
                ref: _Point | None = points[-1]
            elif last.get('from_iteration', -1) >= 0:
                ref = points[int(last['from_iteration'])]
            else:
                ref = None
        else:
            value = yield from self._request('evaluate', self.x0)
            self.nfev += 1
            cur = self._parse_values(value, self.x0)
            cur_idx = 0
            ref = None
            self._current = cur
            self._update_best(cur)
            self._record(
                cur,
                accepted=True,
                from_iteration=-1,
                rho_used=0.0,
                worse=False,
                step=0.0,
                curvature=None,
                subproblem=None,
            )
        while True:
            if self._iteration() >= self.max_iterations:
                self.status = 3
                break
            if cur.df is None:
                value = yield from self._request('gradient', cur.x)
                self._parse_gradient(value, cur)
            if self._at_bound_kkt(cur):
                self.status = 6
                break
            a, b, c = self._curvatures(ref, cur)
            self._last_curvature = (a, np.asarray(b, float).copy(), np.asarray(c, float).copy())
            rho = self._rho
            x_new, sub = solve_subproblem(cur, rho, a, b, c, self.lower, self.upper, opt.lfopc)
            value = yield from self._request('evaluate', x_new)
            self.nfev += 1
            new = self._parse_values(value, x_new)
            self._update_best(new)
            viol_cur = _max_violation(cur.g, cur.h)
            viol_new = _max_violation(new.g, new.h)
            if viol_cur <= opt.gtol and viol_new <= opt.gtol:
                worse = new.f > cur.f
            else:
                worse = viol_new > viol_cur
            step = float(np.linalg.norm(x_new - cur.x))
            if worse or self._revisited(x_new):
                self._rho = rho * opt.rho_reduction
            elif step >= 0.99 * rho:
                rho_max = math.inf if opt.rho_max is None else opt.rho_max
                self._rho = max(rho, min(rho * opt.rho_growth, rho_max))
            accepted = not (worse and opt.worse_step == 'reject')
            df_change = abs(new.f - cur.f)
            f_scale = 1.0 + abs(cur.f)
            by_tolerance = step < opt.xtol or df_change < opt.ftol * f_scale
            noise = self._within_noise(cur, new)
            kept = new if accepted else cur
            # a converged iterate is feasible, or within xtol of the best feasible point:
            # on a staircase constraint (eq. 11) the run can alternate between a feasible
            # point and an infeasible one one stair away
            settled = self._feasible(kept) or (
                self._best is not None and np.linalg.norm(self._best.x - kept.x) < opt.xtol)
            passed = (by_tolerance and settled) or noise
            self._converge_count = self._converge_count + 1 if passed else 0
            # the run ends on the noise test when the noise let the last step pass
            self._noise_passed = passed and not (by_tolerance and settled)
            curvature = {'a': a, 'b': np.asarray(b).copy(), 'c': np.asarray(c).copy()}
            subinfo = {
                'nsteps': sub.nsteps,
                'active': sub.active.tolist(),
                'success': sub.success,
                'message': sub.message,
            }
            self._record(
                new,
                accepted=accepted,
                from_iteration=cur_idx,
                rho_used=rho,
                worse=worse,
                step=step,
                curvature=curvature,
                subproblem=subinfo,
            )
            if accepted:
                ref, cur, cur_idx = cur, new, len(self.history) - 1
                self._current = cur
            else:
                ref = new
            if self._converge_count >= opt.converge_iterations:
                self.status = 5 if self._noise_passed else 0 if step < opt.xtol else 1
                break
            if opt.rho_min > 0 and self._rho < opt.rho_min:
                self.status = 2 if self._feasible(cur) else 4
                break
        self.message = STATUS_MESSAGES[self.status]
        self._pending = None


def dynamic_q(
    evaluate: Callable[[Array], tuple[Any, Any, Any]],
    gradient: Callable[[Array], tuple[Any, Any, Any]],
    x0: ArrayLike,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    options: DynamicQOptions | Mapping[str, Any] | None = None,
    callback: Callable[[OptimizeResult], Any] | None = None,
    history: Sequence[Mapping[str, Any]] | None = None,
    gradient_source: str | None = None,
    counters: Callable[[], Mapping[str, Any]] | None = None,
) -> OptimizeResult:
    """Minimise f(x) s.t. g(x) <= 0, h(x) = 0, lower <= x <= upper (eqs. 1-3).

    Parameters
    ----------
    evaluate : callable
        ``evaluate(x) -> (f, g, h)``: objective, inequality values (g <= 0
        feasible, paper eq. 2) and equality values (eq. 3); g and h may be
        None or empty.  Called once per iteration, never outside the bounds.
    gradient : callable
        ``gradient(x) -> (df, dg, dh)`` with shapes (n,), (m, n), (p, n): the
        pluggable gradient source (simplified-model central differences,
        full-model differences, analytic, ...).
    x0 : array_like, shape (n,)
        Starting point inside the bounds; may be infeasible for g and h.
    lower, upper : array_like, shape (n,), optional
        Bounds (infinite entries allowed).
    options : DynamicQOptions or mapping, optional
        Algorithm options (see :class:`DynamicQOptions`).
    callback : callable, optional
        Called after every iteration (not for the starting point, as in
        SciPy) with an ``OptimizeResult`` of that iteration's record plus the
        counters; returning True or raising StopIteration ends the run
        (status 99).
    history : sequence of mappings, optional
        ``result.history`` of an earlier run to resume from.
    gradient_source : str, optional
        Name under which gradient evaluations are counted; defaults to the
        ``source`` attribute of ``gradient`` if present, else 'user'.
    counters : callable, optional
        Further counts for every record and the result (see :class:`DynamicQ`).

    Returns
    -------
    scipy.optimize.OptimizeResult
        x, fun (= f), g, h, success, status, message, nit (= iterations),
        nfev (calls of ``evaluate``, = n_evaluations), ngev (= njev, calls of
        ``gradient``), ngev_by_source, max_violation, rho, history.  ``x`` is the
        last iterate, as in SciPy; the best point seen is an extra field set:
        ``x_best``, ``f_best``, ``g_best``, ``h_best``, ``best_iteration`` and
        ``max_violation_best``: the feasible point (largest violation <= gtol)
        with the lowest f, or, when no point was feasible, the point with the
        smallest violation, and ``best_feasible`` says which.
    """
    source = gradient_source or getattr(gradient, 'source', None) or 'user'
    driver = DynamicQ(
        x0, lower, upper, options, history=history, gradient_source=source, counters=counters
    )
    while (request := driver.ask()) is not None:
        kind, x = request
        if kind == 'evaluate':
            record = driver.tell(evaluate(x))
        else:
            record = driver.tell(gradient(x))
        if record is not None and callback is not None and record['iteration'] > 0:
            intermediate = OptimizeResult(record)
            intermediate.update(fun=record['f'], nit=record['iteration'])
            try:
                stop = callback(intermediate)
            except StopIteration:
                stop = True
            if stop is True:
                driver.stop('stopped by the callback')
    return driver.result()


# ---------------------------------------------------------------- SciPy-style
def _parse_bounds(bounds: Any, n: int) -> tuple[Array, Array]:
    if bounds is None:
        return np.full(n, -np.inf), np.full(n, np.inf)
    if isinstance(bounds, Bounds):
        lo = np.broadcast_to(np.asarray(bounds.lb, dtype=float), n).copy()
        hi = np.broadcast_to(np.asarray(bounds.ub, dtype=float), n).copy()
        return lo, hi
    pairs = list(bounds)
    if len(pairs) != n:
        raise ValueError(f'bounds has {len(pairs)} (low, high) pairs for {n} variables')
    lo = np.array([-np.inf if p[0] is None else p[0] for p in pairs], dtype=float)
    hi = np.array([np.inf if p[1] is None else p[1] for p in pairs], dtype=float)
    return lo, hi


def _fd_step(x: Array, fd_step: Any) -> Array:
    if fd_step is None:
        # Central differences: eps^(1/3) balances truncation and rounding errors.
        return np.finfo(float).eps ** (1.0 / 3.0) * np.maximum(1.0, np.abs(x))
    return np.broadcast_to(np.asarray(fd_step, dtype=float), x.shape)


def minimize(
    fun: Callable[..., Any],
    x0: ArrayLike,
    args: tuple = (),
    method: str | None = None,
    jac: Callable[..., Any] | bool | str | None = None,
    hess: Any = None,
    hessp: Any = None,
    bounds: Bounds | Sequence[tuple[float | None, float | None]] | None = None,
    constraints: Mapping[str, Any] | Iterable[Mapping[str, Any]] = (),
    tol: float | None = None,
    callback: Callable[..., Any] | None = None,
    options: Mapping[str, Any] | None = None,
) -> OptimizeResult:
    """Dynamic-Q with the calling convention of ``scipy.optimize.minimize``.

    Switching from SLSQP is a one-line change::

        res = scipy.optimize.minimize(fun, x0, method='SLSQP', jac=jac,
                                      bounds=bounds, constraints=cons)
        res = suspension_tuning.optim.dynamic_q.minimize(fun, x0, jac=jac,
                                      bounds=bounds, constraints=cons)

    Parameters
    ----------
    fun : callable
        ``fun(x, *args) -> float`` (or ``(f, grad)`` when ``jac`` is True).
    x0 : array_like, shape (n,)
        Starting point; must be finite.  A point outside the bounds is clipped
        into them, as SciPy's bounded methods (SLSQP, L-BFGS-B) do.
    args : tuple
        Extra arguments of fun and jac.
    method : str, optional
        None or 'dynamic-q'.
    jac : callable, bool or None
        Gradient of fun; None (or a finite-difference name such as
        '2-point', '3-point') means central differences with step
        ``options['fd_step']`` (default eps^(1/3) max(1, |x_i|)), kept inside
        the bounds.
    hess, hessp : None
        Not used by Dynamic-Q; must be None.
    bounds : scipy.optimize.Bounds or sequence of (low, high), optional
        None or infinite entries mean unbounded.
    constraints : dict or sequence of dict
        SciPy dicts: ``type`` 'ineq' (meaning ``fun(x) >= 0``) or 'eq',
        ``fun``, optional ``jac`` and ``args``.
    tol : float, optional
        Sets xtol and ftol when they are not in options.
    callback : callable, optional
        ``callback(xk)`` or ``callback(intermediate_result)`` (chosen by the
        parameter name, as in SciPy); returning True or raising
        StopIteration stops the run.
    options : mapping, optional
        :class:`DynamicQOptions` fields plus ``fd_step`` and ``history`` (an
        earlier ``result.history`` to resume from).  ``rho0`` defaults to
        0.3 times the largest finite bound width, or 0.3 max(1, ||x0||_inf)
        when some variable is unbounded.

    Returns
    -------
    scipy.optimize.OptimizeResult
        As :func:`dynamic_q`; ``g`` is in the paper convention (g <= 0
        feasible, i.e. minus SciPy's 'ineq' values).  Counts as SciPy keeps
        them: ``nfev`` every call of ``fun``, finite differences included
        (with ``jac=True`` a point's ``(f, grad)`` is computed once);
        ``njev`` the gradient evaluations (SLSQP's meaning: analytic or by
        finite differences); ``constr_nfev`` per constraint dict, every call
        of its ``fun``, and ``constr_njev`` the calls of its ``jac``
        (trust-constr's meaning).  Further: ``nfev_fd`` and ``ncev_fd``, the
        calls of ``fun`` and of the constraint functions spent on finite
        differences (included in ``nfev`` and ``constr_nfev``), and
        ``n_evaluations``, the points at which Dynamic-Q evaluated
        (f, g, h).  With ``history`` every count continues the earlier run's.
    """
    if method is not None and method.lower().replace('_', '-') not in ('dynamic-q', 'dynamicq'):
        raise ValueError(f"method must be None or 'dynamic-q', got {method!r}")
    if hess is not None or hessp is not None:
        raise ValueError('Dynamic-Q uses no Hessian: hess and hessp must be None')
    x0 = np.array(x0, dtype=float)
    if x0.ndim != 1 or x0.size == 0:
        raise ValueError(f'x0 must be a non-empty 1-D vector, got shape {x0.shape}')
    n = x0.size
    x0, lower, upper = _validate_problem(x0, *_parse_bounds(bounds, n), clip=True)
    opts = dict(options or {})
    fd_step = opts.pop('fd_step', None)
    history = opts.pop('history', None)
    if tol is not None:
        opts.setdefault('xtol', tol)
        opts.setdefault('ftol', tol)
    if 'rho0' not in opts:
        width = upper - lower
        if np.all(np.isfinite(width)):
            opts['rho0'] = 0.3 * float(np.max(width))
        else:
            opts['rho0'] = 0.3 * max(1.0, float(np.max(np.abs(x0))))
        if not opts['rho0'] > 0:
            opts['rho0'] = 0.3
    if isinstance(constraints, Mapping):
        constraints = [constraints]
    cons = list(constraints)
    for k, con in enumerate(cons):
        if not isinstance(con, Mapping) or 'fun' not in con or 'type' not in con:
            raise ValueError(f'constraint {k} must be a dict with keys type and fun')
        if con['type'] not in ('ineq', 'eq'):
            raise ValueError(f"constraint {k} type must be 'ineq' or 'eq', got {con['type']!r}")

    # Calls of the user's functions, continued from the history's last record if any.
    last = dict(history[-1]) if history else {}
    counts = {
        'nfev': int(last.get('nfev', 0)),
        'nfev_fd': int(last.get('nfev_fd', 0)),
        'ncev_fd': int(last.get('ncev_fd', 0)),
        'constr_nfev': [int(v) for v in last.get('constr_nfev', [0] * len(cons))],
        'constr_njev': [int(v) for v in last.get('constr_njev', [0] * len(cons))],
    }
    if len(counts['constr_nfev']) != len(cons) or len(counts['constr_njev']) != len(cons):
        raise ValueError(f'history counts {len(counts["constr_nfev"])} constraints, '
                         f'the problem has {len(cons)}')
    jac_true = jac is True
    memo: dict[str, Any] = {}

    def call_fun(x: Array) -> Any:
        """One call of fun (with jac=True its (f, grad) of the last point is kept)."""
        if jac_true and memo.get('x') == x.tobytes():
            return memo['value']
        counts['nfev'] += 1
        value = fun(x, *args)
        if jac_true:
            memo.update(x=x.tobytes(), value=value)
        return value

    def objective(x: Array) -> float:
        return float(call_fun(x)[0] if jac_true else call_fun(x))

    def call_con(k: int, x: Array) -> Array:
        counts['constr_nfev'][k] += 1
        value = cons[k]['fun'](x, *cons[k].get('args', ()))
        return np.atleast_1d(np.asarray(value, dtype=float))

    def con_values(x: Array, kind: str) -> Array:
        parts = [call_con(k, x) for k, c in enumerate(cons) if c['type'] == kind]
        return np.concatenate(parts) if parts else np.zeros(0)

    def evaluate(x: Array) -> tuple[float, Array, Array]:
        return objective(x), -con_values(x, 'ineq'), con_values(x, 'eq')

    def fd(fun1: Callable[[Array], Any], x: Array, counter: str) -> Array:
        def batch(points: Array) -> Array:
            counts[counter] += points.shape[0]
            return np.array([np.asarray(fun1(p), dtype=float) for p in points])

        return central_difference(batch, x, _fd_step(x, fd_step), lower, upper)

    analytic_f = callable(jac) or jac_true

    def con_jac(x: Array, kind: str) -> Array:
        rows = []
        for k, c in enumerate(cons):
            if c['type'] != kind:
                continue
            if c.get('jac') is not None:
                counts['constr_njev'][k] += 1
                j = np.asarray(c['jac'](x, *c.get('args', ())), dtype=float)
            else:
                j = fd(lambda p, k=k: call_con(k, p), x, 'ncev_fd')
            rows.append(np.atleast_2d(j).reshape(-1, n))
        return np.vstack(rows) if rows else np.zeros((0, n))

    def gradient(x: Array) -> tuple[Array, Array, Array]:
        if jac_true:
            df = np.asarray(call_fun(x)[1], dtype=float)
        elif callable(jac):
            df = np.asarray(jac(x, *args), dtype=float)
        else:
            df = fd(objective, x, 'nfev_fd')
        return df, -con_jac(x, 'ineq'), con_jac(x, 'eq')

    all_analytic = analytic_f and all(c.get('jac') is not None for c in cons)
    source = 'analytic' if all_analytic else 'central_difference'

    wrapped_callback = None
    if callback is not None:
        try:
            params = list(inspect.signature(callback).parameters)
        except (TypeError, ValueError):
            params = []
        wants_result = params == ['intermediate_result']

        def wrapped_callback(intermediate: OptimizeResult) -> Any:
            if wants_result:
                return callback(intermediate)
            return callback(np.copy(intermediate['x']))

    def current_counts() -> dict[str, Any]:
        return {
            'nfev': counts['nfev'],
            'nfev_fd': counts['nfev_fd'],
            'ncev_fd': counts['ncev_fd'],
            'constr_nfev': list(counts['constr_nfev']),
            'constr_njev': list(counts['constr_njev']),
        }

    return dynamic_q(
        evaluate,
        gradient,
        x0,
        lower,
        upper,
        opts,
        callback=wrapped_callback,
        history=history,
        gradient_source=source,
        counters=current_counts,
    )
