"""Design-space validation of the simplified models (paper section 6.3, Figs 12-16).

* :func:`grid_comparison` - f of both models over a grid of two design variables (the
  others at the centre), the simplified values scaled by eq. 25; R^2 of the scaled
  simplified values against the full ones over the grid, and a PNG with both surfaces.
* :func:`gradient_agreement` - central-difference gradients of f from the full model
  (2n full runs per point, one batch for all points) and from the scaled simplified model
  (:class:`~suspension_tuning.optim.simplified_gradient.SimplifiedGradient`, inputs from
  the full run at the point), and their cosine similarity per point.

Run ``python -m suspension_tuning.studies.design_space --scenario ride --out DIR`` to
calibrate (or load) the scaling, print ``name: value`` lines and write the plots.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from suspension_tuning.optim.finite_diff import central_difference_points
from suspension_tuning.optim.scaling import Scaling, sample_design_space
from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    load_or_calibrate,
    simplified_values,
)
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER, load_design_space
from suspension_tuning.vehicle.pitch_plane import load_simplified_config
from suspension_tuning.vehicle.scenarios import run_scenario
from suspension_tuning.vehicle.simplified import SimplifiedInputs

Array = NDArray[np.float64]
CENTRE = 0.5 * (X_LOWER + X_UPPER)


def _simplified_at(scenario: str, x: Array, n_vars: int, full, scaling: Scaling | None):
    """Simplified values (N, 5) at x; handling uses each design's own full-run inputs."""
    if scenario == 'ride':
        return simplified_values('ride', x, n_vars, None, scaling)
    return np.vstack(
        [
            simplified_values(
                scenario, x[i], n_vars, SimplifiedInputs.from_scenario_result(full, i), scaling
            )
            for i in range(x.shape[0])
        ]
    )


def r_squared(full: Array, model: Array) -> float:
    """Coefficient of determination of ``full`` by ``model`` (NaN if full is constant)."""
    full, model = np.asarray(full, float), np.asarray(model, float)
    ss_tot = float(np.sum((full - full.mean()) ** 2))
    if ss_tot <= 0:
        return float('nan')
    return 1.0 - float(np.sum((full - model) ** 2)) / ss_tot


def grid_comparison(
    scenario: str,
    scaling: Scaling,
    n_vars: int = 2,
    axes: tuple[int, int] = (0, 1),
    grid_points: int | None = None,
    png: str | Path | None = None,
) -> dict[str, object]:
    """Objective of both models over a grid of two variables (Figs 12-16).

    Parameters
    ----------
    scenario : {'ride', 'handling'}
        Scenario.
    scaling : Scaling
        Eq. 25 scaling applied to the simplified values.
    n_vars : int
        2 or 4; variables not on ``axes`` sit at the centre.
    axes : (int, int)
        Indices of the two swept variables.
    grid_points : int, optional
        Points per axis (default config/simplified_models.yaml design_space).
    png : path, optional
        Where to write the plot.

    Returns
    -------
    dict
        'x' (N, n), 'f_full', 'f_simplified' (scaled) (N,), 'r2', 'r2_linear',
        'grid_shape'.
    """
    if grid_points is None:
        grid_points = int(load_simplified_config()['design_space']['grid_points'])
    if grid_points < 2:
        raise ValueError(f'grid_points must be >= 2, got {grid_points}')
    if len(set(axes)) != 2 or not all(0 <= a < n_vars for a in axes):
        raise ValueError(f'axes must be two different indices < {n_vars}, got {axes}')
    v = np.linspace(X_LOWER, X_UPPER, grid_points)
    g1, g2 = np.meshgrid(v, v, indexing='ij')
    x = np.full((g1.size, n_vars), CENTRE)
    x[:, axes[0]] = g1.ravel()
    x[:, axes[1]] = g2.ravel()
    full = run_scenario(scenario, x)
    simp = _simplified_at(scenario, x, n_vars, full, scaling)[:, 0]
    f_full = np.asarray(full.f, dtype=float)
    out = {
        'x': x,
        'f_full': f_full,
        'f_simplified': simp,
        'r2': r_squared(f_full, simp),
        'r2_linear': float(np.corrcoef(f_full, simp)[0, 1] ** 2),
        'grid_shape': g1.shape,
    }
    if png is not None:
        # the axes in physical units, named as config/design_space.yaml names them
        space = load_design_space()
        names = space.names(n_vars)
        low, high = space.bounds(n_vars)
        variables = space.variables(n_vars)
        values = [variables[a][0].in_unit(low[a] + v * (high[a] - low[a])) for a in axes]
        _plot_grid(png, scenario, values, f_full.reshape(g1.shape), simp.reshape(g1.shape),
                   (names[axes[0]], names[axes[1]]), out['r2'])  # fmt: skip
    return out


def _plot_grid(png, scenario, values, f_full, f_simp, labels, r2) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(14, 4.2))
    lo, hi = min(f_full.min(), f_simp.min()), max(f_full.max(), f_simp.max())
    levels = np.linspace(lo, hi, 15) if hi > lo else 15
    for ax, z, title in ((axs[0], f_full, 'full model'), (axs[1], f_simp, 'simplified, eq. 25')):
        cs = ax.contourf(values[0], values[1], z.T, levels=levels, cmap='viridis')
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_title(f'{scenario} f, {title}')
        fig.colorbar(cs, ax=ax)
    axs[2].plot(f_full.ravel(), f_simp.ravel(), 'o')
    axs[2].plot([lo, hi], [lo, hi], 'k--', lw=0.8)
    axs[2].set_xlabel('full model f')
    axs[2].set_ylabel('scaled simplified f')
    axs[2].set_title(f'R^2 = {r2:.3f}')
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)


def cosine(a: Array, b: Array) -> float:
    """Cosine similarity of two vectors (NaN if either is zero)."""
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return float('nan')
    return float(np.dot(a, b) / (na * nb))


def gradient_agreement(
    scenario: str,
    scaling: Scaling,
    points: Array,
    n_vars: int = 2,
    step: float | None = None,
) -> dict[str, Array]:
    """Full-model vs scaled simplified central-difference gradients of f at ``points``.

    All full runs (the points and their 2n stencils) go in one batch; the simplified
    gradient at a point uses the inputs of the full run at that point.

    Returns
    -------
    dict
        'points' (k, n), 'df_full', 'df_simplified' (k, n), 'cosine' (k,).
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    grad = SimplifiedGradient(scenario, n_vars, scaling, step)
    stencils = [central_difference_points(p, grad.step, grad.lower, grad.upper) for p in pts]
    k = pts.shape[0]
    batch = np.vstack([pts] + [s[0] for s in stencils])
    full = run_scenario(scenario, batch)
    df_full = np.empty((k, n_vars))
    df_simp = np.empty((k, n_vars))
    cos = np.empty(k)
    for i in range(k):
        base = k + 2 * n_vars * i
        f = full.f[base : base + 2 * n_vars]
        df_full[i] = (f[:n_vars] - f[n_vars:]) / stencils[i][1]
        df_simp[i] = grad(pts[i], SimplifiedInputs.from_scenario_result(full, i))[0]
        cos[i] = cosine(df_full[i], df_simp[i])
    return {'points': pts, 'df_full': df_full, 'df_simplified': df_simp, 'cosine': cos}


def validation_points(n_vars: int, n_points: int = 10, seed: int = 7) -> Array:
    """Interior LHS points (margin 0.05 from the bounds so the stencils are central)."""
    u = sample_design_space(n_vars, n_points, seed, include_corners=False)
    return 0.05 + 0.9 * (u - X_LOWER) / (X_UPPER - X_LOWER)


def main(argv: list[str] | None = None) -> int:
    """Calibrate/load the scaling, compare the models, print numbers, write PNGs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scenario', choices=('ride', 'handling'), default='ride')
    ap.add_argument('--n-vars', type=int, default=2, choices=(2, 4))
    ap.add_argument('--out', default='studies_out', help='output directory')
    ap.add_argument('--points', type=int, default=10, help='gradient comparison points')
    args = ap.parse_args(argv)
    out = Path(args.out)
    sc, cached = load_or_calibrate(
        out / f'scaling_{args.scenario}_{args.n_vars}.json', args.scenario, args.n_vars
    )
    print(f'scaling_loaded_from_cache: {cached}')
    for name, d in sc.summary().items():
        print(f'{args.scenario}_{name}_r2: {d["r2"]:.4f}')
        print(f'{args.scenario}_{name}_r2_linear: {d["r2_linear"]:.4f}')
        print(f'{args.scenario}_{name}_rule: {d["rule"]}')
        print(f'{args.scenario}_{name}_gradient_factor: {d["gradient_factor"]:.4f}')
    pairs = [(0, 1)] if args.n_vars == 2 else [(1, 3), (0, 2)]
    for axes in pairs:
        png = out / f'design_space_{args.scenario}_{args.n_vars}_{axes[0]}{axes[1]}.png'
        g = grid_comparison(args.scenario, sc, args.n_vars, axes, png=png)
        print(f'{args.scenario}_grid_{axes[0]}{axes[1]}_r2: {g["r2"]:.4f}')
        print(f'{args.scenario}_grid_{axes[0]}{axes[1]}_r2_linear: {g["r2_linear"]:.4f}')
        print(f'{args.scenario}_grid_{axes[0]}{axes[1]}_png: {png}')
    ga = gradient_agreement(
        args.scenario, sc, validation_points(args.n_vars, args.points), args.n_vars
    )
    for i, c in enumerate(ga['cosine']):
        print(f'{args.scenario}_gradient_cosine_{i}: {c:.4f}')
    print(f'{args.scenario}_gradient_cosine_min: {np.nanmin(ga["cosine"]):.4f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
