"""Tests of the design-variable maps, paper eqs. 4-8."""

import numpy as np
import pytest

from suspension_tuning.vehicle.design import (
    VARIABLE_NAMES,
    X_LOWER,
    X_UPPER,
    AxleSettings,
    from_physical,
    load_design_space,
    to_physical,
    validate_design,
)


def test_constants_and_the_shipped_design_space_match_paper_section_5_1():
    assert (X_LOWER, X_UPPER) == (0.001, 1.0)  # eqs. 6, 8
    space = load_design_space()  # config/design_space.yaml
    for axle in ('front', 'rear'):
        dpsf, gvol = space.damper.axle(axle), space.spring.axle(axle)
        assert (dpsf.low, dpsf.high) == (0.1, 3.0)  # section 5.1: dpsf 0.1 to 3
        assert (gvol.low, gvol.high) == (0.1e-3, 0.6e-3)  # section 5.1: 0.1 to 0.6 litres
    assert VARIABLE_NAMES[2] == ('dpsf', 'gvol')
    assert VARIABLE_NAMES[4] == ('dpsf_front', 'gvol_front', 'dpsf_rear', 'gvol_rear')


def test_upper_bound_maps_to_range_end():
    s = to_physical([1.0, 1.0])
    # eq. 4 with x = 1: v = v_high exactly
    assert s.dpsf_front[0] == pytest.approx(3.0, abs=1e-15)
    assert s.gas_volume_front_m3[0] == pytest.approx(0.6e-3, abs=1e-18)


def test_lower_bound_maps_to_paper_value_not_range_end():
    s = to_physical([X_LOWER, X_LOWER])
    # eq. 4 with x = 0.001: dpsf = 0.1 + 0.001 * 2.9 = 0.1029 (the paper's choice)
    assert s.dpsf_front[0] == pytest.approx(0.1029, abs=1e-12)
    # gvol = 0.1 L + 0.001 * 0.5 L = 0.1005 L = 1.005e-4 m^3
    assert s.gas_volume_front_m3[0] == pytest.approx(1.005e-4, abs=1e-16)


def test_two_variables_give_identical_front_and_rear():
    s = to_physical([0.5, 0.25])
    # eq. 5: dpsf = 0.1 + 0.5 * 2.9 = 1.55 ; gvol = 0.1 + 0.25 * 0.5 = 0.225 L
    assert s.dpsf_front[0] == pytest.approx(1.55) and s.dpsf_rear[0] == pytest.approx(1.55)
    assert s.gas_volume_front_m3[0] == pytest.approx(0.225e-3)
    assert s.gas_volume_rear_m3[0] == pytest.approx(0.225e-3)


def test_four_variables_map_each_axle_separately():
    s = to_physical([0.2, 0.4, 0.6, 0.8])
    # eq. 7: 0.1 + 0.2*2.9 = 0.68 ; 0.1 + 0.4*0.5 = 0.3 L ; 0.1 + 0.6*2.9 = 1.84 ;
    # 0.1 + 0.8*0.5 = 0.5 L
    assert s.dpsf_front[0] == pytest.approx(0.68)
    assert s.gas_volume_front_m3[0] == pytest.approx(0.3e-3)
    assert s.dpsf_rear[0] == pytest.approx(1.84)
    assert s.gas_volume_rear_m3[0] == pytest.approx(0.5e-3)


def test_batch_shapes_and_round_trip():
    rng = np.random.default_rng(1)
    for n in (2, 4):
        x = rng.uniform(X_LOWER, X_UPPER, size=(7, n))
        s = to_physical(x)
        assert s.batch_size == 7 and s.dpsf_front.shape == (7,)
        # eq. 4 is affine, so the round trip is exact to rounding (1e-12)
        np.testing.assert_allclose(from_physical(s, n), x, rtol=0, atol=1e-12)


def test_from_physical_range_ends_give_zero_and_one():
    s = AxleSettings(
        dpsf_front=np.array([0.1, 3.0]),
        gas_volume_front_m3=np.array([0.1e-3, 0.6e-3]),
        dpsf_rear=np.array([0.1, 3.0]),
        gas_volume_rear_m3=np.array([0.1e-3, 0.6e-3]),
    )
    # eq. 4: v_low -> 0, v_high -> 1
    np.testing.assert_allclose(from_physical(s, 2), [[0.0, 0.0], [1.0, 1.0]], atol=1e-12)


def test_validate_returns_2d_float_array():
    out = validate_design([0.5, 0.5], 2)
    assert out.shape == (1, 2) and out.dtype == np.float64


@pytest.mark.parametrize('x', [[0.5], [0.5, 0.5, 0.5], [[0.5, 0.5, 0.5]]])
def test_wrong_length_raises(x):
    with pytest.raises(ValueError, match='shape'):
        validate_design(x, 2)


def test_wrong_length_for_to_physical_raises():
    with pytest.raises(ValueError, match='shape'):
        to_physical([0.5, 0.5, 0.5])


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_raises_naming_index(bad):
    with pytest.raises(ValueError, match=r'x\[1\].*not finite') as refusal:
        validate_design([0.5, bad], 2)
    # The number as a person reads it ('nan', 'inf'), not numpy's repr.
    assert str(refusal.value).endswith(f': {float(bad)}') and 'np.' not in str(refusal.value)


@pytest.mark.parametrize('value', [0.0, 0.0009, 1.0000001, -1.0, 2.0])
def test_out_of_bounds_raises_naming_index_and_value(value):
    with pytest.raises(ValueError, match=r'x\[2\].*outside the bounds') as refusal:
        validate_design([0.5, 0.5, value, 0.5], 4)
    assert f'= {float(value)} is outside' in str(refusal.value)


def test_bad_n_vars_raises():
    # 3 is neither the paper's 2 or 4 (section 5.1) nor the size of a shipped preset (8)
    with pytest.raises(ValueError, match='2 or 4.*preset'):
        load_design_space().to_physical([0.5, 0.5, 0.5], 3)
    with pytest.raises(ValueError, match='positive number'):
        validate_design([0.5], 0)


def test_from_physical_rejects_unequal_axles_for_two_variables():
    s = to_physical([0.2, 0.4, 0.6, 0.8])
    with pytest.raises(ValueError, match='identical front and rear'):
        from_physical(s, 2)


def test_from_physical_rejects_out_of_range_value():
    s = AxleSettings(
        dpsf_front=np.array([3.5]),  # above the 4S4 limit 3.0 (section 5.1)
        gas_volume_front_m3=np.array([0.3e-3]),
        dpsf_rear=np.array([1.0]),
        gas_volume_rear_m3=np.array([0.3e-3]),
    )
    with pytest.raises(ValueError, match='dpsf_front'):
        from_physical(s, 4)
