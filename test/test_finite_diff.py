"""Tests of the batch central differences that stay inside the bounds (physics-reference 1.8)."""

import numpy as np
import pytest

from suspension_tuning.optim.finite_diff import (
    batch_from_pointwise,
    central_difference,
    central_difference_points,
)

LOWER = np.array([0.001, 0.001])  # paper eq. 6: normalised design-variable bounds
UPPER = np.array([1.0, 1.0])


def test_interior_stencil_is_symmetric():
    points, steps = central_difference_points([0.5, 0.4], 0.025, LOWER, UPPER)
    # Rows 0, 1: x + h e_i; rows 2, 3: x - h e_i (h = 0.025, the default [E]).
    np.testing.assert_allclose(
        points, [[0.525, 0.4], [0.5, 0.425], [0.475, 0.4], [0.5, 0.375]], atol=1e-15
    )
    np.testing.assert_allclose(steps, [0.05, 0.05], atol=1e-15)


def test_stencil_shifts_inside_at_bounds():
    # At the lower bound the pair becomes [x, x + 2h]; at the upper bound [x - 2h, x].
    points, steps = central_difference_points([0.001, 1.0], 0.025, LOWER, UPPER)
    np.testing.assert_allclose(points[0], [0.051, 1.0])
    np.testing.assert_allclose(points[2], [0.001, 1.0])
    np.testing.assert_allclose(points[1], [0.001, 1.0])
    np.testing.assert_allclose(points[3], [0.001, 0.95])
    np.testing.assert_allclose(steps, [0.05, 0.05])
    assert np.all(points >= LOWER) and np.all(points <= UPPER)


def test_box_narrower_than_stencil_uses_whole_box():
    points, steps = central_difference_points([0.5], 0.1, [0.45], [0.55])
    np.testing.assert_allclose(points[:, 0], [0.55, 0.45])
    np.testing.assert_allclose(steps, [0.1])


def test_central_difference_is_exact_for_quadratics():
    # f = 3 x1^2 + x1 x2: central differences are exact for quadratics, so the
    # gradient at (0.5, 0.4) is (6 x1 + x2, x1) = (3.4, 0.5) to rounding.
    def batch(points):
        return 3.0 * points[:, 0] ** 2 + points[:, 0] * points[:, 1]

    np.testing.assert_allclose(
        central_difference(batch, [0.5, 0.4], 0.025, LOWER, UPPER), [3.4, 0.5], rtol=1e-12
    )


def test_shifted_stencil_gives_midpoint_derivative():
    # At x1 = 0.001 the pair [0.001, 0.051] gives the derivative of x1^2 at its
    # midpoint 0.026: 2 x 0.026 = 0.052 (first-order at the bound, as accepted [E]).
    grad = central_difference(lambda p: p[:, 0] ** 2, [0.001, 0.5], 0.025, LOWER, UPPER)
    np.testing.assert_allclose(grad, [0.052, 0.0], atol=1e-12)


def test_vector_output_gives_jacobian():
    # F = (x1 + 2 x2, x1 x2): Jacobian at (0.5, 0.4) = [[1, 2], [0.4, 0.5]].
    jac = central_difference(
        batch_from_pointwise(lambda x: [x[0] + 2.0 * x[1], x[0] * x[1]]),
        [0.5, 0.4],
        0.025,
        LOWER,
        UPPER,
    )
    np.testing.assert_allclose(jac, [[1.0, 2.0], [0.4, 0.5]], rtol=1e-12)


def test_bad_input_raises_value_error():
    with pytest.raises(ValueError, match='outside the bounds'):
        central_difference_points([1.5, 0.5], 0.025, LOWER, UPPER)
    with pytest.raises(ValueError, match='finite'):
        central_difference_points([np.nan, 0.5], 0.025, LOWER, UPPER)
    with pytest.raises(ValueError, match='step h'):
        central_difference_points([0.5, 0.5], 0.0, LOWER, UPPER)
    with pytest.raises(ValueError, match='lower < upper'):
        central_difference_points([0.5, 0.5], 0.025, UPPER, LOWER)
    with pytest.raises(ValueError, match='must return shape'):
        central_difference(lambda p: np.zeros(3), [0.5, 0.5], 0.025, LOWER, UPPER)
