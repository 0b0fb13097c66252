"""Optimiser layer: Dynamic-Q with the LFOPC subproblem solver, central differences.

Plain Python, numpy and scipy; never imports rclpy.

Public API
----------
:func:`~suspension_tuning.optim.dynamic_q.minimize`
    Drop-in for ``scipy.optimize.minimize`` (SciPy constraint convention).
:func:`~suspension_tuning.optim.dynamic_q.dynamic_q`
    Paper convention (g <= 0 feasible) with a pluggable gradient source.
:class:`~suspension_tuning.optim.dynamic_q.DynamicQ`
    Ask/tell driver for callers that evaluate remotely or asynchronously.
:func:`~suspension_tuning.optim.lfopc.lfopc`, :func:`~suspension_tuning.optim.lfopc.lfop`
    Snyman's leap-frog solvers.
:func:`~suspension_tuning.optim.finite_diff.central_difference`
    Batch central differences kept inside the bounds.
"""

from suspension_tuning.optim.dynamic_q import (
    DynamicQ,
    DynamicQOptions,
    dynamic_q,
    load_options,
    minimize,
)
from suspension_tuning.optim.finite_diff import (
    batch_from_pointwise,
    central_difference,
    central_difference_points,
)
from suspension_tuning.optim.lfopc import LfopcResult, LfopOptions, LfopResult, lfop, lfopc

__all__ = [
    'DynamicQ',
    'DynamicQOptions',
    'LfopOptions',
    'LfopResult',
    'LfopcResult',
    'batch_from_pointwise',
    'central_difference',
    'central_difference_points',
    'dynamic_q',
    'lfop',
    'lfopc',
    'load_options',
    'minimize',
]
