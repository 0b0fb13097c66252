"""LFOP and LFOPC: Snyman's leap-frog dynamic trajectory methods.

LFOP (Snyman 1982, 1983) minimises a smooth unconstrained function F(x) by
following the trajectory of a unit-mass particle in the force field -grad F,
integrated with the leap-frog scheme, and taking energy out of the trajectory
("interference") whenever the kinetic energy drops.  Only gradients of F are
used.  LFOPC (Snyman 2000) applies LFOP to a penalty function whose penalty
parameter rises in phases:

* phase 0: minimise P(x, mu0) = f + sum mu0 h_k^2 + sum beta_j g_j^2, with
  beta_j = mu0 where g_j > 0 and 0 otherwise;
* phase 1: from x*(mu0), minimise P(x, mu1); the constraints with
  g_j(x*(mu1)) > 0 form the active set;
* phase 2: from x*(mu1), minimise P_a = sum mu1 h_k^2 + sum_active mu1 g_j^2
  (f dropped), which removes the O(1/mu) infeasibility of the penalty optimum
  by moving onto the intersection of the active constraints.

References
----------
Snyman, J.A. (2000), "The LFOPC leap-frog algorithm for constrained
optimisation", Computers & Mathematics with Applications 40, 1085-1096.
Snyman, J.A. (1983), "An improved version of the original leap-frog dynamic
method for unconstrained minimization", Applied Mathematical Modelling 7.
Snyman, J.A. (2005), Practical Mathematical Optimization, Springer, ch. 6.
Steps and defaults of LFOP as in /work/shared/notes/physics-reference.md
section 1.4 (checked against CILib's LFVelocityUpdate, whose two visible bugs
are not reproduced here); the phases of LFOPC as in section 1.5 [R].

Implementation notes
--------------------
* The oscillation test of step 6 of LFOP is applied in both branches of the
  step-size test and with the book's order (``s >= m`` halves the time step
  and averages the last two states); CILib applies it only in the clipped
  branch and with the inverted test ``s < m``.
* Stability safeguard [E, a change to the published LFOP]: on a penalty
  function with mu1 = 1e4 the published steps alone fell into a cycle.  The
  particle, thrown into the stiff penalty wall with a time step too large for
  it, gained kinetic energy there (leap-frog instability), was clipped to the
  maximum step delta and thrown back, with only two consecutive gradient
  reversals per bounce, so the m = 3 rule never halved dt.  On
  min (x1-2)^2 + (x2-1)^2 s.t. x1 + x2 <= 2 (optimum (1.5, 0.5)) phase 1 hit
  a 3000-step cap at (1.177, 0.177).  Leap-frog is stable on a mode of
  curvature kappa only if dt^2 kappa < 4, so each new step estimates the
  secant stiffness kappa = ||a_{k+1} - a_k|| / ||x_{k+1} - x_k|| and, when
  dt^2 kappa > 4, redoes the step once with dt = 1 / sqrt(kappa).  The same
  problem then converges in 249 steps to within 2e-7 of the optimum, with
  the published absolute gradient test 1e-5, and no Dynamic-Q subproblem of
  the analytic tests hits the step cap.  (A first version that retried
  steps on which F and the kinetic energy both rose needed F, and halved dt
  to zero at small velocities on HS71 and Rosenbrock subproblems.)
* Step-size test [E]: physics-reference 1.4 suggests also stopping on an
  accepted step shorter than eps_x = 1e-8.  After time-step halvings such
  steps occur far from the minimum (phase 0 of the problem above stopped at
  (1.516, 0.490) instead of the penalty optimum (1.5025, 0.5025)), so the
  test is off by default (eps_x = 0) and the runs stop on the gradient test
  or on the step cap max_steps.  Hitting the cap is reported, never hidden.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from suspension_tuning.optim._options import options_from_mapping

Array = NDArray[np.float64]

_STABILITY_LIMIT = 4.0
"""Leap-frog is stable on a quadratic mode of curvature kappa only when
dt^2 kappa < 4 (standard result for the Stormer-Verlet scheme)."""


@dataclass(frozen=True)
class LfopOptions:
    """Options of LFOP and LFOPC (defaults: physics-reference 1.4 and 1.5).

    Attributes
    ----------
    dt : float
        Initial time step Delta t [S, CILib LFDecorator; book default].
    delta : float
        Largest allowed step ||Delta x|| per time step, in units of x [S].
    m : int
        Consecutive gradient reversals (a_{k+1}.a_k <= 0) tolerated before the
        time step is halved [S].
    delta1 : float
        Time-step growth increment: p <- p + delta1, dt <- p dt [S].
    j : int
        Interferences before the velocity is set to zero [S].
    eps_g : float
        Gradient-norm tolerance ||grad F|| <= eps_g [R: book 1e-5].
    eps_x : float
        Stop when an accepted step is shorter than this; 0 disables the test
        [E: off by default, see the module notes].
    max_steps : int
        Cap on leap-frog steps per phase [E: 1e4 per physics-reference 1.4].
    mu0 : float
        Penalty parameter of LFOPC phase 0 [R: 1e2].
    mu1 : float
        Penalty parameter of LFOPC phases 1 and 2 [R: 1e4].
    """

    dt: float = 0.5
    delta: float = 1.0
    m: int = 3
    delta1: float = 0.001
    j: int = 2
    eps_g: float = 1e-5
    eps_x: float = 0.0
    max_steps: int = 10_000
    mu0: float = 1e2
    mu1: float = 1e4

    def __post_init__(self) -> None:
        """Check that every option is finite and in its valid range."""
        for name in ('dt', 'delta', 'delta1', 'eps_g', 'mu0', 'mu1'):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f'LFOP option {name} must be finite and > 0, got {value!r}')
        if not np.isfinite(self.eps_x) or self.eps_x < 0:
            raise ValueError(f'LFOP option eps_x must be finite and >= 0, got {self.eps_x!r}')
        for name in ('m', 'j', 'max_steps'):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f'LFOP option {name} must be an integer >= 1, got {value!r}')
        if self.mu1 < self.mu0:
            raise ValueError(f'LFOPC needs mu1 >= mu0, got mu0={self.mu0}, mu1={self.mu1}')

    @classmethod
    def from_mapping(cls, options: LfopOptions | dict | None) -> LfopOptions:
        """Build options from a dict (unknown keys raise ValueError)."""
        return options_from_mapping(cls, options, 'LFOP')


@dataclass
class LfopResult:
    """Outcome of one LFOP run.

    Attributes
    ----------
    x : ndarray
        Final point.
    grad_norm : float
        ||grad F(x)|| at the final point.
    nsteps : int
        Gradient evaluations (leap-frog steps, including interference steps).
    converged : bool
        True when a published or practical stopping rule (not the step cap)
        ended the run.
    message : str
        Which rule stopped the run.
    """

    x: Array
    grad_norm: float
    nsteps: int
    converged: bool
    message: str


def lfop(
    grad: Callable[[Array], Array],
    x0: ArrayLike,
    options: LfopOptions | dict | None = None,
) -> LfopResult:
    """Minimise F by the improved leap-frog dynamic trajectory method (LFOP).

    Parameters
    ----------
    grad : callable
        ``grad(x) -> ndarray (n,)``, the gradient of F.
    x0 : array_like, shape (n,)
        Starting point.
    options : LfopOptions or dict, optional
        Algorithm options (see :class:`LfopOptions`).

    Returns
    -------
    LfopResult
        Final point, gradient norm, step count and stopping reason.
    """
    opt = LfopOptions.from_mapping(options)
    x = np.array(x0, dtype=float)
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        raise ValueError(f'LFOP x0 must be a finite 1-D vector, got {x0!r}')
    eps = opt.eps_g
    dt = opt.dt
    a = -np.asarray(grad(x), dtype=float)
    nsteps = 1
    anorm = float(np.sqrt(a @ a))
    if anorm <= eps:
        return LfopResult(x, anorm, nsteps, True, 'gradient norm below eps_g at start')
    v = 0.5 * a * dt
    x_prev, v_prev = x.copy(), v.copy()
    a_valid = True
    p, s, i, jj = 1.0, 0, 0, opt.j
    while True:
        # Steps 2-6: limit the step, grow the time step, damp oscillation.
        vnorm = float(np.sqrt(v @ v))
        if vnorm * dt < opt.delta:
            p += opt.delta1
            dt *= p
        else:
            v = opt.delta * v / (dt * vnorm)
        if s >= opt.m:
            dt *= 0.5
            x = 0.5 * (x + x_prev)
            v = 0.25 * (v + v_prev)
            s = 0
            a_valid = False  # a was computed at the old x, not at the average
        # Step 7: leap-frog position update.
        x_new = x + v * dt
        retried = False
        while True:
            # Step 8: force and velocity at the new position.
            a_new = -np.asarray(grad(x_new), dtype=float)
            nsteps += 1
            if a_valid and not retried:
                # Stability safeguard (module notes): secant stiffness along the step.
                dx_norm = float(np.sqrt((x_new - x) @ (x_new - x)))
                if dx_norm > 0:
                    da = a_new - a
                    kappa = float(np.sqrt(da @ da)) / dx_norm
                    if kappa * dt * dt > _STABILITY_LIMIT and nsteps < opt.max_steps:
                        dt = 1.0 / np.sqrt(kappa)
                        x_new = x + v * dt
                        retried = True
                        continue
            v_new = v + a_new * dt
            # Step 9: count gradient reversals.
            if a_new @ a > 0:
                s = 0
            else:
                s += 1
                p = 1.0
            anorm = float(np.sqrt(a_new @ a_new))
            # Step 10: converged on the gradient.
            if anorm <= eps:
                return LfopResult(x_new, anorm, nsteps, True, 'gradient norm below eps_g')
            if nsteps >= opt.max_steps:
                return LfopResult(x_new, anorm, nsteps, False, 'maximum number of steps reached')
            # Step 11: kinetic energy increased, accept the step.
            if v_new @ v_new > v @ v:
                i = 0
                break
            # Steps 12-13: interference, kinetic energy dropped.
            mid = 0.5 * (x_new + x)
            i += 1
            if i <= jj:
                v_mod = 0.25 * (v_new + v)
            else:
                v_mod = np.zeros_like(v_new)
                jj = 1
            x_prev, x = x, x_new
            v_prev, v = v, v_mod
            a = a_new
            a_valid, retried = True, False
            x_new = mid
        step = x_new - x
        x_prev, x = x, x_new
        v_prev, v = v, v_new
        a = a_new
        a_valid = True
        if opt.eps_x > 0 and float(np.sqrt(step @ step)) < opt.eps_x:
            return LfopResult(x, anorm, nsteps, True, 'step shorter than eps_x')


@dataclass
class LfopcResult:
    """Outcome of an LFOPC run.

    Attributes
    ----------
    x : ndarray
        Constrained minimiser found.
    f : float
        f(x).
    g : ndarray
        Inequality constraint values at x (g <= 0 feasible).
    h : ndarray
        Equality constraint values at x.
    active : ndarray of int
        Indices of the inequality constraints identified as active in phase 1.
    nsteps : tuple of int
        Leap-frog steps in phases 0, 1 and 2.
    success : bool
        True when every phase stopped on a convergence rule.
    message : str
        Stopping reasons of the phases.
    phase_x : list of ndarray
        x*(mu0), x*(mu1) and the phase-2 point.
    """

    x: Array
    f: float
    g: Array
    h: Array
    active: NDArray[np.int_]
    nsteps: tuple[int, int, int]
    success: bool
    message: str
    phase_x: list[Array] = field(default_factory=list)

    @property
    def max_violation(self) -> float:
        """Largest constraint violation max(0, g_j, |h_k|)."""
        return max([0.0, *np.maximum(self.g, 0.0), *np.abs(self.h)])


def _empty_constraint(n: int) -> tuple[Callable, Callable]:
    return (lambda x: np.zeros(0)), (lambda x: np.zeros((0, n)))


def lfopc(
    f: Callable[[Array], float],
    grad_f: Callable[[Array], Array],
    x0: ArrayLike,
    g: Callable[[Array], Array] | None = None,
    jac_g: Callable[[Array], Array] | None = None,
    h: Callable[[Array], Array] | None = None,
    jac_h: Callable[[Array], Array] | None = None,
    options: LfopOptions | dict | None = None,
) -> LfopcResult:
    """Minimise f subject to g(x) <= 0 and h(x) = 0 with LFOPC (Snyman 2000).

    The constraints should be scaled to O(1) (Snyman 2000); the penalty
    infeasibility of phases 0 and 1 is O(multiplier / mu).

    Parameters
    ----------
    f, grad_f : callable
        Objective ``f(x) -> float`` and its gradient ``grad_f(x) -> (n,)``.
    x0 : array_like, shape (n,)
        Starting point (need not be feasible).
    g, jac_g : callable, optional
        Inequalities ``g(x) -> (m,)`` (g <= 0 feasible) and their Jacobian
        ``jac_g(x) -> (m, n)``; both or neither.
    h, jac_h : callable, optional
        Equalities ``h(x) -> (p,)`` and their Jacobian ``(p, n)``.
    options : LfopOptions or dict, optional
        LFOP options and the penalty parameters mu0, mu1.

    Returns
    -------
    LfopcResult
        The minimiser, constraint values, active set and step counts.
    """
    opt = LfopOptions.from_mapping(options)
    x = np.array(x0, dtype=float)
    if x.ndim != 1 or x.size == 0 or not np.all(np.isfinite(x)):
        raise ValueError(f'LFOPC x0 must be a finite non-empty 1-D vector, got {x0!r}')
    n = x.size
    if (g is None) != (jac_g is None) or (h is None) != (jac_h is None):
        raise ValueError('LFOPC needs each constraint function together with its Jacobian')
    if g is None:
        g, jac_g = _empty_constraint(n)
    if h is None:
        h, jac_h = _empty_constraint(n)

    def penalty_grad(mu: float, with_f: bool, mask: NDArray[np.bool_] | None):
        def grad(y: Array) -> Array:
            gv = np.asarray(g(y), dtype=float)
            hv = np.asarray(h(y), dtype=float)
            out = np.asarray(grad_f(y), dtype=float).copy() if with_f else np.zeros(n)
            if gv.size:
                w = np.where(gv > 0, gv, 0.0) if mask is None else np.where(mask, gv, 0.0)
                if np.any(w):
                    out += 2.0 * mu * (w @ np.asarray(jac_g(y), dtype=float))
            if hv.size:
                out += 2.0 * mu * (hv @ np.asarray(jac_h(y), dtype=float))
            return out

        return grad

    r0 = lfop(penalty_grad(opt.mu0, True, None), x, opt)
    r1 = lfop(penalty_grad(opt.mu1, True, None), r0.x, opt)
    g1 = np.asarray(g(r1.x), dtype=float)
    active = np.flatnonzero(g1 > 0)
    n_eq = np.asarray(h(r1.x)).size
    messages = [f'phase 0: {r0.message}', f'phase 1: {r1.message}']
    if active.size or n_eq:
        mask = np.zeros(g1.size, dtype=bool)
        mask[active] = True
        r2 = lfop(penalty_grad(opt.mu1, False, mask), r1.x, opt)
        messages.append(f'phase 2: {r2.message}')
        x_star, steps2, ok2 = r2.x, r2.nsteps, r2.converged
    else:
        messages.append('phase 2: not needed (no active constraints)')
        x_star, steps2, ok2 = r1.x, 0, True
    return LfopcResult(
        x=x_star,
        f=float(f(x_star)),
        g=np.asarray(g(x_star), dtype=float),
        h=np.asarray(h(x_star), dtype=float),
        active=active,
        nsteps=(r0.nsteps, r1.nsteps, steps2),
        success=bool(r0.converged and r1.converged and ok2),
        message='; '.join(messages),
        phase_x=[r0.x, r1.x, x_star],
    )
