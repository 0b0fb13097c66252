"""Tests of the eq. 25 scaling (paper section 6.3.1)."""

from __future__ import annotations

import numpy as np
import pytest

from suspension_tuning.optim.scaling import (
    Scaling,
    config_hash,
    fit_function,
    fit_scaling,
    sample_design_space,
    scaling_key,
)


def test_eq25_hand_example():
    # simplified range [1, 5], full range [10, 30]: F_M = 2 maps to
    # (2 - 1)(30 - 10)/(5 - 1) + 10 = 15 (eq. 25); gradient factor 20/4 = 5
    fs = fit_function('f', full=[10.0, 30.0, 20.0], simplified=[1.0, 5.0, 3.0])
    assert fs.apply(2.0) == pytest.approx(15.0)
    assert fs.gradient_factor == pytest.approx(5.0)
    assert fs.rule == 'eq25'
    # the samples lie exactly on the map: R^2 = 1
    assert fs.r2 == pytest.approx(1.0)


def test_affine_relation_is_recovered_with_r2_one_and_negative_trend_fails():
    rng = np.random.default_rng(0)
    m = rng.uniform(-1, 1, 30)
    fs = fit_function('f', 3.0 * m + 2.0, m)
    np.testing.assert_allclose(fs.apply(m), 3.0 * m + 2.0, rtol=1e-12)
    assert fs.r2 == pytest.approx(1.0)
    # eq. 25 keeps the sense of the trend: an inverted simplified model gives R^2 < 0
    # (hand: F_s = full reflected about its mid-range, SS_res = 4 SS_tot for a symmetric
    # sample) while the squared correlation is still 1
    bad = fit_function('f', -m, m)
    assert bad.r2 < 0
    assert bad.r2_linear == pytest.approx(1.0)


def test_degenerate_ranges_follow_documented_rules():
    # tyre-hop constraint that never activates in the simplified model (all -1)
    fs = fit_function('g_fl', full=[-1.0, -0.8, -1.0], simplified=[-1.0, -1.0, -1.0])
    assert fs.rule == 'simplified_constant'
    assert fs.gradient_factor == 1.0
    # F_s = F_M - F_Mmin + F_Amin
    assert fs.apply(-1.0) == pytest.approx(-1.0)
    assert fs.apply(-0.5) == pytest.approx(-0.5)
    # full constant, simplified varies: eq. 25 as written, factor 0
    fc = fit_function('g_fl', full=[-1.0, -1.0, -1.0], simplified=[-1.0, -0.9, -0.5])
    assert fc.rule == 'full_constant'
    assert fc.gradient_factor == 0.0
    assert np.isnan(fc.r2)


def test_scaling_applies_per_function_and_round_trips_json(tmp_path):
    x = sample_design_space(2, 6, seed=1)
    simp = np.column_stack([np.arange(6.0), -np.ones((6, 4))])
    full = np.column_stack([2.0 * np.arange(6.0) + 1.0, -np.ones((6, 4))])
    key = {'scenario': 'ride', 'n_vars': 2, 'n_samples': 6, 'config_hash': 'abc'}
    sc = fit_scaling(x, full, simp, key=key)
    f, g = sc.apply_fg(np.array([2.5]), -np.ones((1, 4)))
    assert f[0] == pytest.approx(6.0)  # 2 * 2.5 + 1
    np.testing.assert_allclose(g, -1.0)
    np.testing.assert_allclose(sc.gradient_factors, [2.0, 1, 1, 1, 1])
    path = tmp_path / 'scaling.json'
    sc.save(path)
    back = Scaling.load(path, expected_key=key)
    # NaN R^2 of the constant constraints is stored as null and read back as NaN
    for mine, read in zip(sc.functions, back.functions, strict=True):
        assert (read.name, read.rule) == (mine.name, mine.rule)
        assert read.gradient_factor == mine.gradient_factor
        assert read.r2 == mine.r2 or (np.isnan(read.r2) and np.isnan(mine.r2))
    np.testing.assert_array_equal(back.x_samples, x)
    with pytest.raises(ValueError, match='does not match'):
        Scaling.load(path, expected_key={**key, 'n_vars': 4})
    (tmp_path / 'bad.json').write_text('{"format": "other"}')
    with pytest.raises(ValueError, match='not a suspension_tuning scaling'):
        Scaling.load(tmp_path / 'bad.json')


def test_samples_are_deterministic_in_bounds_with_corners_and_latin_strata():
    x = sample_design_space(2, 30, seed=2009)
    np.testing.assert_array_equal(x, sample_design_space(2, 30, seed=2009))
    assert x.shape == (30, 2)
    assert np.all(x >= 0.001) and np.all(x <= 1.0)
    corners = {(0.001, 0.001), (0.001, 1.0), (1.0, 0.001), (1.0, 1.0)}
    assert {tuple(r) for r in x[:4]} == corners
    # Latin hypercube: each of the 26 strata of each axis holds exactly one LHS point
    u = (x[4:] - 0.001) / 0.999
    for k in range(2):
        assert sorted(np.floor(u[:, k] * 26).astype(int)) == list(range(26))
    x4 = sample_design_space(4, 30, seed=1)
    assert x4.shape == (30, 4) and len({tuple(r) for r in x4[:16]}) == 16


def test_key_holds_config_hash_and_bad_inputs_raise():
    key = scaling_key('ride', 2, 30, 2009)
    assert key['config_hash'] == config_hash() and len(key['config_hash']) == 16
    with pytest.raises(ValueError):  # no variables (a preset may have any size >= 1)
        sample_design_space(0, 30)
    with pytest.raises(ValueError, match='NaN'):
        fit_function('f', [1.0, np.nan], [1.0, 2.0])
    with pytest.raises(ValueError, match='shapes disagree'):
        fit_scaling(np.zeros((3, 2)), np.zeros((3, 5)), np.zeros((2, 5)))
