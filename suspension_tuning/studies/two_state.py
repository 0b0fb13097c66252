"""The 4S4's two states tuned together on the mixed scenario: its configuration folder.

The 4S4 strut has a ride state (soft spring: both accumulators, low damping) and a
handling state (stiff spring: the small accumulator alone, high damping), and the
valve controller switches between them (paper section 3).  The paper tunes each state
on its own scenario; here the eight settings of both states (per axle: the soft and
the stiff gas volume, the low and the high damper scale factor) are one design, tuned
on the 'mixed' scenario (config/mixed.yaml: the Belgian paving, then the ISO 3888-1
double lane change at 65 km/h, the valves switched closed-loop with their 50-100 ms
delay), whose objective weighs ride and handling equally::

    f_mixed = (f_ride on the paving + f_hand in the lane change) / 2     (eqs. 9, 10)

subject to eq. 11 over the whole run.  Both terms are normalised to the paper's own
corner ranges (0.1-1 over the ranges of eqs. 9 and 10), so equal weights trade a
tenth of the paper's ride range for a tenth of its handling range; the ride-handling
front (docs/pareto.md) shows what another weighting would buy.

A design space offers one preset per size (config/design_space.yaml), and the
8-variable one is ``ride8``; the two-state design is another 8-variable preset, so it
lives in a configuration folder of its own: a copy of the package's ``config/`` whose
design_space.yaml presets ``two_state8`` and whose mixed.yaml paving is
:data:`MIXED_ROUGH_LENGTH_M` long.  Every node and command started with
``SUSPENSION_TUNING_CONFIG_DIR`` naming that folder reads it (``paths.config_dir``)::

    .venv/bin/python -m suspension_tuning.studies.two_state out/two_state_config
    export SUSPENSION_TUNING_CONFIG_DIR=$PWD/out/two_state_config
    .venv/bin/tune --scenario mixed --n-vars 8

This module imports nothing that reads the configuration at import time, so a
program may write the folder and set the variable before it imports the models.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.paths import config_dir

#: The two-state preset: per axle the ride state's soft gas volume and low-damping
#: dpsf, then the handling state's stiff gas volume and high-damping dpsf (targets of
#: config/design_space.yaml ``variables``).
PRESET_NAME = 'two_state8'
PRESET = ('gas_volume_soft_front', 'dpsf_low_front', 'gas_volume_stiff_front',
          'dpsf_high_front', 'gas_volume_soft_rear', 'dpsf_low_rear', 'gas_volume_stiff_rear',
          'dpsf_high_rear')
#: Paving length of the two-state runs, m [E]: 3 s of W_b settling plus 12 s of
#: averaging at 65 km/h (271 m), the 12 s the ride scenario's noise study averages over;
#: the 80 m of config/mixed.yaml leave 1.3 s of ride after the settling time.
MIXED_ROUGH_LENGTH_M = 271.0


def write_config(out: str | Path, rough_length_m: float = MIXED_ROUGH_LENGTH_M) -> Path:
    """Write the two-state configuration folder at ``out`` (replaced if it exists).

    A copy of the current configuration folder (``paths.config_dir``) with the
    ``presets`` section of design_space.yaml replaced by :data:`PRESET` and mixed.yaml's
    ``rough_length_m`` set to ``rough_length_m``; the comments of both stay.

    Returns
    -------
    Path
        The folder, absolute.
    """
    out = Path(out).expanduser().resolve()
    source = config_dir()
    if out == source:
        raise ValueError(f'{out} is the configuration folder itself: name another one')
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(source, out)
    space = (out / 'design_space.yaml').read_text()
    head = re.split(r'(?m)^# Designs beyond the paper\'s|^presets:', space)[0].rstrip()
    names = ',\n'.join(f'      {name}' for name in PRESET)
    (out / 'design_space.yaml').write_text(
        f'{head}\n\n# The 4S4\'s two states as one design (suspension_tuning.studies.two_state):'
        f'\n# per axle the ride state\'s soft gas volume and low-damping dpsf, then the\n'
        f'# handling state\'s stiff gas volume and high-damping dpsf.  Tuned on the mixed\n'
        f'# scenario, where the valve controller switches between the states.\n'
        f'presets:\n  {PRESET_NAME}: [\n{names}]\n')
    mixed = (out / 'mixed.yaml').read_text()
    # the key's line and the comment lines that continue it
    mixed, count = re.subn(r'(?m)^rough_length_m:.*\n(?:[ \t]+#.*\n)*',
                           f'rough_length_m: {float(rough_length_m):g}  # [m] [E] '
                           '3 s settling + 12 s of ride at 65 km/h (studies/two_state.py)\n',
                           mixed)
    if count != 1:
        raise ValueError(f'{source / "mixed.yaml"}: expected one rough_length_m line')
    (out / 'mixed.yaml').write_text(mixed)
    return out


def valve_jumps(x: Sequence[float], step: float = 0.025,
                integrator: str = 'fixed_step') -> dict[str, Any]:
    """Central differences of the mixed objective, closed loop and with the valves held.

    Each variable of the design ``x`` (normalised) is moved by ``-step`` and ``+step``
    (clipped to the box) and the mixed scenario run twice: closed loop (the valve
    controller decides, as in every run) and with the valve history of the run at
    ``x`` replayed, step for step, whatever the vehicle does.  The two differences
    part where a move makes the controller switch otherwise: the closed-loop objective
    jumps there (docs/design_space.md, the two-state case), which no simplified model
    and no secant update represents.

    Runs in the configuration folder of the process (``paths.config_dir``).

    Returns
    -------
    dict
        'names' of the variables, 'df_closed' and 'df_held' (n,) the central
        differences of f [1 per normalised unit], 'switches' (n, 2) the closed-loop
        valve switch counts at -step and +step, 'switches_at_x' and 'f_at_x'.
    """
    from suspension_tuning.vehicle.design import load_design_space
    from suspension_tuning.vehicle.mixed import run_mixed
    from suspension_tuning.vehicle.params import load_vehicle_params, with_integrator

    x = np.asarray(x, dtype=float)
    n = x.size
    params = with_integrator(load_vehicle_params(), integrator)
    base = run_mixed(x[None, :], params=params)
    log = base.valve_log[0].astype(int)
    lo, hi = np.maximum(x - step, 0.001), np.minimum(x + step, 1.0)
    designs = np.tile(x, (2 * n, 1))
    designs[np.arange(n), np.arange(n)] = lo
    designs[n + np.arange(n), np.arange(n)] = hi

    def held(k: int, _state: dict[str, Any]) -> tuple[int, int, int, int]:
        return tuple(int(v) for v in log[:, k])

    closed = run_mixed(designs, params=params)
    replayed = run_mixed(designs, controllers=[held] * len(designs), params=params)
    width = hi - lo
    switches = closed.metrics['valve_switches']
    return {'names': load_design_space().names(n),
            'df_closed': (closed.f[n:] - closed.f[:n]) / width,
            'df_held': (replayed.f[n:] - replayed.f[:n]) / width,
            'switches': np.column_stack([switches[:n], switches[n:]]),
            'switches_at_x': float(base.metrics['valve_switches'][0]),
            'f_at_x': float(base.f[0])}


def main(argv: list[str] | None = None) -> None:
    """``python -m suspension_tuning.studies.two_state DIR``: write the folder."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('out', type=Path, help='the folder to write (replaced if it exists)')
    parser.add_argument('--rough-length-m', type=float, default=MIXED_ROUGH_LENGTH_M,
                        help=f'paving length of the mixed runs, m (default '
                             f'{MIXED_ROUGH_LENGTH_M:g})')
    parser.add_argument('--valve-jumps', action='store_true',
                        help="then print, at the case's reference design "
                             '(benchmarks/references.json), the central differences of f '
                             'closed loop and with the valve history held (valve_jumps)')
    args = parser.parse_args(argv)
    path = write_config(args.out, args.rough_length_m)
    print(f'export SUSPENSION_TUNING_CONFIG_DIR={path}')
    if args.valve_jumps:
        os.environ['SUSPENSION_TUNING_CONFIG_DIR'] = str(path)
        from suspension_tuning.studies.method_benchmark import reference_for

        out = valve_jumps(reference_for('mixed', len(PRESET)).x)
        print(f'f at the reference: {out["f_at_x"]:.6f}, valve switches '
              f'{out["switches_at_x"]:.0f}')
        print('| variable | df closed loop | df valves held | switches at -0.025 / +0.025 |')
        print('|---|---|---|---|')
        for name, closed, held, sw in zip(out['names'], out['df_closed'], out['df_held'],
                                          out['switches']):
            print(f'| {name} | {closed:+.3f} | {held:+.3f} | {sw[0]:.0f} / {sw[1]:.0f} |')


if __name__ == '__main__':
    main()
