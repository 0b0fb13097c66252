"""Numerical-noise study of the full and simplified models (paper Figs 7-8).

The front damper variable x1 is swept finely through the centre of the design space (the
other variables at the centre) for both models, and the noise of each function (f and
each g) is estimated from the sweep (:func:`noise_measure`: third-difference table, and
the residual about a polynomial trend).  Values are in full-model units (simplified
values scaled by eq. 25 when a scaling is given).

Handling: the simplified model runs with the inputs (steering, slip angles) of the full
model's run at the sweep centre, as all 2n stencil points of one gradient do; the
variant with each point's own full-run inputs is reported as ``simplified_own_inputs``
(it inherits the full model's noise through the inputs).

The full model runs with the fixed-step RK4 kernel ('full') and, with
``--variable-step``, also with the error-controlled variable-step integrator
('full_variable_step', config/vehicle.yaml ``integration.variable_step``), whose step
grid changes with the design as a multibody code's does; :func:`step_size_history`
plots its step sizes over one run.

Run ``python -m suspension_tuning.studies.noise --scenario ride --variable-step --out DIR``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from suspension_tuning.optim.scaling import FUNCTION_NAMES, Scaling
from suspension_tuning.optim.simplified_gradient import load_or_calibrate, simplified_values
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER, load_design_space
from suspension_tuning.vehicle.full_model import CORNERS
from suspension_tuning.vehicle.pitch_plane import load_simplified_config
from suspension_tuning.vehicle.scenarios import run_scenario
from suspension_tuning.vehicle.simplified import SimplifiedInputs

Array = NDArray[np.float64]
CENTRE = 0.5 * (X_LOWER + X_UPPER)


def noise_measure(x: Array, values: Array, degree: int = 2, step: float = 0.025) -> dict:
    """Noise of one swept function (uniform sweep).

    Two estimates of the noise standard deviation sigma:

    * difference table (after Moré & Wild's ECnoise): for independent noise the third
      differences of equally spaced values have variance 20 sigma^2 (binomial weights
      1, 3, 3, 1), while a smooth function's third differences are f'''(x) dx^3,
      negligible on a fine sweep: ``noise_rms = rms(diff3) / sqrt(20)``;
    * ``residual_rms``: RMS residual about a polynomial trend of ``degree`` (includes any
      unresolved smooth curvature, so it is an upper bound).

    Parameters
    ----------
    x : np.ndarray
        Uniform sweep positions (k,), k >= max(degree + 2, 5).
    values : np.ndarray
        Function values (k,).
    degree : int
        Degree of the trend polynomial.
    step : float
        Central-difference half step for ``fd_gradient_noise``.

    Returns
    -------
    dict
        'noise_rms', 'residual_rms', 'noise_rel' (noise_rms over the trend's range),
        'trend_range', 'fd_gradient_noise' (``sqrt(2) noise_rms / (2 h)``, the error
        such noise puts into a central difference of half step h).  A constant function
        has zero noise and NaN relative noise.
    """
    x = np.asarray(x, float)
    y = np.asarray(values, float)
    if x.shape != y.shape or x.ndim != 1 or x.size < max(degree + 2, 5):
        raise ValueError(f'need matching 1-D x, values with >= {max(degree + 2, 5)} points')
    if np.ptp(y) <= 1e-12 * max(1.0, float(np.max(np.abs(y)))):
        return {'noise_rms': 0.0, 'residual_rms': 0.0, 'noise_rel': float('nan'),
                'trend_range': 0.0, 'fd_gradient_noise': 0.0}  # fmt: skip
    d3 = np.diff(y, 3)
    noise = float(np.sqrt(np.mean(d3**2) / 20.0))
    trend = np.polyval(np.polyfit(x, y, degree), x)
    rng = float(np.ptp(trend))
    return {
        'noise_rms': noise,
        'residual_rms': float(np.sqrt(np.mean((y - trend) ** 2))),
        'noise_rel': noise / rng if rng > 0 else float('nan'),
        'trend_range': rng,
        'fd_gradient_noise': float(np.sqrt(2.0) * noise / (2.0 * step)),
    }


def _ratio(a: float, b: float) -> float:
    """a / b for noise levels: inf when only b is zero, NaN when both are (constant g)."""
    return a / b if b > 0 else (float('inf') if a > 0 else float('nan'))


def sweep_x1(
    scenario: str,
    scaling: Scaling | None = None,
    n_vars: int = 2,
    n_points: int | None = None,
    half_width: float | None = None,
    degree: int | None = None,
    png: str | Path | None = None,
    variable_step: bool = False,
) -> dict[str, object]:
    """Sweep x1 through the centre for both models and measure the noise.

    Parameters
    ----------
    variable_step : bool
        Also run the full model with the variable-step integrator (config/vehicle.yaml
        ``integration.variable_step``) as model 'full_variable_step'.

    Returns
    -------
    dict
        'x1' (k,), 'full' (k, 5) (fixed-step RK4), 'simplified' (k, 5) and, for
        handling, 'simplified_own_inputs' (k, 5), with ``variable_step`` also
        'full_variable_step' (k, 5); 'noise' {model: {function: noise_measure}};
        'noise_ratio' {function: full noise_rms / simplified noise_rms}; with
        ``variable_step`` also 'noise_ratio_variable_to_fixed' (noise_rms ratio) and
        'noise_ratio_simplified_to_variable' (noise_rel ratio: relative noise, which
        the linear eq. 25 scaling leaves unchanged).
    """
    cfg = load_simplified_config()
    nc = cfg['noise_study']
    n_points = int(nc['n_points'] if n_points is None else n_points)
    half_width = float(nc['half_width'] if half_width is None else half_width)
    degree = int(nc['detrend_degree'] if degree is None else degree)
    step = float(cfg['gradient']['step'])
    x1 = np.linspace(CENTRE - half_width, CENTRE + half_width, n_points)
    x = np.full((n_points, n_vars), CENTRE)
    x[:, 0] = x1
    centre = n_points // 2
    full_res = run_scenario(scenario, x, integrator='fixed_step')
    models = {'full': np.column_stack([full_res.f, full_res.g])}
    if variable_step:
        var = run_scenario(scenario, x, integrator='variable_step')
        models['full_variable_step'] = np.column_stack([var.f, var.g])
    if scenario == 'ride':
        models['simplified'] = simplified_values('ride', x, n_vars, None, scaling)
    else:
        frozen = SimplifiedInputs.from_scenario_result(full_res, centre)
        models['simplified'] = simplified_values(scenario, x, n_vars, frozen, scaling)
        models['simplified_own_inputs'] = np.vstack(
            [
                simplified_values(
                    scenario, x[i], n_vars, SimplifiedInputs.from_scenario_result(full_res, i),
                    scaling,
                )
                for i in range(n_points)
            ]
        )  # fmt: skip
    noise = {
        m: {nm: noise_measure(x1, v[:, i], degree, step) for i, nm in enumerate(FUNCTION_NAMES)}
        for m, v in models.items()
    }
    ratio = {
        nm: _ratio(noise['full'][nm]['noise_rms'], noise['simplified'][nm]['noise_rms'])
        for nm in FUNCTION_NAMES
    }
    out = {'x1': x1, **models, 'noise': noise, 'noise_ratio': ratio}
    if variable_step:
        nv = noise['full_variable_step']
        out['noise_ratio_variable_to_fixed'] = {
            nm: _ratio(nv[nm]['noise_rms'], noise['full'][nm]['noise_rms'])
            for nm in FUNCTION_NAMES
        }
        rel = {
            m: {nm: d[nm]['noise_rel'] if np.isfinite(d[nm]['noise_rel']) else 0.0
                for nm in FUNCTION_NAMES}
            for m, d in noise.items()
        }  # fmt: skip
        out['noise_ratio_simplified_to_variable'] = {
            nm: _ratio(rel['simplified'][nm], rel['full_variable_step'][nm])
            for nm in FUNCTION_NAMES
        }
    if png is not None:
        _plot(png, scenario, x1, models, n_vars)
    return out


def step_sweep(
    scenario: str,
    scaling: Scaling | None = None,
    n_vars: int = 2,
    steps: tuple[float, ...] = (0.005, 0.01, 0.025, 0.05),
) -> dict[str, Array]:
    """Central-difference gradient of f at the centre for several half steps h.

    Physics-reference 1.8 suggests h in {0.005, 0.01, 0.025, 0.05}: a noisy model gives
    gradients that scatter as h shrinks; a smooth one gives converging values.  The full
    model's stencils for every h run in one batch; the simplified gradient uses the
    inputs of the full run at the centre.

    Returns
    -------
    dict
        'steps' (k,), 'df_full', 'df_simplified' (k, n), 'cosine' (k,).
    """
    from suspension_tuning.optim.finite_diff import central_difference_points
    from suspension_tuning.optim.simplified_gradient import SimplifiedGradient

    x = np.full(n_vars, CENTRE)
    stencils = [central_difference_points(x, h, X_LOWER, X_UPPER) for h in steps]
    full = run_scenario(scenario, np.vstack([x[None]] + [st[0] for st in stencils]))
    inputs = SimplifiedInputs.from_scenario_result(full, 0)
    k = len(steps)
    df_full, df_simp, cos = np.empty((k, n_vars)), np.empty((k, n_vars)), np.empty(k)
    for i, h in enumerate(steps):
        f = full.f[1 + 2 * n_vars * i : 1 + 2 * n_vars * (i + 1)]
        df_full[i] = (f[:n_vars] - f[n_vars:]) / stencils[i][1]
        df_simp[i] = SimplifiedGradient(scenario, n_vars, scaling, h)(x, inputs)[0]
        na, nb = np.linalg.norm(df_full[i]), np.linalg.norm(df_simp[i])
        cos[i] = float(df_full[i] @ df_simp[i] / (na * nb)) if na > 0 and nb > 0 else np.nan
    return {'steps': np.asarray(steps), 'df_full': df_full, 'df_simplified': df_simp,
            'cosine': cos}  # fmt: skip


def step_size_history(
    scenario: str, n_vars: int = 2, png: str | Path | None = None, capacity: int = 20000
) -> dict[str, Array]:
    """Step sizes of the variable-step integrator over one run at the centre design.

    Returns
    -------
    dict
        't_s', 'h_s' (accepted steps: end time and size), 'accepted', 'rejected',
        'derivative_calls', and the run's 't_full_s' with the tyre normal forces
        'fz_n' (4, m) for the plot's lower panel.
    """
    x = np.full((1, n_vars), CENTRE)
    res = run_scenario(scenario, x, integrator='variable_step', step_log_capacity=capacity)
    st = res.integrator['stats']
    n = int(st['accepted_steps'][0])
    out = {
        't_s': st['step_log_t_s'][0, : min(n, capacity)],
        'h_s': st['step_log_h_s'][0, : min(n, capacity)],
        'accepted': n,
        'rejected': int(st['rejected_steps'][0]),
        'derivative_calls': int(st['derivative_calls'][0]),
        't_full_s': res.histories['t_s'],
        'fz_n': res.histories['tyre_fz_n'][0],
    }
    if png is not None:
        import matplotlib

        matplotlib.use('Agg')
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(2, 1, figsize=(12, 6), sharex=True)
        axs[0].semilogy(out['t_s'], 1e3 * out['h_s'], '.', ms=2)
        axs[0].set_ylabel('accepted step h [ms]')
        axs[0].set_title(
            f'{scenario}: variable-step DOPRI5 at the centre design, {n} steps, '
            f'{out["rejected"]} rejected, {out["derivative_calls"]} derivative calls'
        )
        for c, name in enumerate(CORNERS):
            axs[1].plot(out['t_full_s'], 1e-3 * out['fz_n'][c], lw=0.6, label=name)
        axs[1].set_ylabel('tyre normal force [kN]')
        axs[1].set_xlabel('t [s]')
        axs[1].legend(fontsize=7, ncol=4)
        fig.tight_layout()
        Path(png).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(png, dpi=90)
        plt.close(fig)
    return out


def _plot(png, scenario, x1, models, n_vars: int = 4) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(12, 4.2))
    styles = {'full': '-o', 'full_variable_step': '-x', 'simplified': '-s',
              'simplified_own_inputs': ':^'}  # fmt: skip
    labels = {'full': 'full, fixed-step RK4', 'full_variable_step': 'full, variable-step DOPRI5',
              'simplified': 'simplified', 'simplified_own_inputs': 'simplified, own inputs'}
    for m, v in models.items():
        axs[0].plot(x1, v[:, 0], styles[m], ms=3, label=labels[m])
        for i, nm in enumerate(FUNCTION_NAMES[1:], start=1):
            axs[1].plot(x1, v[:, i], styles[m], ms=3, label=f'{labels[m]} {nm}')
    axs[0].set_title(f'{scenario}: objective f vs x1 (Figs 7-8)')
    axs[1].set_title(f'{scenario}: tyre-hop constraints g vs x1')
    space = load_design_space()
    var, _ = space.variables(n_vars)[0]
    low, high = space.bounds(n_vars)
    physical = var.in_unit(low[0] + np.asarray(x1, dtype=float) * (high[0] - low[0]))
    for ax in axs:
        ax.set_xlabel('x1 (front damper, normalised)')
        ax.legend(fontsize=7)
        top = ax.secondary_xaxis('top', functions=(
            lambda x: np.interp(x, x1, physical), lambda v: np.interp(v, physical, x1)))
        top.set_xlabel(f'{space.names(n_vars)[0]} (physical, config/design_space.yaml)',
                       fontsize=8)
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep, print ``name: value`` lines and write the PNG."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scenario', choices=('ride', 'handling'), default='ride')
    ap.add_argument('--n-vars', type=int, default=2, choices=(2, 4))
    ap.add_argument('--out', default='studies_out', help='output directory')
    ap.add_argument('--unscaled', action='store_true', help='skip the eq. 25 scaling')
    ap.add_argument('--variable-step', action='store_true',
                    help='also sweep the variable-step full model and plot its step sizes')
    args = ap.parse_args(argv)
    out = Path(args.out)
    sc = None
    if not args.unscaled:
        sc, _ = load_or_calibrate(
            out / f'scaling_{args.scenario}_{args.n_vars}.json', args.scenario, args.n_vars
        )
    png = out / f'noise_{args.scenario}_{args.n_vars}.png'
    res = sweep_x1(args.scenario, sc, args.n_vars, png=png, variable_step=args.variable_step)
    for m, d in res['noise'].items():
        for nm, v in d.items():
            for k in ('noise_rms', 'residual_rms', 'noise_rel', 'fd_gradient_noise'):
                print(f'{args.scenario}_{m}_{nm}_{k}: {v[k]:.3e}')
    for nm, r in res['noise_ratio'].items():
        print(f'{args.scenario}_noise_ratio_full_over_simplified_{nm}: {r:.3e}')
    print(f'{args.scenario}_noise_png: {png}')
    if args.variable_step:
        for key in ('noise_ratio_variable_to_fixed', 'noise_ratio_simplified_to_variable'):
            for nm, r in res[key].items():
                print(f'{args.scenario}_{key}_{nm}: {r:.3e}')
        steps_png = out / f'steps_{args.scenario}.png'
        hist = step_size_history(args.scenario, args.n_vars, steps_png)
        print(f'{args.scenario}_variable_step_accepted: {hist["accepted"]}')
        print(f'{args.scenario}_variable_step_rejected: {hist["rejected"]}')
        print(f'{args.scenario}_variable_step_median_h_s: {np.median(hist["h_s"]):.4g}')
        print(f'{args.scenario}_step_size_png: {steps_png}')
    st = step_sweep(args.scenario, sc, args.n_vars)
    for h, dfa, dfs, c in zip(st['steps'], st['df_full'], st['df_simplified'], st['cosine'],
                              strict=True):  # fmt: skip
        print(f'{args.scenario}_step_{h:g}_df_full: {np.array2string(dfa, precision=5)}')
        print(f'{args.scenario}_step_{h:g}_df_simplified: {np.array2string(dfs, precision=5)}')
        print(f'{args.scenario}_step_{h:g}_cosine: {c:.4f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
