"""Small, fast versions of the section 6 studies (noise, design-space validation)."""

from __future__ import annotations

import numpy as np
import pytest

from suspension_tuning.optim.simplified_gradient import calibrate
from suspension_tuning.studies.design_space import (
    cosine,
    gradient_agreement,
    grid_comparison,
    r_squared,
    validation_points,
)
from suspension_tuning.studies.noise import noise_measure, step_sweep, sweep_x1


def test_noise_measure_recovers_known_noise_and_ignores_smooth_trends():
    x = np.linspace(0.4, 0.6, 401)
    smooth = 3.0 * (x - 0.5) ** 2 + 0.2 * x
    # a quadratic has zero third differences: no noise (round-off only, ~1e-16)
    assert noise_measure(x, smooth)['noise_rms'] < 1e-12
    # white noise of sigma 1e-3 on top: the difference-table estimate is within 15 %
    # (401 samples: the estimate's relative standard error is ~ sqrt(1/398 * 35/20) ~ 7 %)
    y = smooth + np.random.default_rng(5).normal(0, 1e-3, x.size)
    m = noise_measure(x, y, step=0.025)
    assert m['noise_rms'] == pytest.approx(1e-3, rel=0.15)
    # central difference of half step h = 0.025: error sqrt(2) sigma / 2h
    assert m['fd_gradient_noise'] == pytest.approx(np.sqrt(2) * m['noise_rms'] / 0.05)
    # a constant function (tyre never lifts off: g = -1) has no noise, undefined ratio
    c = noise_measure(x, np.full(x.size, -1.0))
    assert c['noise_rms'] == 0.0 and np.isnan(c['noise_rel'])


def test_cosine_and_r_squared_hand_values():
    assert cosine(np.array([1.0, 0.0]), np.array([1.0, 1.0])) == pytest.approx(np.sqrt(0.5))
    assert np.isnan(cosine(np.zeros(2), np.ones(2)))
    # model = full gives 1; model = mean gives 0
    f = np.array([1.0, 2.0, 3.0])
    assert r_squared(f, f) == 1.0
    assert r_squared(f, np.full(3, 2.0)) == 0.0


def test_ride_noise_sweep_writes_plot_and_reports_both_models(tmp_path):
    png = tmp_path / 'noise.png'
    res = sweep_x1('ride', None, 2, n_points=9, half_width=0.02, png=png)
    assert png.stat().st_size > 10_000
    assert res['full'].shape == (9, 5) and res['simplified'].shape == (9, 5)
    for model in ('full', 'simplified'):
        assert set(res['noise'][model]) == {'f', 'g_fl', 'g_fr', 'g_rl', 'g_rr'}
        assert np.isfinite(res['noise'][model]['f']['noise_rms'])


def test_handling_grid_comparison_writes_plot(tmp_path):
    sc = calibrate('handling', 2, n_samples=6)
    png = tmp_path / 'grid.png'
    out = grid_comparison('handling', sc, 2, grid_points=3, png=png)
    assert out['f_full'].shape == (9,) and out['f_simplified'].shape == (9,)
    assert png.stat().st_size > 10_000
    assert -np.inf < out['r2'] <= 1.0


@pytest.mark.parametrize('scenario', ['ride', 'handling'])
def test_gradient_directions_agree_at_ten_points(scenario):
    # Acceptance: full-model vs eq. 25-scaled simplified central-difference
    # gradients of f at 10 interior LHS points.  Measured at commit time: cosine
    # >= 0.99 (ride) and >= 0.97 (handling) at every point.  The assertion (>= 0.9,
    # i.e. within 26 deg) is what a gradient source for Dynamic-Q needs to point the
    # step the right way; a wrong sign or a swapped variable gives <= 0.
    sc = calibrate(scenario, 2)
    ga = gradient_agreement(scenario, sc, validation_points(2, 10), 2)
    assert ga['cosine'].shape == (10,)
    assert np.all(ga['cosine'] >= 0.9), ga['cosine']


def test_step_sweep_returns_both_gradients_per_step():
    # the gradient of f at the centre for two half steps; both models are smooth at the
    # scale of h (noise study: ~1e-8 noise on f), so the two steps' full-model gradients
    # agree to 1 % (measured 0.3 %) and each simplified gradient points the same way
    # (measured cosine 0.995)
    st = step_sweep('ride', None, 2, steps=(0.01, 0.025))
    assert st['df_full'].shape == (2, 2) and st['df_simplified'].shape == (2, 2)
    np.testing.assert_allclose(st['df_full'][0], st['df_full'][1], rtol=0.01)
    assert np.all(st['cosine'] > 0.9)
