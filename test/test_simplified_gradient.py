"""Tests of the central-difference gradient source on the scaled simplified models."""

from __future__ import annotations

import numpy as np
import pytest

from suspension_tuning.optim.scaling import fit_scaling
from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    calibrate,
    simplified_values,
)
from suspension_tuning.vehicle.scenarios import run_scenario
from suspension_tuning.vehicle.simplified import SimplifiedInputs, run_simplified


def _toy_scaling(factor_f=2.0):
    # simplified f in [0, 1] mapped to [0, factor_f]; constraints with unit factor
    x = np.array([[0.1, 0.1], [0.9, 0.9]])
    simp = np.array([[0.0, -1, -1, -1, -1], [1.0, -1, -1, -1, -1]])
    full = np.array([[0.0, -1, -1, -1, -1], [factor_f, -1, -1, -1, -1]])
    return fit_scaling(x, full, simp, key={'scenario': 'ride', 'n_vars': 2})


def test_gradient_is_scaled_central_difference_of_one_batch():
    grad = SimplifiedGradient('ride', 2, _toy_scaling(2.0), step=0.025)
    x = np.array([0.4, 0.6])
    df, dg, values = grad(x)
    assert df.shape == (2,) and dg.shape == (4, 2) and values.shape == (5,)
    assert grad.n_runs == 5  # 2n stencil runs and x itself, one batch
    # hand: eq. 25 factor 2 times (f(x + h e_i) - f(x - h e_i)) / 2h
    pts = np.array([[0.425, 0.6], [0.4, 0.625], [0.375, 0.6], [0.4, 0.575], [0.4, 0.6]])
    out = run_simplified('ride', pts, 2)
    f, g = out['f'], out['g_soft']
    np.testing.assert_allclose(df, 2.0 * (f[:2] - f[2:4]) / 0.05, rtol=1e-9)
    # the toy constraints are constant in the samples ('simplified_constant' rule): unit
    # factor, so the constraint Jacobian is the plain central difference of the pitch-
    # plane model's smooth tyre-hop measure (config tyre_hop_gradient: soft; the Belgian
    # paving unloads its tyres here)
    np.testing.assert_allclose(dg, ((g[:2] - g[2:4]) / 0.05).T, rtol=1e-9, atol=1e-12)
    assert np.any(dg != 0.0)
    # the values at x: eq. 25 of the model's own values there (f: factor 2, offset 0;
    # constraints: unit factor, offset F_Amin - F_Mmin = 0)
    np.testing.assert_allclose(values, np.r_[2.0 * f[4], g[4]], rtol=1e-12)


def test_stencil_never_leaves_the_bounds():
    seen = []

    class Recording(SimplifiedGradient):
        def values(self, x, inputs=None):
            seen.append(np.array(x))
            return super().values(x, inputs)

    grad = Recording('ride', 2, None, step=0.05)
    df, _, _ = grad(np.array([0.001, 1.0]))
    pts = np.vstack(seen)
    assert np.all(pts >= 0.001) and np.all(pts <= 1.0)
    # at the bounds the pair is shifted inside with width 2h = 0.1 (finite_diff.py); the
    # fifth point is x itself
    np.testing.assert_allclose(sorted(pts[:, 0]), [0.001, 0.001, 0.001, 0.001, 0.101])
    assert np.all(np.isfinite(df))


def test_handling_needs_inputs_and_mismatched_scaling_is_rejected():
    with pytest.raises(ValueError, match='handling'):
        SimplifiedGradient('handling', 2)(np.array([0.5, 0.5]))
    with pytest.raises(ValueError, match='scenario'):
        SimplifiedGradient('handling', 2, _toy_scaling())
    with pytest.raises(ValueError, match='unknown scenario'):
        SimplifiedGradient('pothole', 2)
    with pytest.raises(ValueError, match='step'):
        SimplifiedGradient('ride', 2, step=0.0)
    with pytest.raises(ValueError, match='outside the bounds'):
        SimplifiedGradient('ride', 2)(np.array([0.5, 1.2]))


def test_handling_gradient_uses_full_run_inputs():
    full = run_scenario('handling', np.array([[0.5, 0.5]]))
    inputs = SimplifiedInputs.from_scenario_result(full)
    grad = SimplifiedGradient('handling', 2, None, step=0.025)
    df, dg, _ = grad(np.array([0.5, 0.5]), full)  # a ScenarioResult is accepted as inputs
    df2, _, _ = grad(np.array([0.5, 0.5]), inputs)
    np.testing.assert_array_equal(df, df2)
    # hand check of one component from the model's values
    v = simplified_values('handling', np.array([[0.525, 0.5], [0.475, 0.5]]), 2, inputs)
    assert df[0] == pytest.approx((v[0, 0] - v[1, 0]) / 0.05, rel=1e-9)
    # stiffer spring (smaller gas volume) lowers roll: f_hand rises with x2 (gvol)
    assert df[1] > 0


@pytest.mark.parametrize('scenario', ['ride', 'handling'])
def test_scaled_simplified_model_explains_full_model_over_30_samples(scenario):
    # Acceptance: R^2 >= 0.9 of the eq. 25-scaled simplified f against the full
    # model's f over the paper's 30 samples (corners + LHS) of the 2-variable space.
    # Measured at commit time: ride 0.997, handling 0.913 (reported, not tuned).
    sc = calibrate(scenario, 2, n_samples=30)
    assert sc.x_samples.shape == (30, 2)
    f = sc.functions[0]
    assert f.rule == 'eq25'
    assert f.r2 >= 0.9, f'{scenario}: R^2 = {f.r2:.3f}'
    assert f.gradient_factor > 0  # same trend sense in both models


def test_calibration_settings_default_to_the_config_and_match_the_designs():
    from suspension_tuning.optim.simplified_gradient import (
        calibration_designs,
        calibration_settings,
    )
    from suspension_tuning.vehicle.pitch_plane import load_simplified_config

    cfg = load_simplified_config()['scaling']
    # [E] 16 samples (config; the paper used 30, 6.3.1)
    assert calibration_settings() == (16, int(cfg["seed"]))
    assert calibration_settings(12, 5) == (12, 5)
    x, n_samples, seed = calibration_designs(2, 12)
    assert (n_samples, seed) == calibration_settings(12) and x.shape == (12, 2)


def test_a_runs_calibration_samples_default_per_case_and_refuse_one():
    import pytest

    from suspension_tuning.optim.simplified_gradient import (
        calibration_settings,
        run_calibration_samples,
    )

    # config/simplified_models.yaml scaling.run_samples: none on the ride, 4 on handling
    # (measured paid full runs, docs/corrected_gradients.md); an unlisted size (mixed, 8
    # variables) takes scaling.n_samples
    assert run_calibration_samples('ride', 4) == run_calibration_samples('ride', 2, -1) == 0
    assert run_calibration_samples('ride', 8) == 0
    assert run_calibration_samples('handling', 4, None) == 4
    assert run_calibration_samples('mixed', 8) == calibration_settings()[0]
    assert run_calibration_samples('ride', 4, 0) == 0  # given: none
    assert run_calibration_samples('handling', 4, 16) == 16
    with pytest.raises(ValueError, match='at least 2 samples'):
        run_calibration_samples('ride', 4, 1)
