"""Numerical noise of the full model under both integrators and of the simplified model.

Paper sections 4.1 and 6 (Figs 7-8): the multibody full model "exhibits severe numerical
noise", the simplified models are much smoother.  For each scenario, x1 is swept finely
through the centre of the design space (41 points, step 0.005, config/simplified_models.yaml
``noise_study``) with the full model integrated by the fixed-step RK4 kernel and by the
variable-step Dormand-Prince 5(4) integrator (config/vehicle.yaml
``integration.variable_step``, rtol = atol = 1e-3, Adams' default integrator error), and
with the simplified model.  Noise = standard deviation of the third differences / sqrt(20)
(``studies.noise.noise_measure``).

Prints ``name: value`` lines; the ride lines without a scenario prefix are the headline:

- ``noise_ratio_variable_to_fixed_<fn>``: variable-step noise over fixed-step noise (same
  units);
- ``noise_ratio_simplified_to_variable_<fn>``: the simplified model's relative noise (noise
  over its trend's range, unchanged by the linear eq. 25 scaling) over the variable-step
  full model's;

for fn = f and the tyre-hop constraints g_fl..g_rr (eq. 11).  A constraint that stays at
-1 (no tyre ever lifts off over the sweep) has no noise in either model: its ratio is nan.

Run: .venv/bin/python benchmarks/bench_noise.py
"""

from __future__ import annotations

import time

import numpy as np

from suspension_tuning.optim.scaling import FUNCTION_NAMES
from suspension_tuning.studies.noise import sweep_x1

TARGET_VARIABLE_TO_FIXED = 100.0  # [-] target: variable-step noise >= 100x fixed-step noise


def main() -> None:
    t0 = time.perf_counter()
    for scenario in ('ride', 'handling'):
        res = sweep_x1(scenario, None, 2, variable_step=True)
        prefix = '' if scenario == 'ride' else 'handling_'
        for model in ('full', 'full_variable_step', 'simplified'):
            m = res['noise'][model]['f']
            print(f'{scenario}_{model}_f_noise_rms: {m["noise_rms"]:.3e}')
            print(f'{scenario}_{model}_f_noise_rel: {m["noise_rel"]:.3e}')
        for key in ('noise_ratio_variable_to_fixed', 'noise_ratio_simplified_to_variable'):
            for name in FUNCTION_NAMES:
                print(f'{prefix}{key}_{name}: {res[key][name]:.3e}')
        g = np.asarray(res['full_variable_step'])[:, 1:]
        print(f'{scenario}_variable_step_g_max_over_sweep: {np.max(g):.4f}')
    print(f'target_noise_ratio_variable_to_fixed_f: {TARGET_VARIABLE_TO_FIXED:.0f}')
    print(f'bench_noise_wall_s: {time.perf_counter() - t0:.1f}')


if __name__ == '__main__':
    main()
