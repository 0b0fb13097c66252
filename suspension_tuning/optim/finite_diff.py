"""Central finite differences on a batch function, never outside the bounds.

The seed paper (Thoresson et al. 2009, section 2) computes the gradients of
the objective and constraints by central differences, 2n runs per gradient.
Here all 2n perturbed designs are built at once so that a batch evaluator
(the simplified vehicle models, or a pool of full-model workers) can run them
together.

Stencil at a bound (physics-reference 1.8 [E]): the pair x_i - h, x_i + h is
shifted inside the box as a whole, keeping its width 2h, e.g. [x_i, x_i + 2h]
at a lower bound.  The difference quotient is then the derivative at the
pair's midpoint, a first-order approximation at x_i, which is what the paper
accepts in exchange for never evaluating outside the bounds.  When the box is
narrower than 2h in a coordinate, the pair spans the whole box.

Layout of the stencil: row ``i`` is the upper point of coordinate ``i`` and
row ``n + i`` the lower point.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def _check_inputs(
    x: ArrayLike, h: ArrayLike, lower: ArrayLike | None, upper: ArrayLike | None
) -> tuple[Array, Array, Array, Array]:
    x = np.array(x, dtype=float)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f'finite differences need a non-empty 1-D x, got shape {x.shape}')
    if not np.all(np.isfinite(x)):
        raise ValueError(f'finite differences need a finite x, got {x}')
    n = x.size
    lo = np.full(n, -np.inf) if lower is None else np.broadcast_to(np.array(lower, float), n)
    hi = np.full(n, np.inf) if upper is None else np.broadcast_to(np.array(upper, float), n)
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
        raise ValueError('finite-difference bounds contain NaN')
    if np.any(lo >= hi):
        raise ValueError(f'finite-difference bounds need lower < upper, got {lo} and {hi}')
    if np.any(x < lo) or np.any(x > hi):
        raise ValueError(f'finite differences asked at x = {x} outside the bounds [{lo}, {hi}]')
    step = np.broadcast_to(np.array(h, dtype=float), n)
    if not np.all(np.isfinite(step)) or np.any(step <= 0):
        raise ValueError(f'finite-difference step h must be finite and > 0, got {h!r}')
    return x, step.copy(), lo.copy(), hi.copy()


def central_difference_points(
    x: ArrayLike,
    h: ArrayLike = 0.025,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
) -> tuple[Array, Array]:
    """Build the 2n central-difference points, shifted inside the bounds.

    Parameters
    ----------
    x : array_like, shape (n,)
        Point at which the gradient is wanted (inside the bounds).
    h : float or array_like, shape (n,)
        Half-width of the stencil, in the units of x (default 0.025 for
        normalised design variables, physics-reference 1.8 [E]).
    lower, upper : array_like, shape (n,), optional
        Bounds (infinite allowed); no point is placed outside them.

    Returns
    -------
    points : ndarray, shape (2n, n)
        Row i is the upper point of coordinate i, row n + i the lower point.
    steps : ndarray, shape (n,)
        Distance between the two points of each pair (2h unless the box is
        narrower), the divisor of the difference quotient.
    """
    x, step, lo, hi = _check_inputs(x, h, lower, upper)
    n = x.size
    width = hi - lo
    narrow = width < 2.0 * step
    low_point = np.where(narrow, lo, np.clip(x - step, lo, hi - 2.0 * step))
    high_point = np.where(narrow, hi, low_point + 2.0 * step)
    points = np.tile(x, (2 * n, 1))
    idx = np.arange(n)
    points[idx, idx] = high_point
    points[n + idx, idx] = low_point
    # Guard the rounding of low_point + 2h against the upper bound.
    np.clip(points, lo, hi, out=points)
    steps = points[idx, idx] - points[n + idx, idx]
    return points, steps


def central_difference(
    fun_batch: Callable[[Array], ArrayLike],
    x: ArrayLike,
    h: ArrayLike = 0.025,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
) -> Array:
    """Central-difference gradient or Jacobian from one batch evaluation.

    Parameters
    ----------
    fun_batch : callable
        Maps points (m, n) to values (m,) or (m, k); called once with the
        2n stencil points of :func:`central_difference_points`.
    x : array_like, shape (n,)
        Point at which the derivative is wanted.
    h : float or array_like, shape (n,)
        Stencil half-width in the units of x.
    lower, upper : array_like, shape (n,), optional
        Bounds that the stencil respects.

    Returns
    -------
    ndarray
        Gradient (n,) for scalar outputs, Jacobian (k, n) for vector outputs.
    """
    points, steps = central_difference_points(x, h, lower, upper)
    n = steps.size
    values = np.asarray(fun_batch(points), dtype=float)
    if values.shape[:1] != (2 * n,) or values.ndim > 2:
        raise ValueError(
            f'fun_batch must return shape ({2 * n},) or ({2 * n}, k), got {values.shape}'
        )
    diff = (values[:n] - values[n:]) / (steps if values.ndim == 1 else steps[:, None])
    return diff if values.ndim == 1 else diff.T


def batch_from_pointwise(fun: Callable[[Array], ArrayLike]) -> Callable[[Array], Array]:
    """Wrap a one-point function ``fun(x)`` as a batch function over rows.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> float or (k,)`` for one point x (n,).

    Returns
    -------
    callable
        ``batch(points (m, n)) -> (m,) or (m, k)``.
    """

    def batch(points: Array) -> Array:
        return np.array([np.asarray(fun(p), dtype=float) for p in points])

    return batch
