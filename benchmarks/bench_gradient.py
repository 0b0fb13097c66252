"""Cost of one simplified-model gradient against one full-model run (paper section 2).

The paper: 2n simplified runs per gradient, each ~10 % of a full run, so a gradient costs
0.2 n full runs (0.8 for n = 4).  Issue target: one gradient with n = 4 (8 simplified
runs in one batch, eq. 25-scaled) costs at most 0.2 of one full-model run.

Prints ``name: value`` lines per scenario (ride, handling):

* ``<scenario>_full_run_s`` - best (minimum) wall time of ``run_scenario`` for one design
  (set-up, simulation and metrics: what one optimisation iteration pays);
* ``<scenario>_full_sim_only_s`` - the full model's own simulation time of that run;
* ``<scenario>_gradient_s`` - best (minimum) wall time of one ``SimplifiedGradient`` call at the
  centre (n = 4: 8 simplified runs, metrics, scaling);
* ``<scenario>_gradient_to_full_run_ratio`` and ``..._to_full_sim_only_ratio``;

and ``gradient_to_full_run_ratio`` (the larger of the two scenarios' ratios).  The first
calls (numba compile or cache load) are excluded.  Minimum over interleaved repeats: the
machine is shared, and the minimum is the least disturbed estimate of both costs.  Both
models run their batch with numba ``prange`` over designs (the full model's single
design cannot use it; the 8-design gradient can).

Run: .venv/bin/python benchmarks/bench_gradient.py
"""

from __future__ import annotations

import time

import numpy as np

from suspension_tuning.optim.scaling import fit_scaling
from suspension_tuning.optim.simplified_gradient import SimplifiedGradient
from suspension_tuning.vehicle.scenarios import run_scenario

N_VARS = 4
REPEATS = 40
TARGET = 0.2  # [-] one n = 4 gradient <= 0.2 full-model runs


def unit_scaling(scenario: str):
    """An eq. 25 scaling (costs the same to apply as a calibrated one)."""
    x = np.array([[0.1] * N_VARS, [0.9] * N_VARS])
    v = np.array([[0.0, -1, -1, -1, -1], [1.0, -0.5, -0.5, -0.5, -0.5]])
    return fit_scaling(x, v, v, key={'scenario': scenario, 'n_vars': N_VARS})


def main() -> None:
    x = np.full(N_VARS, 0.5005)
    ratios = []
    for scenario in ('ride', 'handling'):
        full = run_scenario(scenario, x[None])  # warm-up (compile / cache load)
        grad = SimplifiedGradient(scenario, N_VARS, unit_scaling(scenario))
        grad(x, full)  # warm-up
        full_walls, sim_walls, grad_walls = [], [], []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            full = run_scenario(scenario, x[None])
            full_walls.append(time.perf_counter() - t0)
            sim_walls.append(full.wall_time_s)
            t0 = time.perf_counter()
            grad(x, full)
            grad_walls.append(time.perf_counter() - t0)
        f_run = min(full_walls)
        f_sim = min(sim_walls)
        g = min(grad_walls)
        ratios.append(g / f_run)
        print(f'{scenario}_full_run_s: {f_run:.4f}')
        print(f'{scenario}_full_sim_only_s: {f_sim:.4f}')
        print(f'{scenario}_gradient_s: {g:.4f}')
        print(f'{scenario}_simplified_runs_per_gradient: {2 * N_VARS}')
        print(f'{scenario}_gradient_to_full_run_ratio: {g / f_run:.3f}')
        print(f'{scenario}_gradient_to_full_sim_only_ratio: {g / f_sim:.3f}')
    print(f'gradient_to_full_run_ratio: {max(ratios):.3f}')
    print(f'target_gradient_to_full_run_ratio: {TARGET}')
    print('paper_gradient_to_full_run_ratio: 0.8')


if __name__ == '__main__':
    main()
