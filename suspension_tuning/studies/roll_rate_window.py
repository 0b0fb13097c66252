"""Windows and definitions of the RMS roll rate against the paper's 0.8-5.7 deg/s.

The paper's handling objective (eq. 10) uses "the RMS roll velocity for the whole double
lane change manoeuvre" and reports 0.8-5.7 deg/s at the four corners of the 2-variable
design space [P s.5.2].  The handling scenario measures it from lane 1 entry to the end of
section 6.  :func:`roll_rate_definitions` evaluates, at the four corners, the RMS roll
rate over other windows (the first lane change, the whole run, the manoeuvre plus up to
20 s of straight running after it) and other definitions (mean removed, mean absolute
value, a 1 Hz low-passed rate), without touching any vehicle parameter.

A window only rescales all four corners alike unless the roll decays differently per
corner, so the paper's range needs both the right scale (0.8 and 5.7) and the right
ratio of largest to smallest corner (5.7 / 0.8 = 7.1).  :func:`window_for_paper_range`
states the window length a pure rescaling would need.

Run ``python -m suspension_tuning.studies.roll_rate_window``: one batch of four handling
runs with a 20 s run-out, a few seconds.
"""

from __future__ import annotations

import argparse
import copy

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from suspension_tuning.studies.road_identification import CORNER_NAMES, CORNERS_2VAR
from suspension_tuning.vehicle.params import load_scenarios_config, load_vehicle_params
from suspension_tuning.vehicle.scenarios import run_scenario

Array = NDArray[np.float64]
PAPER_RATE_RANGE_DEG_S = (0.8, 5.7)
"""RMS roll velocity at the corners of the paper's validated model [P s.5.2], deg/s."""
EXTRA_RUN_OUT_S = 20.0
"""Straight running simulated after section 6 for the longer windows [E], s."""


def _rms(x: Array, t: Array, t0: float, t1: float) -> float:
    m = (t >= t0) & (t <= t1)
    return float(np.sqrt(np.mean(x[m] ** 2)))


def roll_rate_definitions(extra_run_out_s: float = EXTRA_RUN_OUT_S) -> dict[str, Array]:
    """RMS-roll-rate variants at the four 2-variable corners, deg/s.

    Parameters
    ----------
    extra_run_out_s : float
        Straight running added after the configured run-out, s (the scenario's own
        metrics do not depend on it: they end at section 6).

    Returns
    -------
    dict
        Name of the window / definition -> values at the four corners (order of
        ``CORNER_NAMES``), deg/s; plus 'manoeuvre_duration_s' (4,).
    """
    params = load_vehicle_params()
    cfg = copy.deepcopy(load_scenarios_config())
    hcfg = cfg['handling']
    speed = float(hcfg['speed_kmh']) / 3.6
    run_out = float(hcfg['run_out_m'])
    hcfg['run_out_m'] = run_out + extra_run_out_s * speed
    res = run_scenario('handling', CORNERS_2VAR, params, config=cfg)
    h = res.histories
    t, rate = h['t_s'], h['roll_rate_deg_s']
    t_man = res.metrics['t_manoeuvre_s']
    t_lc = res.metrics['t_first_lane_change_s']
    t_default_end = (float(hcfg['lead_in_m']) + run_out) / speed + t_man[:, 1] - t_man[:, 0]
    b, a = signal.butter(2, 1.0 / (0.5 / (t[1] - t[0])))  # 1 Hz low-pass, zero phase
    out: dict[str, list[float]] = {}

    def add(name: str, value: float) -> None:
        out.setdefault(name, []).append(value)

    for i in range(CORNERS_2VAR.shape[0]):
        t0, t1 = t_man[i]
        add('manoeuvre: lane 1 entry to section 6 exit (scenario)', _rms(rate[i], t, t0, t1))
        add('first lane change only', _rms(rate[i], t, *t_lc[i]))
        add('whole run: lead-in, manoeuvre, run-out', _rms(rate[i], t, 0.0, t_default_end[i]))
        for extra in (2.0, 5.0, 10.0, extra_run_out_s):
            add(f'manoeuvre + {extra:g} s straight after', _rms(rate[i], t, t0, t1 + extra))
        m = (t >= t0) & (t <= t1)
        add('manoeuvre, mean removed (standard deviation)', float(np.std(rate[i][m])))
        add('manoeuvre, mean absolute value', float(np.mean(np.abs(rate[i][m]))))
        add('manoeuvre, 1 Hz low-passed rate', _rms(signal.filtfilt(b, a, rate[i]), t, t0, t1))
    result = {k: np.array(v) for k, v in out.items()}
    result['manoeuvre_duration_s'] = t_man[:, 1] - t_man[:, 0]
    return result


def window_for_paper_range(rms_manoeuvre_deg_s: Array, duration_s: float) -> dict[str, float]:
    """Window lengths that would rescale the manoeuvre RMS onto the paper's end points.

    If the roll rate were zero outside the manoeuvre, the RMS over a window T would be
    ``rms_man sqrt(T_man / T)``.  The smallest corner reaches 0.8 deg/s at
    ``T = T_man (rms_min / 0.8)^2`` and the largest 5.7 deg/s at
    ``T = T_man (rms_max / 5.7)^2``; one window does both only if the corner ratio is
    the paper's 7.1.

    Parameters
    ----------
    rms_manoeuvre_deg_s : array_like
        RMS roll rate over the manoeuvre at the corners, deg/s.
    duration_s : float
        Manoeuvre duration T_man, s.

    Returns
    -------
    dict
        'window_for_min_s', 'window_for_max_s', 'ratio_ours', 'ratio_paper'.
    """
    r = np.asarray(rms_manoeuvre_deg_s, dtype=float)
    lo, hi = PAPER_RATE_RANGE_DEG_S
    return {
        'window_for_min_s': float(duration_s * (r.min() / lo) ** 2),
        'window_for_max_s': float(duration_s * (r.max() / hi) ** 2),
        'ratio_ours': float(r.max() / r.min()),
        'ratio_paper': hi / lo,
    }


def main(argv: list[str] | None = None) -> int:
    """Print the table of windows and definitions and the rescaling check."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--extra-run-out-s', type=float, default=EXTRA_RUN_OUT_S)
    args = ap.parse_args(argv)
    rows = roll_rate_definitions(args.extra_run_out_s)
    dur = rows.pop('manoeuvre_duration_s')
    lo, hi = PAPER_RATE_RANGE_DEG_S
    print(f'corners: {", ".join(CORNER_NAMES)}; paper {lo}-{hi} deg/s, ratio {hi / lo:.2f}')
    print('| window / definition | ' + ' | '.join(CORNER_NAMES) + ' | range | ratio |')
    print('|---|' + '---|' * (len(CORNER_NAMES) + 2))
    for name, v in rows.items():
        cells = ' | '.join(f'{x:.2f}' for x in v)
        print(f'| {name} | {cells} | {v.min():.2f}-{v.max():.2f} | {v.max() / v.min():.2f} |')
    first = next(iter(rows.values()))
    check = window_for_paper_range(first, float(np.mean(dur)))
    print(f'manoeuvre_duration_s: {np.mean(dur):.2f}')
    for k, v in check.items():
        print(f'{k}: {v:.2f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
