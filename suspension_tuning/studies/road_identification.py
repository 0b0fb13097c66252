"""Identification of the Belgian paving's stone height spread from the paper's corner range.

The paper's measured Belgian-paving profile is not public.  What it reports of it is the
response of its validated vehicle model: at the four corners of the 2-variable design
space the BS 6841 W_b weighted RMS seat accelerations range from 0.7 to 4.4 m/s^2
[P s.5.2].  The sett paving of config/road.yaml (:class:`~suspension_tuning.vehicle.
road.SettPavingSpec`) has one parameter that those responses can identify, the standard
deviation of the stone heights ``sett_height_std_m``; the others are fixed from the
paper (the bed's ISO 8608 numbers) or from sett dimensions (pitch, joints), see the YAML.

:func:`identify_sett_height` minimises, over a few road seeds, the mean squared log
error of the smallest and the largest per-seat corner value against 0.7 and 4.4 m/s^2:

    J(sigma) = mean_seeds [ ln(a_min / 0.7)^2 + ln(a_max / 4.4)^2 ]

(one parameter, two reported values, so the fit is over-determined and its residuals
say how well the road model explains the paper).  Vehicle parameters are not touched.

:func:`plot_psd` draws the paving's PSD (analytic parts and the Welch estimate of the
synthesised tracks, raw and as the tyre sees them after contact-patch averaging) against
the ISO 8608 class boundaries.

Run ``python -m suspension_tuning.studies.road_identification [--plot PNG]
[--sensitivity] [--no-fit]``: the grid is 29 points x 6 seeds of 4-design full-model
batches, about a minute on 2 cores; ``--sensitivity`` adds the variants of
:data:`SENSITIVITY_CASES` (bed roughness, joints, layout, speed).
"""

from __future__ import annotations

import argparse
import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal

from suspension_tuning.vehicle import road as road_mod
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER
from suspension_tuning.vehicle.params import (
    VehicleParams,
    load_scenarios_config,
    load_vehicle_params,
)
from suspension_tuning.vehicle.scenarios import ride_road_spec, run_scenario

Array = NDArray[np.float64]
CORNERS_2VAR = np.array(
    [[X_LOWER, X_LOWER], [X_LOWER, X_UPPER], [X_UPPER, X_LOWER], [X_UPPER, X_UPPER]]
)
"""The four corners of the 2-variable design space (dpsf, gvol), eqs. 5-6."""
CORNER_NAMES = (
    'dpsf 0.1, 0.1 L',
    'dpsf 0.1, 0.6 L',
    'dpsf 3.0, 0.1 L',
    'dpsf 3.0, 0.6 L',
)
TARGET_MIN_MPS2 = 0.7
"""Smallest corner W_b RMS of the paper's validated model [P s.5.2], m/s^2."""
TARGET_MAX_MPS2 = 4.4
"""Largest corner W_b RMS of the paper's validated model [P s.5.2], m/s^2."""
DEFAULT_SEEDS = (8608, 1, 2, 3, 4, 5)
"""The scenario's road seed (config/road.yaml) and five more realisations [E]."""
ISO8608_CLASS_LIMITS_M3 = 2.0 ** np.arange(3, 18, 2) * 1e-6
"""ISO 8608 class boundaries of G_d(n0), A/B ... G/H, m^3 (physics-reference 6.1)."""


@dataclass
class CornerResponses:
    """Per-seat W_b RMS and eq. 11 constraints at the four corners for several roads.

    Attributes
    ----------
    seeds : tuple of int
        Road seeds.
    wb_rms_mps2 : np.ndarray
        (n_seeds, 4 corners, 2 seats: driver, passenger), m/s^2.
    g : np.ndarray
        (n_seeds, 4 corners, 4 tyres) eq. 11 values.
    """

    seeds: tuple[int, ...]
    wb_rms_mps2: Array
    g: Array

    @property
    def a_min_mps2(self) -> Array:
        """Smallest per-seat corner value per seed, m/s^2."""
        return self.wb_rms_mps2.min(axis=(1, 2))

    @property
    def a_max_mps2(self) -> Array:
        """Largest per-seat corner value per seed, m/s^2."""
        return self.wb_rms_mps2.max(axis=(1, 2))


def _ride_config(overrides: dict, config: dict | None) -> dict:
    cfg = copy.deepcopy(config if config is not None else load_scenarios_config())
    cfg['ride']['road_overrides'] = {**(cfg['ride'].get('road_overrides') or {}), **overrides}
    return cfg


def corner_responses(
    overrides: dict | None = None,
    seeds: tuple[int, ...] = DEFAULT_SEEDS,
    params: VehicleParams | None = None,
    config: dict | None = None,
) -> CornerResponses:
    """Run the ride scenario at the four 2-variable corners on several road seeds.

    Parameters
    ----------
    overrides : dict, optional
        Road fields replacing those of the scenario's road (e.g. ``sett_height_std_m``).
    seeds : tuple of int
        Road seeds, one full-model batch of 4 designs each.
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).
    config : dict, optional
        Scenario configuration (default config/scenarios.yaml).

    Returns
    -------
    CornerResponses
        W_b RMS and constraints per seed, corner and seat / tyre.
    """
    params = params if params is not None else load_vehicle_params()
    wb, g = [], []
    for seed in seeds:
        cfg = _ride_config({**(overrides or {}), 'seed': int(seed)}, config)
        res = run_scenario('ride', CORNERS_2VAR, params, config=cfg)
        m = res.metrics
        wb.append(np.stack([m['a_rms_driver_mps2'], m['a_rms_passenger_mps2']], axis=1))
        g.append(res.g)
    return CornerResponses(tuple(int(s) for s in seeds), np.array(wb), np.array(g))


def log_error(resp: CornerResponses) -> float:
    """J = mean over seeds of ln(a_min/0.7)^2 + ln(a_max/4.4)^2."""
    e_min = np.log(resp.a_min_mps2 / TARGET_MIN_MPS2)
    e_max = np.log(resp.a_max_mps2 / TARGET_MAX_MPS2)
    return float(np.mean(e_min**2 + e_max**2))


@dataclass
class Identification:
    """Result of :func:`identify_sett_height`.

    Attributes
    ----------
    sett_height_std_m : float
        Identified stone height standard deviation, m.
    objective : float
        J at the optimum (mean squared log error).
    responses : CornerResponses
        Corner values at the optimum.
    evaluations : list of (float, float)
        (sigma in m, J) of every evaluation, in order.
    """

    sett_height_std_m: float
    objective: float
    responses: CornerResponses
    evaluations: list[tuple[float, float]]


def identify_sett_height(
    seeds: tuple[int, ...] = DEFAULT_SEEDS,
    bounds_m: tuple[float, float] = (0.008, 0.014),
    step_log: float = 0.02,
    params: VehicleParams | None = None,
    config: dict | None = None,
) -> Identification:
    """Identify ``sett_height_std_m`` from the paper's corner range 0.7-4.4 m/s^2.

    Grid search of :func:`log_error` over ln(sigma).  J is not smooth in sigma: the
    largest corner value comes from the least damped, stiffest corner, whose axles hop
    and reach the bump stops, so a few impacts more or less move it by several per cent
    between neighbouring sigma.  A grid shows that scatter, where a local 1-D search
    would stop in whichever dip it meets first.

    Parameters
    ----------
    seeds : tuple of int
        Road seeds averaged in J.
    bounds_m : (float, float)
        Search interval of sigma, m.
    step_log : float
        Grid step of ln(sigma) (0.02: 2 % of sigma).
    params, config
        Vehicle parameters and scenario configuration (defaults from config/).

    Returns
    -------
    Identification
        The grid point of smallest J, its objective and corner values, and every
        evaluation.
    """
    params = params if params is not None else load_vehicle_params()
    lo, hi = np.log(bounds_m[0]), np.log(bounds_m[1])
    grid = np.exp(np.linspace(lo, hi, int(round((hi - lo) / step_log)) + 1))
    evaluations: list[tuple[float, float]] = []
    best: tuple[float, float, CornerResponses] | None = None
    for sigma in grid:
        resp = corner_responses({'sett_height_std_m': float(sigma)}, seeds, params, config)
        val = log_error(resp)
        evaluations.append((float(sigma), val))
        if best is None or val < best[1]:
            best = (float(sigma), val, resp)
    assert best is not None
    return Identification(best[0], best[1], best[2], evaluations)


SENSITIVITY_CASES: dict[str, tuple[dict, float | None]] = {
    'configured road': ({}, None),
    'bed G_d0 1e-5 m^3 (paper 1e-4)': ({'gd_n0_m3': 1e-5}, None),
    'bed G_d0 3e-4 m^3': ({'gd_n0_m3': 3e-4}, None),
    'no joints': ({'joint_width_m': 0.0, 'joint_depth_m': 0.0}, None),
    'independent stones and courses per track': ({'sett_layout': 'independent'}, None),
    'speed 40 km/h': ({}, 40.0),
    'speed 60 km/h (road 600 m long)': ({'length_m': 600.0}, 60.0),
}
"""Variants of the identified road for :func:`sensitivity`: (road overrides, speed km/h)."""


def sensitivity(
    seeds: tuple[int, ...] = DEFAULT_SEEDS, params: VehicleParams | None = None
) -> dict[str, CornerResponses]:
    """Corner responses of the identified road and of the variants in SENSITIVITY_CASES.

    Parameters
    ----------
    seeds : tuple of int
        Road seeds.
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).

    Returns
    -------
    dict
        Case name -> :class:`CornerResponses`.
    """
    params = params if params is not None else load_vehicle_params()
    out = {}
    for name, (overrides, speed_kmh) in SENSITIVITY_CASES.items():
        cfg = copy.deepcopy(load_scenarios_config())
        if speed_kmh is not None:
            cfg['ride']['speed_kmh'] = speed_kmh
        out[name] = corner_responses(overrides, seeds, params, cfg)
    return out


def welch_psd(z_m: Array, dx_m: float, segment_m: float = 50.0) -> tuple[Array, Array]:
    """One-sided Welch PSD of an elevation record: (n cycles/m, G_d m^3)."""
    nper = int(round(segment_m / dx_m))
    n, g = signal.welch(z_m, fs=1.0 / dx_m, nperseg=min(nper, z_m.size), detrend='linear')
    return n[1:], g[1:]


def plot_psd(
    spec: road_mod.RoadSpec,
    path: str | Path,
    contact_length_m: float,
    speed_kmh: float,
    paper_spec: road_mod.RoadSpec | None = None,
) -> dict[str, float]:
    """Write a PNG of the road's PSD against the ISO 8608 class boundaries.

    Parameters
    ----------
    spec : RoadSpec or SettPavingSpec
        Road to plot (synthesised as the scenario does).
    path : str or Path
        Output PNG.
    contact_length_m : float
        Tyre contact length of the enveloping average (tyre.yaml), m.
    speed_kmh : float
        Scenario speed, for the temporal-frequency axis on top.
    paper_spec : RoadSpec, optional
        A second road drawn for comparison (the paper-literal ISO 8608 road).

    Returns
    -------
    dict
        RMS elevation of the left track (raw and enveloped), m, and the Welch PSD of the
        raw left track at n0 = 0.1 cycles/m, m^3.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    prof = road_mod.synthesise_tracks(spec)
    z = np.asarray(prof.z_left_m)
    n_avg = int(round(contact_length_m / spec.dx_m))
    z_env = ndimage.uniform_filter1d(z, n_avg, mode='nearest') if n_avg > 1 else z
    n, g = welch_psd(z, spec.dx_m)
    _, g_env = welch_psd(z_env, spec.dx_m)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    n0 = 0.1
    nn = np.logspace(-2, np.log10(0.5 / spec.dx_m), 400)
    names = 'ABCDEFGH'
    for i, lim in enumerate(ISO8608_CLASS_LIMITS_M3):
        ax.loglog(nn, lim * (nn / n0) ** -2, color='0.75', lw=0.8)
        name = 'A lower' if i == 0 else f'{names[i - 1]}/{names[i]}'
        n_text = 0.35 / spec.dx_m
        ax.text(n_text, lim * (n_text / n0) ** -2 * 1.2, name, color='0.45', fontsize=7,
                ha='right')  # fmt: skip
    ax.loglog(n, g, color='C0', lw=1.0, label=f'{_label(spec)}: left track (Welch)')
    ax.loglog(n, g_env, color='C0', lw=1.0, ls='--',
              label=f'same, averaged over the {contact_length_m:.2f} m contact patch')  # fmt: skip
    band = (nn >= spec.n_min_cyc_per_m) & (nn <= spec.n_max_cyc_per_m)
    ax.loglog(nn[band], road_mod.iso8608_psd(nn[band], spec), color='C2', lw=1.2,
              label='ISO 8608 bed, analytic')  # fmt: skip
    if isinstance(spec, road_mod.SettPavingSpec):
        ax.loglog(nn, road_mod.sett_height_psd(nn, spec), color='C3', lw=1.2,
                  label='stone heights, analytic (no joints)')  # fmt: skip
    if paper_spec is not None:
        zp = np.asarray(road_mod.synthesise_tracks(paper_spec).z_left_m)
        n_p, g_p = welch_psd(zp, paper_spec.dx_m)
        ax.loglog(n_p, g_p, color='C1', lw=1.0, label=f'{_label(paper_spec)} (Welch)')
    ax.set_xlim(0.01, 0.5 / spec.dx_m)
    ax.set_ylim(1e-11, 1e-1)
    ax.set_xlabel('spatial frequency n [cycles/m]')
    ax.set_ylabel('displacement PSD G_d(n) [m^3]')
    ax.grid(True, which='major', alpha=0.3)
    top = ax.secondary_xaxis('top', functions=(lambda x: x * speed_kmh / 3.6,
                                               lambda f: f * 3.6 / speed_kmh))  # fmt: skip
    top.set_xlabel(f'temporal frequency at {speed_kmh:g} km/h [Hz]')
    ax.legend(fontsize=7, loc='lower left')
    ax.set_title('Belgian paving against the ISO 8608 class boundaries (grey, w = 2)', fontsize=9)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {
        'rms_left_m': float(np.sqrt(np.mean(z**2))),
        'rms_left_enveloped_m': float(np.sqrt(np.mean(z_env**2))),
        'welch_psd_at_n0_m3': float(np.interp(n0, n, g)),
    }


def _label(spec: road_mod.RoadSpec) -> str:
    if isinstance(spec, road_mod.SettPavingSpec):
        return f'sett paving (stone sigma {1e3 * spec.sett_height_std_m:.1f} mm)'
    return f'ISO 8608 G_d0 = {spec.gd_n0_m3:.0e} m^3, w = {spec.waviness:g}'


def _print_responses(label: str, resp: CornerResponses) -> None:
    print(f'{label}:')
    for k, seed in enumerate(resp.seeds):
        cells = ', '.join(
            f'{name} {resp.wb_rms_mps2[k, c, 0]:.2f}/{resp.wb_rms_mps2[k, c, 1]:.2f}'
            f' (g {resp.g[k, c].max():+.2f})'
            for c, name in enumerate(CORNER_NAMES)
        )
        print(f'  seed {seed}: min {resp.a_min_mps2[k]:.3f} max {resp.a_max_mps2[k]:.3f}; {cells}')


def main(argv: list[str] | None = None) -> int:
    """Identify the stone height spread, print ``name: value`` lines, optionally plot."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, nargs='+', default=list(DEFAULT_SEEDS))
    ap.add_argument('--plot', type=Path, default=None, help='write the PSD PNG here')
    ap.add_argument('--sensitivity', action='store_true',
                    help='corner values of the road variants of SENSITIVITY_CASES')  # fmt: skip
    ap.add_argument('--no-fit', action='store_true',
                    help='only evaluate the configured road (no identification)')  # fmt: skip
    args = ap.parse_args(argv)
    params = load_vehicle_params()
    seeds = tuple(args.seeds)
    spec = ride_road_spec(load_scenarios_config()['ride'])
    if not isinstance(spec, road_mod.SettPavingSpec):
        print(f'the ride road is not a sett paving ({type(spec).__name__}): nothing to identify')
        return 1
    configured = corner_responses(None, seeds, params)
    _print_responses(f'configured road (sigma {1e3 * spec.sett_height_std_m:.2f} mm)', configured)
    print(f'configured_objective: {log_error(configured):.5f}')
    if not args.no_fit:
        ident = identify_sett_height(seeds, params=params)
        for sigma, val in ident.evaluations:
            print(f'  grid sigma {1e3 * sigma:.3f} mm: J {val:.5f}')
        _print_responses('identified', ident.responses)
        print(f'identified_sett_height_std_m: {ident.sett_height_std_m:.5f}')
        print(f'identified_objective: {ident.objective:.5f}')
        for key in ('a_min_mps2', 'a_max_mps2'):
            gm = np.exp(np.mean(np.log(getattr(ident.responses, key))))
            print(f'identified_{key}_geomean: {gm:.3f}')
    if args.sensitivity:
        print('| variant | smallest corner value, m/s^2 | largest corner value, m/s^2 '
              '| largest g, dpsf 0.1 corners | largest g, dpsf 3 corners |')  # fmt: skip
        print('|---|---|---|---|---|')
        for name, resp in sensitivity(seeds, params).items():
            g_low = resp.g[:, :2].max()
            g_high = resp.g[:, 2:].max()
            print(
                f'| {name} | {resp.a_min_mps2.min():.2f}-{resp.a_min_mps2.max():.2f} '
                f'(geomean {np.exp(np.mean(np.log(resp.a_min_mps2))):.2f}) '
                f'| {resp.a_max_mps2.min():.2f}-{resp.a_max_mps2.max():.2f} '
                f'(geomean {np.exp(np.mean(np.log(resp.a_max_mps2))):.2f}) '
                f'| {g_low:+.2f} | {g_high:+.2f} |'
            )
    if args.plot is not None:
        sc = load_scenarios_config()['ride']
        paper = road_mod.load_road_spec('belgian_paving_paper_iso8608')
        stats = plot_psd(spec, args.plot, params.tyre.contact_length_m,
                         float(sc['speed_kmh']), paper)  # fmt: skip
        for k, v in stats.items():
            print(f'{k}: {v:.4g}')
        print(f'plot: {args.plot}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
