"""Real-time factor of the full vehicle model (simulated seconds per wall second).

Prints ``name: value`` lines: for each scenario and integrator (the fixed-step RK4 kernel,
and the variable-step Dormand-Prince 5(4) one at config/vehicle.yaml's tolerances), one
design alone and 32 designs in one batch (per-design factor = batch x simulated time /
wall time).  The fixed-step lines keep their names; the variable-step ones contain
``variable_step``.  The first call compiles
(or loads from cache) the numba kernel; its time is printed separately and excluded.

Run: .venv/bin/python benchmarks/bench_vehicle.py
"""

from __future__ import annotations

import time

import numpy as np

from suspension_tuning.vehicle import scenarios
from suspension_tuning.vehicle.params import load_vehicle_params

TARGET_SINGLE = 100.0  # [-] issue: >= 100x real time for one design
TARGET_BATCH = 1000.0  # [-] issue: >= 1000x real time per design in a batch of 32
BATCH = 32
REPEATS = 3


def best_wall(name: str, x: np.ndarray, params, integrator: str) -> tuple[float, float]:
    walls, sim = [], 0.0
    for _ in range(REPEATS):
        res = scenarios.run_scenario(name, x, params, integrator=integrator)
        walls.append(res.wall_time_s)
        sim = res.simulated_time_s
    return min(walls), sim


def main() -> None:
    params = load_vehicle_params()
    t0 = time.perf_counter()
    scenarios.run_scenario('handling', np.array([0.5, 0.5]), params)
    print(f'first_call_incl_compile_or_cache_load_s: {time.perf_counter() - t0:.2f}')
    t0 = time.perf_counter()
    scenarios.run_scenario('handling', np.array([0.5, 0.5]), params, integrator='variable_step')
    print(f'variable_step_first_call_incl_compile_or_cache_load_s: '
          f'{time.perf_counter() - t0:.2f}')
    rng = np.random.default_rng(0)
    xb = rng.uniform(0.001, 1.0, size=(BATCH, 2))
    for integrator, tag in (('fixed_step', ''), ('variable_step', '_variable_step')):
        for name in scenarios.SCENARIOS:
            wall1, sim = best_wall(name, np.array([0.5, 0.5]), params, integrator)
            wallb, _ = best_wall(name, xb, params, integrator)
            print(f'{name}{tag}_simulated_s: {sim:.2f}')
            print(f'{name}{tag}_single_wall_s: {wall1:.4f}')
            print(f'{name}{tag}_single_rtf: {sim / wall1:.0f}')
            print(f'{name}{tag}_batch{BATCH}_wall_s: {wallb:.4f}')
            print(f'{name}{tag}_batch{BATCH}_rtf_per_design: {BATCH * sim / wallb:.0f}')
    print(f'target_single_rtf: {TARGET_SINGLE:.0f}')
    print(f'target_batch_rtf_per_design: {TARGET_BATCH:.0f}')


if __name__ == '__main__':
    main()
