"""First-order multi-fidelity correction of the simplified models' gradients.

The eq. 25 scaling (Thoresson et al. 2009, section 6.3.1) maps each simplified
function onto the full model's range with one factor fitted over the whole design
space.  Locally the slopes still differ: on the 4-variable ride, at the tyre-hop
boundary where the optimum lies, the full model's eq. 11 constraint of the rear
tyres changes 1.8-2.2 times as fast along the rear damping as the scaled simplified
one, and the front's 1.3-1.5 times along the front damping, while both point the
same way (cosine >= 0.995).  Along the active boundary the descent direction is then
wrong (cosine to the full model's as low as 0.04), and every step back to
feasibility overshoots by about 100 %.

:class:`SecantCorrection` learns that local difference from the full runs the
optimiser makes anyway, one per iterate, and adds no full run.  With F the full
model's values (objective, constraints) and S the eq. 25-scaled simplified values at
the same design, the discrepancy ``D(x) = F(x) - S(x)`` is known at every iterate.
Its Jacobian C is estimated by Broyden's rank-one secant update along each step
``s = x_k - x_{k-1}``, ``y = D(x_k) - D(x_{k-1})``::

    C <- C + (y - C s) s^T / (s^T s)

starting from C = 0 (eq. 25 alone), and the gradients given to the optimiser are
those of the corrected model ``S + D(x_k) + C (x - x_k)``: ``grad S + C``.  This is
the first-order additive correction of multi-fidelity optimisation (Eldred,
Giunta and Collis 2004, as in Dakota's ``correction additive first_order``), with
the high-fidelity gradient, which would cost 2n full runs, replaced by the secant
estimate that Broyden's method builds from values alone.

Choices [E], with the reasons:

* Additive, not multiplicative: the mismatch is a slope ratio along some directions
  and not others (the ratio differs per variable), which a per-function factor (a
  local eq. 25) cannot represent; an additive Jacobian correction can.  Measured on
  the 4-variable ride from 6 starts, the additive secant brought the best feasible
  design within 0.16 % of the reference from every start, where a per-function
  factor fitted to the steps did not remove the zig-zag.
* Noise guard: a step shorter than ``min_step`` (normalised units) is not used.  Over
  a short step the change of D is mostly the full model's numerical noise and the
  count structure of eq. 11 (a step of 1e-4 changes eq. 11 by 0 or by 7.4e-4), and
  dividing it by the short step would give slopes of any size.  0.004 is 0.16 of
  the gradients' central-difference half step (0.025) and 4 times the move limit
  below which Dynamic-Q stops (1e-3).
* Rows without a simplified model (extra constraints whose gradients come from
  full-model central differences) are exact already and are left alone.
* Variables no simplified model sees (an anti-roll bar in the pitch-plane model: the
  column of the simplified Jacobian is exactly zero in every row) would never be
  learnt: the optimiser never steps along them, so no secant has a component there.
  Their columns are seeded once, at the first corrected gradient, with a one-sided
  full-model difference of the discrepancy (one full run per such variable, counted;
  :meth:`SecantCorrection.seed_column`), and the secant updates refine them from then
  on.  Option ``seed_blind`` (default true).
* A bound decided by the correction alone is checked.  Broyden's estimate never
  forgets: a column learnt over long steps far away can reverse the sign of the
  simplified slope at a bound, and there the optimiser stops (the bound-KKT or the xtol
  test) without ever stepping inward, so no secant can correct it.  On the 8-variable
  handling case with 16 calibration samples, 2 of 6 starts stopped at the soft end of
  both compression scale factors, 8.8 % above the reference, although the simplified
  slope and the full model's both point to the stiff end.  So where a variable sits on
  a bound, the simplified slope of the objective points inward and the corrected one
  outward, one full run at ``x + seed_step`` inward sets that column from the full
  model (:meth:`SecantCorrection.seed_column` with the simplified slope), once per
  variable and bound in a run.  Option ``verify_bounds`` (default true).
* At a restart, the variables the simplified models see poorly are set from the full
  model.  A restart (``restarts``) starts the correction afresh, C = 0, so the run goes
  back to the simplified slopes that led it where it stalled.  Where the stalled run's
  correction of the objective's slope along a variable exceeded ``reseed_ratio`` times
  the simplified slope there (:func:`poorly_seen`), that column is set from the full
  model: a central difference of step ``seed_step``, two full runs (one-sided, one run,
  where the box leaves no room).  Central, because a stale Broyden column can pick a
  variable that sits near its own optimum, where a one-sided step of 0.1 errs by as
  much as the slope itself.  On the 8-variable ride with the roll-and-pitch model these
  are the anti-roll bars (both, or the front one) and no other variable, at each of
  the 7 restarts logged.  At lhs1's answer the model's slope
  of the rear-left eq. 11 row along the rear bar is twice the full model's (-0.113
  against -0.059), so that along the active boundary the rear bar's reduced slope of f
  has the wrong sign; the run had stiffened the rear bar from 0.11 to 0.75 (the
  reference has 0.40), and its restart at C = 0 ended at the same 2.13 %.  Fixed-step
  model, the 6 benchmark starts and 18 more: 20 of 24 solved without, 23 with
  (docs/corrected_gradients.md).
* A continuation on the check's model keeps the poorly seen columns.  A run the noise
  test ended (or whose answer the check refused, or that converged away from its
  answer) goes on on the check's model with a correction of its own, since the one it
  learnt holds the other model's noise.  Its poorly seen columns, though, say what the
  simplified models miss, which both full models share, and the run did not stall on
  them: they are kept (``carry_to_check``, :meth:`SecantCorrection.carry_columns`, no
  full run), the other columns start at zero.  Started at zero, the 8-variable noisy
  ride from lhs1 went back to the roll-and-pitch model's rear-bar slope: on the check's
  model it stiffened the rear bar to 0.69 (the reference has 0.40) and crept for 53
  iterations 1.2 % above the reference.  Noisy model, the 6 benchmark starts: 8
  variables 6 of 6 solved with, 5 of 6 without; 4 variables 29 paid full runs (median)
  either way.  Setting those columns from the check's model instead (central
  differences, 2 runs a column) also solves all 6 but costs the 4-variable ride,
  whose correction overrules the pitch-plane model in most columns, 48.5 paid.

* Off where the full model's objective jumps (``off_for_scenarios``, default the
  'mixed' scenario).  In the mixed scenario the valve controller decides, from the
  vehicle's state, how often the 4S4 switches between its states, and a small change
  of the design can add a switch pair: the objective then jumps.  At the two-state
  reference (docs/design_space.md) a move of -0.025 in 6 of the 8 variables adds one
  (8 to 10 switches), and the closed-loop central difference of f along the front
  high-state damping is 32 times the one with the valve history held (-0.353 and
  -0.011; ``studies.two_state.valve_jumps``).  A secant over a step
  that crosses such a jump learns the jump as a slope, and Broyden's estimate keeps
  it.  Two-state mixed case, 8 variables, from 24 starts (the benchmark's 6 and 18
  more): without the correction 6 solved and 13 within 5 % on the fixed-step model, 8
  and 18 on the noisy one; with it 3 and 6, 1 and 4.  A gate that uses a function's
  correction only while it predicts the steps' changes of D better than none (5 and
  13, 4 and 8) cost the 4-variable ride runs (24 starts: 21 solved, median 15.5 full
  runs, against 23 and 14) and was not kept.

References
----------
Broyden, C.G. (1965), "A class of methods for solving nonlinear simultaneous
equations", Mathematics of Computation 19, 577-593.
Eldred, M.S., Giunta, A.A. & Collis, S.S. (2004), "Second-order corrections for
surrogate-based optimization with model hierarchies", AIAA 2004-4457.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from suspension_tuning.optim._options import options_from_mapping

Array = NDArray[np.float64]

#: Values of ``CorrectionOptions.method``.
CORRECTION_METHODS = ('secant', 'none')
#: Stop tests a corrected run may restart after (``CorrectionOptions.restart_after``;
#: Dynamic-Q's ``stop_test`` names), each in the words of a restarted run's message.
RESTART_CAUSES = {'maxiter': 'at the iteration limit', 'ftol': 'after the ftol test',
                  'xtol': 'after the xtol test', 'noise': 'after the noise test',
                  'rho_min': 'at the smallest move limit',
                  'bound_kkt': 'after the bound KKT test'}
#: Their names.
RESTARTABLE_STOPS = tuple(RESTART_CAUSES)


@dataclass(frozen=True)
class CorrectionOptions:
    """Options of the simplified-gradient correction (config/optimiser.yaml).

    Attributes
    ----------
    method : str
        'secant' (Broyden's update of the discrepancy's Jacobian, module notes) or
        'none' (the eq. 25-scaled simplified gradients as they are, the paper's method).
    min_step : float
        Steps shorter than this (Euclidean norm, normalised design units) do not
        update the correction [E: 0.004, module notes].
    seed_blind : bool
        Seed the columns of variables no simplified model sees with a one-sided
        full-model difference at the first corrected gradient (module notes).
    seed_step : float
        The step of that difference, normalised units [E: 0.1, config/optimiser.yaml].
    verify_bounds : bool
        Check with one full run each a bound that the correction alone decides (module
        notes).
    off_for_scenarios : tuple of str
        Scenarios optimised without the correction, whatever ``method`` says: those
        whose full-model objective jumps with the design (module notes; 'mixed').
    restarts : int
        A corrected run that ends by one of ``restart_after`` starts again from its
        answer this many times at most, the correction started afresh there (a blind
        variable's column seeded again) and Dynamic-Q with its first move limit
        [E: 1, config/optimiser.yaml]; over a set of operating conditions every
        condition's correction starts afresh (at C = 0, without ``reseed_ratio``).
    reseed_ratio : float
        At a restart, a variable whose learnt correction of the objective's slope
        exceeded this multiple of the simplified slope at the answer gets its column
        set from the full model, a central difference of step ``seed_step`` (module
        notes, :func:`poorly_seen`) [E: 0.5, config/optimiser.yaml]; 0 sets none.
    carry_to_check : bool
        A continuation on the check's model (``tuning.optimise``'s ``check_model``,
        continue_by 'tighter_model') keeps the columns of the variables the run's
        correction found poorly seen (:func:`poorly_seen` with ``reseed_ratio``) and
        starts the others afresh; no full run (module notes) [E: true,
        config/optimiser.yaml].  False: every column afresh, C = 0.
    restart_after : tuple of str
        The stop tests (:data:`RESTARTABLE_STOPS`) after which a corrected run restarts
        [E: 'maxiter' and 'ftol', config/optimiser.yaml]: the iteration limit, and the
        ftol test, which passes when f stalls while the steps are still longer than
        xtol, as on a run creeping along the eq. 11 staircase.
    """

    method: str = 'secant'
    min_step: float = 0.004
    seed_blind: bool = True
    seed_step: float = 0.1
    verify_bounds: bool = True
    off_for_scenarios: tuple[str, ...] = ('mixed',)
    restarts: int = 1
    restart_after: tuple[str, ...] = ('maxiter', 'ftol')
    reseed_ratio: float = 0.5
    carry_to_check: bool = True

    def __post_init__(self) -> None:
        """Check the method, the steps and the restarts."""
        if self.method not in CORRECTION_METHODS:
            raise ValueError(f'correction method must be one of '
                             f'{", ".join(CORRECTION_METHODS)}, got {self.method!r}')
        if not (isinstance(self.min_step, int | float) and np.isfinite(self.min_step)
                and self.min_step >= 0):
            raise ValueError(f'correction min_step must be finite and >= 0, got '
                             f'{self.min_step!r}')
        if not (isinstance(self.seed_step, int | float) and np.isfinite(self.seed_step)
                and 0 < self.seed_step <= 0.5):
            raise ValueError(f'correction seed_step must be in (0, 0.5], got '
                             f'{self.seed_step!r}')
        if not (isinstance(self.reseed_ratio, int | float)
                and not isinstance(self.reseed_ratio, bool)
                and np.isfinite(self.reseed_ratio) and self.reseed_ratio >= 0):
            raise ValueError(f'correction reseed_ratio must be finite and >= 0, got '
                             f'{self.reseed_ratio!r}')
        if not isinstance(self.carry_to_check, bool):
            raise ValueError(f'correction carry_to_check must be true or false, got '
                             f'{self.carry_to_check!r}')
        if isinstance(self.restarts, bool) or not isinstance(self.restarts, int) \
                or self.restarts < 0:
            raise ValueError(f'correction restarts must be an integer >= 0, got '
                             f'{self.restarts!r}')
        names = self.off_for_scenarios
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise ValueError(f'correction off_for_scenarios must be a list of scenario '
                             f'names, got {names!r}')
        object.__setattr__(self, 'off_for_scenarios', tuple(names))
        stops = self.restart_after
        if isinstance(stops, str) or not all(s in RESTARTABLE_STOPS for s in stops):
            raise ValueError(f'correction restart_after must be a list of stop tests '
                             f'({", ".join(RESTARTABLE_STOPS)}), got {stops!r}')
        object.__setattr__(self, 'restart_after', tuple(stops))

    def restarts_after(self, stop_test: str, done: int) -> bool:
        """Whether a corrected run that ended by ``stop_test`` restarts from its answer.

        ``done``: how often it has restarted already (at most :attr:`restarts` in all).
        """
        return done < self.restarts and stop_test in self.restart_after

    def applies_to(self, scenario: str) -> bool:
        """Whether a run of ``scenario`` with simplified gradients is corrected."""
        return self.method != 'none' and scenario not in self.off_for_scenarios

    @classmethod
    def from_mapping(cls, options: CorrectionOptions | Mapping[str, Any] | None
                     ) -> CorrectionOptions:
        """Build options from a mapping; unknown keys raise ValueError."""
        return options_from_mapping(cls, options, 'correction')

    def as_dict(self) -> dict[str, Any]:
        """The options as a plain dict (records, run configurations)."""
        out = asdict(self)
        out['off_for_scenarios'] = list(self.off_for_scenarios)
        out['restart_after'] = list(self.restart_after)
        return out


def poorly_seen(previous: ArrayLike, simplified: ArrayLike, ratio: float) -> NDArray[np.intp]:
    """Variables whose simplified objective slope a stalled run's correction overruled.

    Parameters
    ----------
    previous : array_like, shape (k, n)
        The correction C of the run that stopped (objective row first).
    simplified : array_like, shape (k, n)
        The eq. 25-scaled simplified Jacobian at the restart's first design.
    ratio : float
        :attr:`CorrectionOptions.reseed_ratio`; 0 or less selects none.

    Returns
    -------
    ndarray of int
        Columns j with ``|C[0, j]| > ratio |S[0, j]|`` and a non-zero simplified column
        (a column that is zero in every row is a blind variable's, seeded anyway).
    """
    c = np.asarray(previous, dtype=float)
    s = np.asarray(simplified, dtype=float)
    if c.shape != s.shape or c.ndim != 2:
        raise ValueError(f'correction: previous {c.shape} and simplified {s.shape} '
                         f'Jacobians must have one 2-D shape')
    if not ratio > 0.0:
        return np.zeros(0, dtype=np.intp)
    seen = np.any(s != 0.0, axis=0)
    return np.flatnonzero(seen & (np.abs(c[0]) > ratio * np.abs(s[0])))


def load_correction_options(path: str) -> CorrectionOptions:
    """The ``simplified_correction`` section of an optimiser file (config/optimiser.yaml).

    A file without the section gives the defaults.
    """
    import yaml

    with open(path, encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    if not isinstance(data, dict):
        raise ValueError(f'{path}: not a mapping of sections')
    return CorrectionOptions.from_mapping(data.get('simplified_correction'))


class SecantCorrection:
    """Broyden estimate of the Jacobian of ``D = F - S`` (full minus scaled simplified).

    Parameters
    ----------
    n_functions : int
        Number of functions: the objective and the constraints (rows).
    n_vars : int
        Number of design variables (columns).
    min_step : float
        Shortest step that updates the estimate, units of x.

    Notes
    -----
    Call :meth:`observe` at every design where both models' values are known, in the
    order of the optimiser's iterates; :meth:`correct` adds the current estimate to a
    simplified Jacobian.  A row whose simplified value is NaN (no simplified model for
    that function) is never corrected.
    """

    def __init__(self, n_functions: int, n_vars: int, min_step: float = 0.004) -> None:
        self.jacobian = np.zeros((int(n_functions), int(n_vars)))
        self.min_step = float(min_step)
        self.n_updates = 0
        self.n_short_steps = 0
        self.seeded: list[int] = []
        self.carried: list[int] = []
        self._last: tuple[Array, Array] | None = None

    def seed_column(self, j: int, x: ArrayLike, step: float, full_at_x: ArrayLike,
                    full_at_step: ArrayLike, simplified_at_x: ArrayLike,
                    simplified_slope: ArrayLike | None = None) -> None:
        """Set column j from a full run at ``x + step e_j``: D's slope along j is the
        full model's one-sided difference minus the simplified slope (zero, the default,
        for a variable the simplified models do not see).

        Rows without a simplified model (NaN in ``simplified_at_x``) stay zero.
        """  # noqa: D205
        full0 = np.asarray(full_at_x, dtype=float)
        full1 = np.asarray(full_at_step, dtype=float)
        simp = np.asarray(simplified_at_x, dtype=float)
        slope = (np.zeros_like(full0) if simplified_slope is None
                 else np.asarray(simplified_slope, dtype=float))
        if (float(step) == 0.0 or full0.shape != full1.shape or full0.shape != simp.shape
                or slope.shape != full0.shape):
            raise ValueError('correction: seed needs a non-zero step and values of one shape')
        self.jacobian[:, int(j)] = np.where(np.isfinite(simp),
                                            (full1 - full0) / step - slope, 0.0)
        self.seeded.append(int(j))

    def carry_columns(self, columns: ArrayLike, previous: ArrayLike) -> None:
        """Take ``columns`` of ``previous``, the correction of the run continued here.

        Parameters
        ----------
        columns : array_like of int
            The variables whose columns are kept (:func:`poorly_seen`).
        previous : array_like, shape (k, n)
            That run's correction C, of this estimate's shape.
        """
        c = np.asarray(previous, dtype=float)
        if c.shape != self.jacobian.shape:
            raise ValueError(f'correction: a carried correction {c.shape} must have the '
                             f'shape {self.jacobian.shape}')
        cols = np.asarray(columns, dtype=int).reshape(-1)
        self.jacobian[:, cols] = c[:, cols]
        self.carried.extend(int(j) for j in cols)

    def observe(self, x: ArrayLike, full_values: ArrayLike, simplified_values: ArrayLike
                ) -> bool:
        """Take the discrepancy at x; update along the step from the previous design.

        Parameters
        ----------
        x : array_like, shape (n,)
            Design, normalised.
        full_values, simplified_values : array_like, shape (k,)
            Full-model values and eq. 25-scaled simplified values at x (objective,
            then constraints); NaN in ``simplified_values`` marks a row without a
            simplified model.

        Returns
        -------
        bool
            Whether the estimate was updated.
        """
        x = np.asarray(x, dtype=float)
        full = np.asarray(full_values, dtype=float)
        simp = np.asarray(simplified_values, dtype=float)
        if full.shape != simp.shape or full.shape != (self.jacobian.shape[0],):
            raise ValueError(f'correction: {self.jacobian.shape[0]} values expected, got '
                             f'{full.shape} full and {simp.shape} simplified')
        d = np.where(np.isfinite(simp), full - simp, 0.0)
        updated = False
        if self._last is not None:
            x_last, d_last = self._last
            s = x - x_last
            ss = float(s @ s)
            if ss > 0.0 and np.sqrt(ss) >= self.min_step:
                y = d - d_last
                self.jacobian += np.outer(y - self.jacobian @ s, s) / ss
                self.jacobian[~np.isfinite(simp)] = 0.0
                self.n_updates += 1
                updated = True
            else:
                self.n_short_steps += 1
        self._last = (x.copy(), d)
        return updated

    def correct(self, jacobian: ArrayLike) -> Array:
        """The simplified Jacobian (k, n) plus the current estimate."""
        jac = np.asarray(jacobian, dtype=float)
        if jac.shape != self.jacobian.shape:
            raise ValueError(f'correction: Jacobian of shape {self.jacobian.shape} '
                             f'expected, got {jac.shape}')
        return jac + self.jacobian

    def summary(self) -> dict[str, Any]:
        """Updates made, short steps skipped and the estimate (for results and bags)."""
        return {'method': 'secant', 'min_step': self.min_step, 'n_updates': self.n_updates,
                'n_short_steps': self.n_short_steps, 'seeded_columns': list(self.seeded),
                'carried_columns': list(self.carried),
                'jacobian': self.jacobian.tolist()}
