"""Analytic test problems with published optima, in the SciPy calling convention.

Used by test/test_dynamic_q.py and benchmarks/bench_optimiser.py.  Each
function returns a dict with fun, jac, x0, bounds, constraints (SciPy dicts:
'ineq' means fun(x) >= 0), the known optimum x_star, f_star, and optional
options for minimize.  Sources: Hock and Schittkowski (1981), "Test examples
for nonlinear programming codes", Lecture Notes in Economics and Mathematical
Systems 187 (HS21, HS35, HS71, HS6, HS7); hand calculations for the others,
written beside them.
"""

import math

import numpy as np


def _rosen(x: np.ndarray) -> float:
    return 100.0 * (x[1] - x[0] ** 2) ** 2 + (1.0 - x[0]) ** 2


def _rosen_grad(x: np.ndarray) -> np.ndarray:
    return np.array(
        [-400.0 * x[0] * (x[1] - x[0] ** 2) - 2.0 * (1.0 - x[0]), 200.0 * (x[1] - x[0] ** 2)]
    )


def hs21() -> dict:
    """HS21, bounded quadratic with a linear inequality.

    HS21: min 0.01 x1^2 + x2^2 - 100 s.t. 10 x1 - x2 - 10 >= 0, 2 <= x1 <= 50,
    -50 <= x2 <= 50.  x* = (2, 0), f* = -99.96 (HS 1981).  HS's start (-1, -1) lies
    outside the bounds; (2, -1) is it moved onto the bound x1 = 2.
    """
    return dict(
        fun=lambda x: 0.01 * x[0] ** 2 + x[1] ** 2 - 100.0,
        jac=lambda x: np.array([0.02 * x[0], 2.0 * x[1]]),
        x0=[2.0, -1.0],
        bounds=[(2.0, 50.0), (-50.0, 50.0)],
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: 10.0 * x[0] - x[1] - 10.0,
                'jac': lambda x: np.array([10.0, -1.0]),
            }
        ],
        x_star=[2.0, 0.0],
        f_star=-99.96,
    )


def hs35() -> dict:
    """HS35, convex quadratic with a linear inequality and x >= 0.

    HS35 (Beale): min 9 - 8x1 - 6x2 - 4x3 + 2x1^2 + 2x2^2 + x3^2 + 2x1x2 + 2x1x3
    s.t. 3 - x1 - x2 - 2 x3 >= 0, x >= 0; start (0.5, 0.5, 0.5).
    x* = (4/3, 7/9, 4/9), f* = 1/9 (HS 1981).
    """
    return dict(
        fun=lambda x: (
            9.0
            - 8.0 * x[0]
            - 6.0 * x[1]
            - 4.0 * x[2]
            + 2.0 * x[0] ** 2
            + 2.0 * x[1] ** 2
            + x[2] ** 2
            + 2.0 * x[0] * x[1]
            + 2.0 * x[0] * x[2]
        ),
        jac=lambda x: np.array(
            [
                -8.0 + 4.0 * x[0] + 2.0 * x[1] + 2.0 * x[2],
                -6.0 + 4.0 * x[1] + 2.0 * x[0],
                -4.0 + 2.0 * x[2] + 2.0 * x[0],
            ]
        ),
        x0=[0.5, 0.5, 0.5],
        bounds=[(0.0, None)] * 3,
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: 3.0 - x[0] - x[1] - 2.0 * x[2],
                'jac': lambda x: np.array([-1.0, -1.0, -2.0]),
            }
        ],
        x_star=[4.0 / 3.0, 7.0 / 9.0, 4.0 / 9.0],
        f_star=1.0 / 9.0,
    )


def hs71() -> dict:
    """HS71, equality, inequality and bounds.

    HS71: min x1 x4 (x1 + x2 + x3) + x3 s.t. x1 x2 x3 x4 >= 25, sum x_i^2 = 40,
    1 <= x <= 5; start (1, 5, 5, 1) (violates the equality: sum x^2 = 52).
    x* = (1, 4.7429994, 3.8211503, 1.3794082), f* = 17.0140173 (HS 1981).
    """
    return dict(
        fun=lambda x: x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2],
        jac=lambda x: np.array(
            [
                x[3] * (2.0 * x[0] + x[1] + x[2]),
                x[0] * x[3],
                x[0] * x[3] + 1.0,
                x[0] * (x[0] + x[1] + x[2]),
            ]
        ),
        x0=[1.0, 5.0, 5.0, 1.0],
        bounds=[(1.0, 5.0)] * 4,
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: x[0] * x[1] * x[2] * x[3] - 25.0,
                'jac': lambda x: np.array(
                    [
                        x[1] * x[2] * x[3],
                        x[0] * x[2] * x[3],
                        x[0] * x[1] * x[3],
                        x[0] * x[1] * x[2],
                    ]
                ),
            },
            {'type': 'eq', 'fun': lambda x: x @ x - 40.0, 'jac': lambda x: 2.0 * x},
        ],
        x_star=[1.0, 4.7429994, 3.8211503, 1.3794082],
        f_star=17.0140173,
    )


def hs6() -> dict:
    """HS6, one nonlinear equality.

    HS6: min (1 - x1)^2 s.t. 10 (x2 - x1^2) = 0; start (-1.2, 1).  x* = (1, 1), f* = 0.
    """
    return dict(
        fun=lambda x: (1.0 - x[0]) ** 2,
        jac=lambda x: np.array([-2.0 * (1.0 - x[0]), 0.0]),
        x0=[-1.2, 1.0],
        bounds=None,
        constraints=[
            {
                'type': 'eq',
                'fun': lambda x: 10.0 * (x[1] - x[0] ** 2),
                'jac': lambda x: np.array([-20.0 * x[0], 10.0]),
            }
        ],
        x_star=[1.0, 1.0],
        f_star=0.0,
    )


def hs7() -> dict:
    """HS7, one nonlinear equality.

    HS7: min ln(1 + x1^2) - x2 s.t. (1 + x1^2)^2 + x2^2 - 4 = 0; start (2, 2).
    x* = (0, sqrt 3), f* = -sqrt 3 (HS 1981).
    """
    return dict(
        fun=lambda x: math.log(1.0 + x[0] ** 2) - x[1],
        jac=lambda x: np.array([2.0 * x[0] / (1.0 + x[0] ** 2), -1.0]),
        x0=[2.0, 2.0],
        bounds=None,
        constraints=[
            {
                'type': 'eq',
                'fun': lambda x: (1.0 + x[0] ** 2) ** 2 + x[1] ** 2 - 4.0,
                'jac': lambda x: np.array([4.0 * x[0] * (1.0 + x[0] ** 2), 2.0 * x[1]]),
            }
        ],
        x_star=[0.0, math.sqrt(3.0)],
        f_star=-math.sqrt(3.0),
    )


def rosenbrock_bound_active() -> dict:
    """Rosenbrock with an active bound.

    Rosenbrock in [-2, 0.5] x [-2, 2] from (-1.2, 1).  Hand calculation: along the
    valley x2 = x1^2, f = (1 - x1)^2 falls until x1 = 1, so the bound x1 = 0.5 is
    active; then x2 = 0.25 (df/dx2 = 0) and df/dx1 = -1 < 0 there (KKT with the
    upper bound).  x* = (0.5, 0.25), f* = 0.25.
    """
    return dict(
        fun=_rosen,
        jac=_rosen_grad,
        x0=[-1.2, 1.0],
        bounds=[(-2.0, 0.5), (-2.0, 2.0)],
        constraints=[],
        x_star=[0.5, 0.25],
        f_star=0.25,
    )


def rosenbrock_interior() -> dict:
    """Rosenbrock with inactive bounds.

    Rosenbrock in [-2, 2]^2 from (-1.2, 1): the bounds are inactive, x* = (1, 1),
    f* = 0.  Tolerances: the step test bounds the error only by about xtol times the
    condition number of the Hessian at x* (about 2500), so xtol = 1e-8 for 1e-4 on x
    (with the default 1e-5 the run stops at error 2.5e-3, f = 1.5e-6).  Near f* = 0 the
    ftol test is absolute, and f - f* = 2e-9 still allows an error of 1e-4 along the
    valley (smallest Hessian eigenvalue 0.4) while successive f values there differ by
    1e-12 or less (measured: ftol = 1e-12 stopped at error 6.6e-5), so ftol = 1e-15
    leaves the step test in charge.
    """
    return dict(
        fun=_rosen,
        jac=_rosen_grad,
        x0=[-1.2, 1.0],
        bounds=[(-2.0, 2.0), (-2.0, 2.0)],
        constraints=[],
        x_star=[1.0, 1.0],
        f_star=0.0,
        options={'xtol': 1e-8, 'ftol': 1e-15},
    )


def constrained_quadratic() -> dict:
    """Quadratic with one active linear inequality, closed-form optimum.

    Min ||x - p||^2 with p = (1, 2, 3) s.t. x1 + x2 + x3 <= 3.  Closed form (projection
    onto the half-space): x* = p - (a.p - 3)/||a||^2 a = p - (6 - 3)/3 (1, 1, 1)
    = (0, 1, 2), f* = 3.
    """
    p = np.array([1.0, 2.0, 3.0])
    return dict(
        fun=lambda x: float((x - p) @ (x - p)),
        jac=lambda x: 2.0 * (x - p),
        x0=[0.0, 0.0, 0.0],
        bounds=None,
        constraints=[
            {'type': 'ineq', 'fun': lambda x: 3.0 - x.sum(), 'jac': lambda x: -np.ones(3)}
        ],
        x_star=[0.0, 1.0, 2.0],
        f_star=3.0,
    )


PROBLEMS = {  # name -> problem factory
    'hs21': hs21,
    'hs35': hs35,
    'hs71': hs71,
    'hs6': hs6,
    'hs7': hs7,
    'rosenbrock_bound_active': rosenbrock_bound_active,
    'rosenbrock_interior': rosenbrock_interior,
    'constrained_quadratic': constrained_quadratic,
}
