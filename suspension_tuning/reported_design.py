"""The design an optimisation run reports: the best feasible iterate it has seen.

Dynamic-Q's result keeps SciPy's meaning of ``x``: the last iterate.  On the vehicle
problems the eq. 11 tyre-hop constraints are active and a run may end on an infeasible
iterate after feasible, better ones, so the design a run reports is the best point
seen (``x_best``, ``f_best``, ``g_best``, ``best_iteration``, ``best_feasible``,
``max_violation_best`` of :func:`~suspension_tuning.optim.dynamic_q.dynamic_q`):
the feasible iterate (largest violation <= gtol) with the lowest f, or, when no
iterate was feasible, the one with the smallest violation, and then the report says
plainly that no feasible design was found.  The coordinator's action result, ``tune``,
the demo, ``inspect_bag`` and the studies all report this design; the last iterate
stays in the run's history.

Plain Python, no rclpy.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from suspension_tuning.optim.dynamic_q import CONVERGED_STATUSES

#: Joins the sentence on the reported design and Dynamic-Q's stop message in a result.
STOP_SEPARATOR = '; Dynamic-Q '


@dataclass(frozen=True)
class ReportedDesign:
    """The design a run reports, and whether it is feasible.

    Attributes
    ----------
    x : list of float
        Normalised design (eqs. 4-8).
    f : float
        Objective at x (full model).
    g : list of float
        Inequality constraints at x (<= 0 feasible).
    iteration : int
        The iteration whose design x is (index into the run's history).
    feasible : bool
        Every constraint holds at x to within the optimiser's gtol.
    max_violation : float
        max(0, max g) at x.
    constraint_values : list of float
        The extra constraints' quantities at x, their units (empty without any).
    """

    x: list[float]
    f: float
    g: list[float]
    iteration: int
    feasible: bool
    max_violation: float
    constraint_values: list[float] = field(default_factory=list)

    @property
    def statement(self) -> str:
        """One plain sentence: which iteration, or that no design was feasible."""
        return statement(self.feasible, self.iteration, self.max_violation)


def statement(feasible: bool, iteration: int, max_violation: float) -> str:
    """``'best feasible design: iteration k'`` or the plain "no feasible design" sentence."""
    if feasible:
        return f'best feasible design: iteration {int(iteration)}'
    return ('no feasible design found: the reported design is the least violating one '
            f'(max g = {float(max_violation):.4g}), iteration {int(iteration)}')




def design_success(result: Mapping[str, Any], design: ReportedDesign | None) -> bool:
    """A run succeeded when Dynamic-Q converged and the reported design is feasible.

    Dynamic-Q's own ``success`` judges the last iterate (SciPy's ``x``); on the eq. 11
    staircase a converged run may end one stair beyond the feasible point it reports.
    """
    return (design is not None and design.feasible
            and result.get('status') in CONVERGED_STATUSES)


def result_message(design: ReportedDesign | None, stop: str) -> str:
    """A result's message: the sentence on the reported design, then Dynamic-Q's stop.

    Without a reported design (no point was evaluated) the stop message alone.
    """
    if design is None:
        return stop
    return f'{design.statement}{STOP_SEPARATOR}{stop}'


def stop_message(message: str) -> str:
    """Dynamic-Q's own stop message out of a result message (the message itself if none)."""
    head, sep, tail = message.partition(STOP_SEPARATOR)
    return tail if sep else head


def reported_design(result: Mapping[str, Any]) -> ReportedDesign | None:
    """The reported design of a Dynamic-Q result (``tuning.optimise``, ``dynamic_q``).

    Returns
    -------
    ReportedDesign or None
        From the best-point fields; None when the run evaluated no point (cancelled
        before its first evaluation).
    """
    if 'x_best' not in result:
        return None
    return ReportedDesign(
        x=np.asarray(result['x_best'], float).tolist(),
        f=float(result['f_best']),
        g=np.asarray(result['g_best'], float).tolist(),
        iteration=int(result['best_iteration']),
        feasible=bool(result['best_feasible']),
        max_violation=float(result['max_violation_best']),
        constraint_values=[float(v) for v in result.get('constraint_values_best', [])],
    )


def best_record(records: Sequence[Mapping[str, Any]], gtol: float
                ) -> tuple[int, bool] | None:
    """The record Dynamic-Q would report among recorded iterates, by the same rule.

    For results recorded before the reported design was part of them: the record with
    the lowest f among those with ``max_violation <= gtol``, else the one with the
    smallest violation; the first of equal ones (Dynamic-Q keeps a point only when it
    is strictly better).

    Parameters
    ----------
    records : sequence of mappings
        Iteration records with ``f`` and ``max_violation``, in the order evaluated.
    gtol : float
        Feasibility tolerance of the run (its optimiser options' gtol).

    Returns
    -------
    (index, feasible) or None
        Index into ``records`` and whether that record is feasible; None for no records.
    """
    if not records:
        return None
    feasible = [k for k, r in enumerate(records) if float(r['max_violation']) <= gtol]
    if feasible:
        return min(feasible, key=lambda k: (float(records[k]['f']), k)), True
    return min(range(len(records)),
               key=lambda k: (float(records[k]['max_violation']), k)), False
