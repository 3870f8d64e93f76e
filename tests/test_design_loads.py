"""EN 1991-4 design loads (siloflow.design_loads) against hand computations written out here.

The expected values are computed in each test with plain arithmetic from the standard's
formulas and the Annex E wheat row (gamma_u 9.0 kN/m3, phi_r 34 deg, phi_im 30 deg, a_phi 1.12,
K_m 0.54, a_K 1.11, mu_m(D2) 0.38, a_mu 1.16, C_op 0.5), not with the module's helpers; the
numbers in the comments are those values, rounded.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from siloflow.case_file import case_from_dict
from siloflow.cli import app
from siloflow.design_loads import (MATERIALS, bulk_solid, classify, design_loads, hopper_is_steep)
from siloflow.plan import Silo
from postprocess.en_verdicts import compare_with_dem
from postprocess.report.figures import design_figure

from conftest import QUICK

# wheat, wall type D2, characteristic values (EN 1991-4 §4.2.3): x_u = a x_m, x_l = x_m / a
GAMMA = 9.0e3                      # N/m3: gamma_u, used for every load
K_U = 1.11 * 0.54                  # 0.5994
K_L = 0.54 / 1.11                  # 0.48649
MU_U = 1.16 * 0.38                 # 0.4408
MU_L = 0.38 / 1.16                 # 0.32759
TAN_PHI_R = math.tan(math.radians(34.0))   # 0.67451


def cylinder(radius, height=30.0):
    return Silo(kind="cylinder", half_width=radius, radius=radius, height=height, hopper_height=0.0,
                outlet_radius=0.1 * radius)


def hopper(radius, half_angle_deg, outlet_radius=0.3, height=30.0):
    h = (radius - outlet_radius) / math.tan(math.radians(half_angle_deg))
    return Silo(kind="hopper", half_width=radius, radius=radius, height=height, hopper_height=h,
                outlet_radius=outlet_radius)


def test_slender_wheat_silo_filling_pressure_by_hand():
    # d_c = 6 m, h_c = 20 m (h_c/d_c = 3.33: slender), flat bottom, equivalent surface at 20 m
    # A/U = (pi r^2)/(2 pi r) = r/2 = 1.5 m
    # max horizontal pressure: K upper, mu lower (Table 3.1)
    # z_o = (A/U) / (K mu) = 1.5 / (0.5994 * 0.32759) = 1.5 / 0.19636 = 7.6392 m
    # p_ho = gamma K z_o = 9000 * 0.5994 * 7.6392 = 41210.5 Pa (= gamma (A/U) / mu)
    # p_hf(z) = p_ho (1 - exp(-z / z_o))
    z_o = 1.5 / (K_U * MU_L)
    p_ho = GAMMA * K_U * z_o
    assert z_o == pytest.approx(7.6392, rel=1e-4) and p_ho == pytest.approx(41210.5, rel=1e-5)
    depths = np.array([2.0, 5.0, 10.0, 20.0])
    expected = [p_ho * (1.0 - math.exp(-z / z_o)) for z in depths]
    # 2 m: 41210.5 * (1 - exp(-0.26181)) = 41210.5 * 0.23034 = 9492 Pa
    # 5 m: 41210.5 * (1 - exp(-0.65452)) = 19794 Pa; 10 m: 30080 Pa; 20 m: 38204 Pa
    assert expected == pytest.approx([9492.4, 19793.7, 30080.4, 38204.5], rel=1e-4)
    loads = design_loads(cylinder(3.0), "wheat", 20.0, "D2", heights=20.0 - depths)
    assert loads.classification == "slender"
    np.testing.assert_allclose(loads.p_hf, expected, rtol=0.01)
    # wall friction, max-friction case (K upper, mu upper): p_wf = mu p_ho Y_J with its own z_o
    z_o_w = 1.5 / (K_U * MU_U)                      # 5.6772 m
    p_wf = [MU_U * GAMMA * K_U * z_o_w * (1.0 - math.exp(-z / z_o_w)) for z in depths]
    np.testing.assert_allclose(loads.p_wf, p_wf, rtol=0.01)
    # vertical, max-vertical case (K lower, mu lower): p_vf = gamma z_o (1 - exp(-z/z_o))
    z_o_v = 1.5 / (K_L * MU_L)                      # 9.4123 m
    p_vf = [GAMMA * z_o_v * (1.0 - math.exp(-z / z_o_v)) for z in depths]
    np.testing.assert_allclose(loads.p_vf, p_vf, rtol=0.01)
    # discharge, slender AAC 2: p_he = 1.15 p_hf, p_we = 1.10 p_wf
    np.testing.assert_allclose(loads.p_he, 1.15 * np.array(expected), rtol=0.01)
    np.testing.assert_allclose(loads.p_we, 1.10 * np.array(p_wf), rtol=0.01)


def test_squat_wheat_silo_filling_pressure_by_hand():
    # d_c = 10 m, h_c = 8 m (h_c/d_c = 0.8: squat), A/U = 2.5 m
    # z_o = 2.5 / (0.5994 * 0.32759) = 12.7320 m; p_ho = gamma (A/U) / mu = 9000 * 2.5 / 0.32759 = 68684 Pa
    z_o = 2.5 / (K_U * MU_L)
    p_ho = GAMMA * 2.5 / MU_L
    assert z_o == pytest.approx(12.732, rel=1e-4) and p_ho == pytest.approx(68684.2, rel=1e-5)
    depths = np.array([2.0, 4.0, 8.0])
    # flat top: the highest wall contact is the equivalent surface, h_o = 0
    # n = -(1 + tan 34 deg)(1 - 0/z_o) = -1.67451
    # Y_R(z) = 1 - (z/z_o + 1)^n; 2 m: 1 - (1.15708)^-1.67451 = 0.21676 -> p_hf = 14888 Pa
    n = -(1.0 + TAN_PHI_R)
    flat = [p_ho * (1.0 - (z / z_o + 1.0) ** n) for z in depths]
    assert flat == pytest.approx([14888.0, 25215.7, 38325.1], rel=1e-4)
    loads = design_loads(cylinder(5.0), "wheat", 8.0, "D2", heights=8.0 - depths)
    assert loads.classification == "squat" and loads.h_o == 0.0
    np.testing.assert_allclose(loads.p_hf, flat, rtol=0.01)
    # heap (the standard's symmetrical filling): h_o = (r/3) tan phi_r = (5/3) 0.67451 = 1.12418 m
    # n = -1.67451 (1 - 1.12418/12.732) = -1.52666; Y_R = 1 - ((z - h_o)/(z_o - h_o) + 1)^n
    h_o = 5.0 / 3.0 * TAN_PHI_R
    n_heap = -(1.0 + TAN_PHI_R) * (1.0 - h_o / z_o)
    heap = [p_ho * (1.0 - ((z - h_o) / (z_o - h_o) + 1.0) ** n_heap) for z in depths]
    assert heap == pytest.approx([7219.0, 19694.6, 34923.1], rel=1e-4)
    loads = design_loads(cylinder(5.0), "wheat", 8.0, "D2", heights=8.0 - depths, top="heap")
    np.testing.assert_allclose(loads.p_hf, heap, rtol=0.01)
    # squat silos: discharge = filling, no discharge factor
    assert loads.C_h == loads.C_w == 1.0
    np.testing.assert_allclose(loads.p_he, loads.p_hf)


def test_squat_vertical_stress_is_the_slice_equilibrium():
    # p_vf = gamma z_V must solve dp_v/dz = gamma - (U/A) mu p_hf = gamma (1 - Y_R), with
    # p_v(h_o) = gamma h_o; integrate that numerically (trapezoid) with the max-vertical K, mu
    r, h_c = 5.0, 8.0
    z_o = 2.5 / (K_L * MU_L)
    h_o = r / 3.0 * TAN_PHI_R
    n = -(1.0 + TAN_PHI_R) * (1.0 - h_o / z_o)
    z = np.linspace(h_o, h_c, 20001)
    rate = GAMMA * ((z - h_o) / (z_o - h_o) + 1.0) ** n
    p_v = GAMMA * h_o + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(z))])
    loads = design_loads(cylinder(r), "wheat", h_c, "D2", heights=h_c - z[::2000], top="heap")
    np.testing.assert_allclose(loads.p_vf, p_v[::2000], rtol=1e-6)


def test_characteristic_values_per_load_case():
    loads = design_loads(cylinder(3.0), "wheat", 20.0, "D2")
    assert loads.K["max_horizontal"] == pytest.approx(K_U) and loads.mu["max_horizontal"] == pytest.approx(MU_L)
    assert loads.K["max_friction"] == pytest.approx(K_U) and loads.mu["max_friction"] == pytest.approx(MU_U)
    assert loads.K["max_vertical"] == pytest.approx(K_L) and loads.mu["max_vertical"] == pytest.approx(MU_L)
    assert loads.z_o["max_horizontal"] == pytest.approx(1.5 / (K_U * MU_L))
    # the wall type picks the friction column: D3 wheat mu_m 0.57 -> mu_l = 0.57 / 1.16
    d3 = design_loads(cylinder(3.0), "wheat", 20.0, "D3")
    assert d3.mu["max_horizontal"] == pytest.approx(0.57 / 1.16)
    # explicit values replace the table's and are used for every load case
    solid = bulk_solid(None, unit_weight=8000.0, K=0.5, mu=0.4, phi_r=30.0)
    hand = design_loads(cylinder(3.0), solid, 20.0)
    assert set(hand.K.values()) == {0.5} and set(hand.mu.values()) == {0.4}
    assert hand.p_hf[0] == pytest.approx(8000.0 * 1.5 / 0.4 * (1.0 - math.exp(-20.0 / (1.5 / 0.2))), rel=1e-9)
    with pytest.raises(ValueError, match="unit_weight"):
        bulk_solid(None, K=0.5, mu=0.4)
    with pytest.raises(ValueError, match="not in the EN 1991-4"):
        bulk_solid("gravelx")


def test_material_table_is_self_consistent():
    # the standard's estimate K_m ~ 1.1 (1 - sin phi_im) (a transcription check only)
    for m in MATERIALS.values():
        assert m.K_m == pytest.approx(1.1 * (1.0 - math.sin(math.radians(m.phi_im))), abs=0.04), m.name
        assert m.gamma_l <= m.gamma_u and m.mu_m[0] <= m.mu_m[1] <= m.mu_m[2]
    w = MATERIALS["wheat"]
    assert (w.gamma_l, w.gamma_u, w.phi_r, w.K_m, w.mu_m, w.C_op) == (7500.0, 9000.0, 34, 0.54, (0.24, 0.38, 0.57), 0.5)


def test_classification_boundaries():
    """EN 1991-4:2006 §5.1(2)-(3) (and the terms of §1.5): slender 2.0 <= h_c/d_c; intermediate
    1.0 < h_c/d_c < 2.0; squat 0.4 < h_c/d_c <= 1.0; retaining: a flat bottom and h_c/d_c <= 0.4;
    a silo with a hopper and h_c/d_c <= 0.4 is classed as squat. So h_c/d_c = 0.4 exactly is a
    retaining silo on a flat bottom (siloflow had it squat before issue 37)."""
    assert classify(2.0) == "slender" and classify(1.999) == "intermediate"
    assert classify(1.0001) == "intermediate" and classify(1.0) == "squat"
    assert classify(0.4001) == "squat" and classify(0.4) == "retaining" and classify(0.399) == "retaining"
    assert classify(0.4, flat_bottom=False) == "squat"        # a hopper silo is never "retaining"
    assert classify(0.399, flat_bottom=False) == "squat"
    # through the geometry: d_c = 6 m, fills of 12, 9, 6 and 2 m
    got = [design_loads(cylinder(3.0), "wheat", h).classification for h in (12.0, 9.0, 6.0, 2.0)]
    assert got == ["slender", "intermediate", "squat", "retaining"]


def test_discharge_and_patch_factors():
    # slender d_c = 6, h_c = 20: h_c/d_c = 3.3333
    # C_pf = 0.21 C_op (1 + 2 E^2)(1 - exp(-1.5 (h_c/d_c - 1))) = 0.21 * 0.5 * (1 - exp(-3.5)) = 0.101829
    # C_pe = 0.42 ... = 0.203659
    loads = design_loads(cylinder(3.0), "wheat", 20.0)
    growth = 1.0 - math.exp(-1.5 * (20.0 / 6.0 - 1.0))
    assert loads.C_pf == pytest.approx(0.21 * 0.5 * growth) == pytest.approx(0.101829, rel=1e-5)
    assert loads.C_pe == pytest.approx(0.42 * 0.5 * growth)
    assert loads.patch_height == pytest.approx(math.pi * 6.0 / 16.0)          # 1.178 m ~ 0.2 d_c
    np.testing.assert_allclose(loads.p_patch, loads.C_pe * loads.p_he)
    # eccentricity e = 0.6 m: E = 2 e / d_c = 0.2, 1 + 2 E^2 = 1.08
    ecc = design_loads(cylinder(3.0), "wheat", 20.0, eccentricity=0.6)
    assert ecc.C_pf == pytest.approx(0.21 * 0.5 * 1.08 * growth)
    # AAC 1: no patch; C_h = 1.15 + 1.5 (1 + 0.4 e/d_c) C_op = 1.15 + 1.5 * 1.04 * 0.5 = 1.93, C_w = 1.4 * 1.04
    aac1 = design_loads(cylinder(3.0), "wheat", 20.0, aac=1, eccentricity=0.6)
    assert (aac1.C_pf, aac1.C_pe) == (0.0, 0.0)
    assert aac1.C_h == pytest.approx(1.93) and aac1.C_w == pytest.approx(1.456)
    # intermediate h_c/d_c = 1.5: C_S = 0.5, C_h = 1 + 0.15 C_S = 1.075, C_w = 1 + 0.1 C_S = 1.05
    mid = design_loads(cylinder(3.0), "wheat", 9.0)
    assert (mid.C_h, mid.C_w) == (pytest.approx(1.075), pytest.approx(1.05))
    # the intermediate factors meet the slender ones at h_c/d_c = 2, for AAC 1 and 2 alike
    for aac in (1, 2):
        below = design_loads(cylinder(3.0), "wheat", 11.999, aac=aac, eccentricity=0.6)
        above = design_loads(cylinder(3.0), "wheat", 12.0, aac=aac, eccentricity=0.6)
        assert (below.classification, above.classification) == ("intermediate", "slender")
        assert below.C_h == pytest.approx(above.C_h, abs=1e-3) and below.C_w == pytest.approx(above.C_w, abs=1e-3)
    # squat: no filling patch (the factor is clipped at 0)
    assert design_loads(cylinder(3.0), "wheat", 5.0).C_pf == 0.0


def test_hopper_steep_or_shallow_and_filling_pressure():
    # steep when tan beta < (1 - K_l) / (2 mu_h,l) = (1 - 0.48649) / (2 * 0.32759) = 0.78378 (beta 38.1 deg)
    limit = (1.0 - K_L) / (2.0 * MU_L)
    assert limit == pytest.approx(0.78378, rel=1e-4)
    assert hopper_is_steep(30.0, K_L, MU_L) and not hopper_is_steep(45.0, K_L, MU_L)
    steep = design_loads(hopper(3.0, 30.0), "wheat", hopper(3.0, 30.0).hopper_height + 20.0)
    shallow = design_loads(hopper(3.0, 45.0), "wheat", hopper(3.0, 45.0).hopper_height + 20.0)
    assert steep.hopper.steep and not shallow.hopper.steep
    assert shallow.hopper.mu_h == pytest.approx((1.0 - K_L) / (2.0 * math.tan(math.radians(45.0))))

    # steep 30 deg hopper under a 20 m slender column (d_c = 6 m), AAC 2 (C_b = 1.0):
    # p_vft = C_b gamma z_o,v (1 - exp(-20 / z_o,v)), z_o,v = 1.5 / (K_l mu_l) = 9.4123 m -> 74592 Pa
    z_o_v = 1.5 / (K_L * MU_L)
    p_vft = 1.0 * GAMMA * z_o_v * (1.0 - math.exp(-20.0 / z_o_v))
    assert p_vft == pytest.approx(74592.0, rel=1e-4)
    # apex to transition h_h = r / tan beta = 3 / 0.57735 = 5.19615 m
    # F_f = 1 - b / (1 + tan beta / mu_h) = 1 - 0.2 / (1 + 0.57735 / 0.32759) = 0.92760
    # n = S (F mu_h cot beta + F) - 2 = 2 (0.92760 * 0.32759 * 1.73205 + 0.92760) - 2 = 0.90783
    t = math.tan(math.radians(30.0))
    h_h = 3.0 / t
    F = 1.0 - 0.2 / (1.0 + t / MU_L)
    n = 2.0 * (F * MU_L / t + F) - 2.0
    assert (F, n) == (pytest.approx(0.92760, rel=1e-4), pytest.approx(0.90783, rel=1e-4))
    # mid-hopper x = h_h / 2: p_v = gamma h_h / (n - 1) (x/h_h - (x/h_h)^n) + p_vft (x/h_h)^n
    x = 0.5 * h_h
    p_v = GAMMA * h_h / (n - 1.0) * (0.5 - 0.5 ** n) + p_vft * 0.5 ** n
    z = x - 0.3 / t                                  # the outlet (radius 0.3 m) is 0.5196 m above the apex
    got = design_loads(hopper(3.0, 30.0), "wheat", hopper(3.0, 30.0).hopper_height + 20.0, heights=[z])
    assert got.p_v_hopper[0] == pytest.approx(p_v, rel=0.01)
    assert got.p_nf[0] == pytest.approx(F * p_v, rel=0.01)
    # discharge: F_e = (1 + sin phi_i cos eps) / (1 - sin phi_i cos(2 beta + eps)), phi_i upper = 33.6 deg,
    # phi_wh = atan 0.32759 = 18.14 deg, eps = phi_wh + asin(sin phi_wh / sin phi_i) = 52.37 deg -> F_e = 1.1051
    s = math.sin(math.radians(30.0 * 1.12))
    phi_wh = math.atan(MU_L)
    eps = phi_wh + math.asin(math.sin(phi_wh) / s)
    F_e = (1.0 + s * math.cos(eps)) / (1.0 - s * math.cos(math.radians(60.0) + eps))
    assert got.hopper.F_e == pytest.approx(F_e, rel=1e-6) == pytest.approx(1.1051, rel=1e-3)


def test_refuses_what_the_standard_does_not_cover():
    slab = Silo(kind="planar", half_width=0.1, height=0.5, hopper_height=0.05, outlet_radius=0.01,
                width=0.2, thickness=0.0044)
    with pytest.raises(ValueError, match="planar"):
        design_loads(slab, "wheat", 0.3)
    with pytest.raises(ValueError, match="does not reach above the hopper"):
        design_loads(hopper(3.0, 30.0), "wheat", 1.0)
    with pytest.raises(ValueError, match="wall_type"):
        design_loads(cylinder(3.0), "wheat", 10.0, wall_type="D4")
    with pytest.raises(ValueError, match="angle of repose"):
        design_loads(cylinder(3.0), bulk_solid(None, unit_weight=8e3, K=0.5, mu=0.4), 4.0)   # squat


def test_design_settings_in_the_case(quick_dict):
    quick_dict["design"] = {"material": "maize", "wall_type": "D3", "action_assessment_class": 1}
    assert case_from_dict(quick_dict).design.material == "maize"
    from siloflow.errors import CaseError
    for bad, field in (({"material": "gravelx"}, "design"), ({"K": 0.5}, "design"),
                       ({"material": "wheat", "K": 1.5}, "design.K"),
                       ({"material": "wheat", "action_assessment_class": 4}, "design.action_assessment_class"),
                       ({"material": "wheat", "wall_type": "D4"}, "design.wall_type")):
        quick_dict["design"] = bad
        with pytest.raises(CaseError) as info:
            case_from_dict(quick_dict)
        assert any(path.startswith(field) for path, _ in info.value.problems), info.value.problems


def test_compare_with_dem_on_a_made_up_band_table(tmp_path):
    loads = design_loads(cylinder(3.0), "wheat", 20.0)
    bands = pd.DataFrame({"band": [0, 1, 2], "z_mid": [10.0, 18.0, 25.0],
                          "static_pressure": [15000.0, 4000.0, 0.0], "max_dynamic_pressure": [30000.0, 6000.0, 0.0]})
    table = compare_with_dem(loads, bands)
    p_hf_10 = 41210.5 * (1.0 - math.exp(-10.0 / 7.6392))     # 30080 Pa, depth 10 m
    assert table.en_p_hf[0] == pytest.approx(p_hf_10, rel=1e-3)
    assert table.en_p_he[0] == pytest.approx(1.15 * p_hf_10, rel=1e-3)
    assert table.static_over_p_hf[0] == pytest.approx(15000.0 / p_hf_10, rel=1e-3)
    assert table.max_dynamic_over_p_he[0] == pytest.approx(30000.0 / (1.15 * p_hf_10), rel=1e-3)
    assert table.dem_discharge_factor.tolist()[:2] == [2.0, 1.5] and (table.en_C_h == 1.15).all()
    assert np.isnan(table.en_p_hf[2]) and np.isnan(table.static_over_p_hf[2])     # above the fill
    assert np.isnan(table.dem_discharge_factor[2])
    path = design_figure(loads, tmp_path / "fig.png", bands)
    assert path.stat().st_size > 1000


def test_cli_design_on_the_quick_case(tmp_path):
    out = tmp_path / "tmp"
    result = CliRunner().invoke(app, ["design", str(QUICK), "-o", str(out)], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    assert "no design section: wheat" in result.output and "slender" in result.output
    table = pd.read_csv(out / "design_loads.csv")
    assert {"z", "p_hf", "p_wf", "p_vf", "p_he", "p_patch"} <= set(table.columns)
    assert (out / "design_loads.png").stat().st_size > 1000
    # with a run's bands.csv beside it
    run = tmp_path / "run"
    assert CliRunner().invoke(app, ["render", str(QUICK), "-o", str(run)]).exit_code == 0
    (run / "results").mkdir(parents=True)
    pd.DataFrame({"band": [0], "z_mid": [0.05], "static_pressure": [150.0],
                  "max_dynamic_pressure": [300.0]}).to_csv(run / "results" / "bands.csv", index=False)
    result = CliRunner().invoke(app, ["design", str(QUICK), "-o", str(out), "--run", str(run)], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    assert pd.read_csv(out / "design_vs_dem.csv").dem_discharge_factor[0] == pytest.approx(2.0)


def test_explicit_design_values_are_physically_bounded(quick_dict, write_case, tmp_path):
    """Issue 34.7: K = mu = 1e-300 passed the schema and K mu underflowed to 0 (ZeroDivisionError)."""
    from siloflow.case import DESIGN_RANGES
    from siloflow.design_loads import EXPLICIT_RANGES
    from siloflow.errors import CaseError
    assert DESIGN_RANGES == EXPLICIT_RANGES
    for values, fields in (({"K": 1.0e-300, "mu": 1.0e-300}, {"design.K", "design.mu"}),
                           ({"K": 0.05}, {"design.K"}), ({"K": 1.2}, {"design.K"}),
                           ({"mu": 0.01}, {"design.mu"}), ({"mu": 1.6}, {"design.mu"}),
                           ({"unit_weight": 50.0}, {"design.unit_weight"}),
                           ({"unit_weight": 2e5}, {"design.unit_weight"})):
        quick_dict["design"] = {"unit_weight": 100.0, "K": 0.5, "mu": 0.4, **values}
        with pytest.raises(CaseError) as info:
            case_from_dict(quick_dict)
        assert {path for path, _ in info.value.problems} == fields, info.value.problems
        with pytest.raises(ValueError, match="outside"):
            bulk_solid(None, **{"unit_weight": 100.0, "K": 0.5, "mu": 0.4, **values})
    quick_dict["design"] = {"unit_weight": 100.0, "K": 1.0e-300, "mu": 1.0e-300}
    result = CliRunner().invoke(app, ["design", str(write_case(quick_dict)), "-o", str(tmp_path / "d")])
    assert result.exit_code == 1 and "design.K" in result.output and "design.mu" in result.output
    assert "Traceback" not in result.output and not isinstance(result.exception, ZeroDivisionError)
    for K, mu in ((0.1, 0.05), (1.0, 1.5)):          # the bounds themselves are loads
        quick_dict["design"] = {"unit_weight": 100.0, "K": K, "mu": mu}
        case = case_from_dict(quick_dict)
        loads = design_loads(cylinder(3.0), bulk_solid(None, unit_weight=100.0, K=K, mu=mu), 20.0)
        assert case.design.K == K and np.isfinite(loads.p_hf[loads.z < 20.0]).all()


def test_design_refuses_a_run_of_another_case(tmp_path, quick_dict, write_case):
    """Issue 34.7: ``design case.yaml --run R`` took the band pressures of a run of another silo."""
    run = tmp_path / "run"
    assert CliRunner().invoke(app, ["render", str(QUICK), "-o", str(run)]).exit_code == 0
    (run / "results").mkdir()
    pd.DataFrame({"band": [0], "z_mid": [0.05], "static_pressure": [150.0],
                  "max_dynamic_pressure": [300.0]}).to_csv(run / "results" / "bands.csv", index=False)
    wider = write_case({**quick_dict, "geometry": {**quick_dict["geometry"], "radius": 0.02}}, "wider.yaml")
    result = CliRunner().invoke(app, ["design", str(wider), "-o", str(tmp_path / "d"), "--run", str(run)],
                                env={"COLUMNS": "400"})
    assert result.exit_code == 1, result.output
    assert "run of another case" in result.output and "geometry.radius: 0.02 here, 0.015 in the run's case" \
        in result.output
    assert not (tmp_path / "d").exists()
    heavier = dict(quick_dict, materials={**quick_dict["materials"],
                                          "particle": {**quick_dict["materials"]["particle"], "density": 2600.0}})
    result = CliRunner().invoke(app, ["design", str(write_case(heavier, "heavier.yaml")), "-o", str(tmp_path / "d"),
                                      "--run", str(run)], env={"COLUMNS": "400"})
    assert result.exit_code == 1 and "materials.particle.density" in result.output
    # what the design does not depend on may differ (the run's length, its outputs, its name)
    other = dict(quick_dict, name="other", discharge={"duration": 2.0}, design={"material": "maize"})
    result = CliRunner().invoke(app, ["design", str(write_case(other, "other.yaml")), "-o", str(tmp_path / "d"),
                                      "--run", str(run)], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    # a folder that is not a run folder (no case.yaml) is refused, not taken as this case's
    bare = tmp_path / "bare"
    (bare / "results").mkdir(parents=True)
    (run / "results" / "bands.csv").replace(bare / "results" / "bands.csv")
    result = CliRunner().invoke(app, ["design", str(QUICK), "-o", str(tmp_path / "d"), "--run", str(bare)])
    assert result.exit_code == 1 and "case.yaml" in result.output and result.exception.__class__ is SystemExit


# --------------------------------------------------------------------------- issue 37, item 7
# Each test below pins a value that a mutant of siloflow/design_loads.py got wrong undetected.

def test_intermediate_silo_aac1_discharge_factors_by_hand():
    """EN 1991-4 §5.3.2.2, AAC 1, intermediate silo (1 < h_c/d_c < 2), C_S = h_c/d_c - 1 (linear):
    C_h = 1 + (0.15 + 1.5 (1 + 0.4 e/d_c) C_op) C_S,  C_w = 1 + 0.4 (1 + 1.4 e/d_c) C_S."""
    # d_c = 6 m, h_c = 9 m: h_c/d_c = 1.5, C_S = 0.5; e = 0.6 m: e/d_c = 0.1
    # wheat C_op 0.5: C_h = 1 + (0.15 + 1.5 * 1.04 * 0.5) * 0.5 = 1 + 0.93 * 0.5 = 1.465
    #                 C_w = 1 + 0.4 * 1.14 * 0.5 = 1.228
    # (with C_S^2 = 0.25 these would be 1.2325 and 1.114)
    wheat = design_loads(cylinder(3.0), "wheat", 9.0, aac=1, eccentricity=0.6)
    assert wheat.classification == "intermediate"
    assert wheat.C_h == pytest.approx(1.465, rel=1e-9) and wheat.C_w == pytest.approx(1.228, rel=1e-9)
    np.testing.assert_allclose(wheat.p_he, 1.465 * wheat.p_hf, rtol=1e-12)
    np.testing.assert_allclose(wheat.p_we, 1.228 * wheat.p_wf, rtol=1e-12)
    # maize (Table E.1 C_op 0.9): C_h = 1 + (0.15 + 1.5 * 1.04 * 0.9) * 0.5 = 1 + 1.554 * 0.5 = 1.777
    maize = design_loads(cylinder(3.0), "maize", 9.0, aac=1, eccentricity=0.6)
    assert maize.C_h == pytest.approx(1.777, rel=1e-9) and maize.C_w == pytest.approx(1.228, rel=1e-9)
    # no eccentricity, h_c/d_c = 1.25 (h_c = 7.5 m): C_S = 0.25, C_h = 1 + 0.9 * 0.25 = 1.225, C_w = 1.1
    low = design_loads(cylinder(3.0), "wheat", 7.5, aac=1)
    assert (low.C_h, low.C_w) == (pytest.approx(1.225, rel=1e-9), pytest.approx(1.1, rel=1e-9))


def test_discharge_patch_factor_of_low_intermediate_silos_by_hand():
    """EN 1991-4 discharge patch, h_c/d_c <= 1.2: C_pe = 0.272 C_op (h_c/d_c - 1 + E), E = 2 e/d_c
    (above 1.2: C_pe = 0.42 C_op (1 + 2 E^2)(1 - exp(-1.5 (h_c/d_c - 1))))."""
    # d_c = 6 m, h_c = 6.6 m: h_c/d_c = 1.1; wheat C_op 0.5
    # e = 0.6 m: E = 0.2, C_pe = 0.272 * 0.5 * (0.1 + 0.2) = 0.0408
    ecc = design_loads(cylinder(3.0), "wheat", 6.6, eccentricity=0.6, heights=[3.0])
    assert ecc.classification == "intermediate"
    assert ecc.C_pe == pytest.approx(0.0408, rel=1e-9)
    assert ecc.p_pe[0] == pytest.approx(0.0408 * ecc.p_he[0], rel=1e-12) and ecc.p_pe[0] > 0
    # e = 0: C_pe = 0.272 * 0.5 * 0.1 = 0.0136
    assert design_loads(cylinder(3.0), "wheat", 6.6).C_pe == pytest.approx(0.0136, rel=1e-9)
    # maize C_op 0.9, e = 0: 0.272 * 0.9 * 0.1 = 0.02448
    assert design_loads(cylinder(3.0), "maize", 6.6).C_pe == pytest.approx(0.02448, rel=1e-9)
    # just above the switch, h_c/d_c = 1.3 (h_c = 7.8 m), E = 0.2:
    # C_pe = 0.42 * 0.5 * 1.08 * (1 - exp(-0.45)) = 0.082186
    above = design_loads(cylinder(3.0), "wheat", 7.8, eccentricity=0.6)
    assert above.C_pe == pytest.approx(0.42 * 0.5 * 1.08 * (1.0 - math.exp(-0.45)), rel=1e-9)
    assert above.C_pe == pytest.approx(0.082186, rel=1e-4)


def test_bottom_load_magnifier_by_hand():
    """EN 1991-4 §6.1.2: p_vft = C_b p_vf(h_c), C_b = 1.0 for AAC 2 and 3 and 1.3 for AAC 1; where the
    solid may load the bottom dynamically, 1.2 (AAC 2, 3) and 1.6 (AAC 1)."""
    # slender, d_c = 6 m, h_c = 20 m, flat bottom; max vertical case (K lower, mu lower):
    # p_vf(20 m) = gamma z_o,v (1 - exp(-20 / z_o,v)), z_o,v = 9.4123 m -> 74592.1 Pa
    z_o_v = 1.5 / (K_L * MU_L)
    p_vf = GAMMA * z_o_v * (1.0 - math.exp(-20.0 / z_o_v))
    assert p_vf == pytest.approx(74592.1, rel=1e-5)
    expected = {(1, False): 1.3, (2, False): 1.0, (3, False): 1.0,
                (1, True): 1.6, (2, True): 1.2, (3, True): 1.2}
    for (aac, dynamic), C_b in expected.items():
        loads = design_loads(cylinder(3.0), "wheat", 20.0, aac=aac, dynamic_bottom=dynamic, heights=[10.0])
        assert loads.C_b == C_b, (aac, dynamic)
        # AAC 1: 96969.8 Pa; AAC 1 dynamic: 119347.4 Pa; AAC 2/3 dynamic: 89510.5 Pa
        assert loads.p_vft == pytest.approx(C_b * p_vf, rel=1e-9), (aac, dynamic)
    # in a hopper silo p_vft is the hopper's stress at the transition, p_v(x = h_h) = C_b p_vf(h_c)
    h = hopper(3.0, 30.0)
    top = design_loads(h, "wheat", h.hopper_height + 20.0, aac=1, dynamic_bottom=True, heights=[h.hopper_height])
    assert top.hopper.C_b == 1.6
    assert top.p_v_hopper[0] == pytest.approx(1.6 * p_vf, rel=1e-9)


def test_hopper_discharge_and_filling_traction_by_hand():
    """EN 1991-4 §6.3: p_v(x) = gamma h_h / (n - 1) (x/h_h - (x/h_h)^n) + p_vft (x/h_h)^n with
    n = S (F mu_h cot beta + F) - 2 (S = 2, cone); filling F = F_f: p_nf = F_f p_v, p_tf = mu_h F_f p_v
    (§6.3.2); discharge (§6.3.3) F = F_e in both n and the pressures: p_ne = F_e p_v, p_te = mu_h F_e p_v."""
    # steep 30 deg hopper under a 20 m slender column, d_c = 6 m, AAC 2: mu_h = mu_l = 0.32759,
    # p_vft = 74592.1 Pa, h_h = 5.19615 m; at mid-height x = h_h / 2
    t = math.tan(math.radians(30.0))
    h_h = 3.0 / t
    z_o_v = 1.5 / (K_L * MU_L)
    p_vft = GAMMA * z_o_v * (1.0 - math.exp(-20.0 / z_o_v))
    F_f = 1.0 - 0.2 / (1.0 + t / MU_L)                          # 0.92760
    n_f = 2.0 * (F_f * MU_L / t + F_f) - 2.0                      # 0.90783
    s = math.sin(math.radians(30.0 * 1.12))                       # phi_i upper 33.6 deg
    phi_wh = math.atan(MU_L)
    eps = phi_wh + math.asin(math.sin(phi_wh) / s)
    F_e = (1.0 + s * math.cos(eps)) / (1.0 - s * math.cos(math.radians(60.0) + eps))     # 1.10512
    n_e = 2.0 * (F_e * MU_L / t + F_e) - 2.0                      # 1.46433
    assert (n_f, n_e) == (pytest.approx(0.90783, rel=1e-4), pytest.approx(1.46433, rel=1e-4))
    p_v_f = GAMMA * h_h / (n_f - 1.0) * (0.5 - 0.5 ** n_f) + p_vft * 0.5 ** n_f     # 56493.0 Pa
    p_v_e = GAMMA * h_h / (n_e - 1.0) * (0.5 - 0.5 ** n_e) + p_vft * 0.5 ** n_e     # 40890.6 Pa
    assert (p_v_f, p_v_e) == (pytest.approx(56493.0, rel=1e-5), pytest.approx(40890.6, rel=1e-5))
    h = hopper(3.0, 30.0)
    z = 0.5 * h_h - 0.3 / t                                       # x = h_h / 2 above the apex
    got = design_loads(h, "wheat", h.hopper_height + 20.0, heights=[z])
    assert got.hopper.steep and got.hopper.n_e == pytest.approx(n_e, rel=1e-9)
    assert got.p_v_hopper[0] == pytest.approx(p_v_f, rel=1e-9)
    assert got.p_nf[0] == pytest.approx(F_f * p_v_f, rel=1e-9)             # 52402.9 Pa
    assert got.p_tf[0] == pytest.approx(MU_L * F_f * p_v_f, rel=1e-9)      # 17166.5 Pa
    assert got.p_ne[0] == pytest.approx(F_e * p_v_e, rel=1e-9)             # 45189.1 Pa (62431.7 with n_f)
    assert got.p_te[0] == pytest.approx(MU_L * F_e * p_v_e, rel=1e-9)      # 14803.3 Pa
    # shallow 45 deg hopper (§6.4): mu_heff = (1 - K_l) / (2 tan beta) in F_f, n and p_tf
    hs = hopper(3.0, 45.0)
    h_h = 3.0 / 1.0
    mu_eff = (1.0 - K_L) / 2.0                                    # 0.25676
    F_f = 1.0 - 0.2 / (1.0 + 1.0 / mu_eff)
    n_f = 2.0 * (F_f * mu_eff + F_f) - 2.0
    p_v = GAMMA * h_h / (n_f - 1.0) * (0.5 - 0.5 ** n_f) + p_vft * 0.5 ** n_f
    got = design_loads(hs, "wheat", hs.hopper_height + 20.0, heights=[0.5 * h_h - 0.3])
    assert not got.hopper.steep
    assert got.p_tf[0] == pytest.approx(mu_eff * F_f * p_v, rel=1e-9)
    assert got.p_te[0] == pytest.approx(got.p_tf[0], rel=1e-12)          # shallow: discharge = filling


def test_wall_vertical_force_n_zSk_by_hand():
    """EN 1991-4 (5.7): n_zSk = mu p_ho (z - z_o Y_J(z)) = integral of p_wf from the surface to z,
    the frictional drag the wall has taken up (positive, growing with depth); max-friction case."""
    # slender d_c = 6 m: K upper, mu upper, z_o = 1.5 / (0.5994 * 0.4408) = 5.6772 m,
    # mu p_ho = gamma (A/U) = 9000 * 1.5 = 13500 N/m2
    z_o = 1.5 / (K_U * MU_U)
    depths = np.array([5.0, 10.0, 20.0])
    expected = [GAMMA * 1.5 * (z - z_o * (1.0 - math.exp(-z / z_o))) for z in depths]
    # 5 m: 13500 * (5 - 5.6772 * 0.58545) = 22625 N/m; 10 m: 71525 N/m; 20 m: 195620 N/m
    assert expected == pytest.approx([22625.0, 71524.9, 195620.1], rel=1e-5)
    loads = design_loads(cylinder(3.0), "wheat", 20.0, "D2", heights=20.0 - depths)
    np.testing.assert_allclose(loads.n_zSk, expected, rtol=1e-9)
    # the same as the integral of p_wf (trapezoid on a fine grid) down to 20 m
    z = np.linspace(0.0, 20.0, 20001)
    p_wf = MU_U * GAMMA * K_U * z_o * (1.0 - np.exp(-z / z_o))
    assert np.trapezoid(p_wf, z) == pytest.approx(expected[-1], rel=1e-6)
    # squat silo (d_c = 10 m, h_c = 8 m, flat top): n_zSk = integral of p_wf = mu p_ho Y_R
    z_o = 2.5 / (K_U * MU_U)
    n = -(1.0 + TAN_PHI_R)
    z = np.linspace(0.0, 8.0, 8001)
    p_wf = GAMMA * 2.5 * (1.0 - (z / z_o + 1.0) ** n)            # mu p_ho = gamma A/U
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (p_wf[1:] + p_wf[:-1]) * np.diff(z))])
    squat = design_loads(cylinder(5.0), "wheat", 8.0, "D2", heights=8.0 - z[::2000])
    assert squat.classification == "squat"
    np.testing.assert_allclose(squat.n_zSk, integral[::2000], rtol=1e-6, atol=1e-9)
    assert (np.diff(squat.n_zSk) > 0).all()                       # grows with depth


#: EN 1991-4:2006 Annex E, Table E.1, the rows siloflow carries, written out here from the standard
#: (cross-checked against an independent transcription: arturopala/encalmo,
#: structures/.../eurocode/actions/silos/ParticulateSolid.scala; cement, fly ash and sand D2 values
#: also against keipalahniuk/silo-calcs): gamma_l, gamma_u (kN/m3), phi_r, phi_im (deg), a_phi,
#: K_m, a_K, mu_m for wall types D1, D2, D3, a_mu, C_op
TABLE_E1 = {
    "default":          (6.0, 22.0, 40, 35, 1.30, 0.50, 1.50, 0.32, 0.39, 0.50, 1.40, 1.0),
    "aggregate":        (17.0, 18.0, 36, 31, 1.16, 0.52, 1.15, 0.39, 0.49, 0.59, 1.12, 0.4),
    "alumina":          (10.0, 12.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.46, 0.51, 1.07, 0.5),
    "barley":           (7.0, 8.0, 31, 28, 1.14, 0.59, 1.11, 0.24, 0.33, 0.48, 1.16, 0.5),
    "cement":           (13.0, 16.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.46, 0.51, 1.07, 0.5),
    "cement_clinker":   (15.0, 18.0, 47, 40, 1.20, 0.38, 1.31, 0.46, 0.56, 0.62, 1.07, 0.7),
    "coal":             (7.0, 10.0, 36, 31, 1.16, 0.52, 1.15, 0.44, 0.49, 0.59, 1.12, 0.6),
    "fly_ash":          (8.0, 15.0, 41, 35, 1.16, 0.46, 1.20, 0.51, 0.62, 0.72, 1.07, 0.5),
    "flour":            (6.5, 7.0, 45, 42, 1.06, 0.36, 1.11, 0.24, 0.33, 0.48, 1.16, 0.6),
    "lime_hydrated":    (6.0, 8.0, 34, 27, 1.26, 0.58, 1.20, 0.36, 0.41, 0.51, 1.07, 0.6),
    "limestone_powder": (11.0, 13.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.51, 0.56, 1.07, 0.5),
    "maize":            (7.0, 8.0, 35, 31, 1.14, 0.53, 1.14, 0.22, 0.36, 0.53, 1.24, 0.9),
    "sand":             (14.0, 16.0, 39, 36, 1.09, 0.45, 1.11, 0.38, 0.48, 0.57, 1.16, 0.4),
    "soya_beans":       (7.0, 8.0, 29, 25, 1.16, 0.63, 1.11, 0.24, 0.38, 0.48, 1.16, 0.5),
    "sugar":            (8.0, 9.5, 38, 32, 1.19, 0.50, 1.20, 0.46, 0.51, 0.56, 1.07, 0.4),
    "wheat":            (7.5, 9.0, 34, 30, 1.12, 0.54, 1.11, 0.24, 0.38, 0.57, 1.16, 0.5),
}


def test_material_table_matches_en1991_4_table_e1():
    assert set(MATERIALS) == set(TABLE_E1)
    for name, row in TABLE_E1.items():
        m = MATERIALS[name]
        got = (m.gamma_l / 1e3, m.gamma_u / 1e3, m.phi_r, m.phi_im, m.a_phi, m.K_m, m.a_K, *m.mu_m, m.a_mu, m.C_op)
        assert got == pytest.approx(row, rel=1e-12), name
    # the values reach the loads: cement (gamma_u 16 kN/m3, K_m 0.54, a_K 1.20, mu_m D2 0.46, a_mu 1.07),
    # slender d_c = 6 m at depth 20 m: p_hf = gamma_u (A/U) / mu_l (1 - exp(-z / z_o))
    K_u, mu_l = 0.54 * 1.20, 0.46 / 1.07
    z_o = 1.5 / (K_u * mu_l)                                      # 5.3845 m
    p_hf = 16.0e3 * 1.5 / mu_l * (1.0 - math.exp(-20.0 / z_o))    # 54465.6 Pa
    assert p_hf == pytest.approx(54465.6, rel=1e-5)
    cement = design_loads(cylinder(3.0), "cement", 20.0, "D2", heights=[0.0])
    assert cement.p_hf[0] == pytest.approx(p_hf, rel=1e-9)
    # maize C_op 0.9 in the filling patch: C_pf = 0.21 * 0.9 * (1 - exp(-1.5 (20/6 - 1))) = 0.18329
    maize = design_loads(cylinder(3.0), "maize", 20.0)
    assert maize.C_pf == pytest.approx(0.21 * 0.9 * (1.0 - math.exp(-3.5)), rel=1e-9)


def test_design_api_is_what_the_cli_writes(tmp_path):
    """siloflow.design (issue 37: the CLI's answers have API functions) gives the loads the CLI tabulates."""
    import siloflow
    from siloflow.case_file import load_case
    from siloflow.errors import CaseError
    out = tmp_path / "d"
    assert CliRunner().invoke(app, ["design", str(QUICK), "-o", str(out)]).exit_code == 0
    result = siloflow.design(load_case(QUICK))
    assert result.defaulted and result.bands is None and result.bulk_unit_weight > 0
    assert result.loads.table().round(9).equals(pd.read_csv(out / "design_loads.csv").round(9))
    assert siloflow.design(QUICK, top="heap").loads.h_o > 0
    with pytest.raises(CaseError, match="missing.yaml"):
        siloflow.design(tmp_path / "missing.yaml")


def test_angle_of_repose_is_bounded_and_its_loads_finite(quick_dict, write_case, tmp_path):
    """Issue 55.8: phi_r_deg 89.99 on a squat silo overflowed (OverflowError) and 1e-300 printed
    NaN loads. The schema bounds phi_r to [5, 70] deg, and Y_R's vertical stress is evaluated without
    a power of z_o - h_o alone and through its limit at n = -1 (where the standard's form is 0 / 0)."""
    from siloflow.design_loads import squat_filling
    from siloflow.errors import CaseError
    for phi_r in (89.99, 1e-300, 4.9, 70.1):
        quick_dict["design"] = {"material": "wheat", "phi_r_deg": phi_r}
        with pytest.raises(CaseError) as info:
            case_from_dict(quick_dict)
        assert [p for p, _ in info.value.problems] == ["design.phi_r_deg"], info.value.problems
        with pytest.raises(ValueError, match="phi_r"):
            bulk_solid("wheat", phi_r=phi_r)
    for phi_r in (5.0, 70.0):                        # the bounds themselves: a squat silo's loads
        loads = design_loads(cylinder(5.0), bulk_solid("wheat", phi_r=phi_r), 8.0, "D2", top="heap")
        below_heap = loads.z < 8.0 - loads.h_o        # p_vf is NaN inside the heap, above the wall contact
        assert loads.classification == "squat" and np.isfinite(loads.p_hf).all() and np.isfinite(loads.p_wf).all()
        assert np.isfinite(loads.p_vf[below_heap]).all() and below_heap.sum() > 10
    # the formula itself, beyond the bounds: finite, and continuous through n = -1 (h_o = 0, phi_r -> 0)
    depth = np.linspace(0.0, 8.0, 9)
    tiny, small = (squat_filling(depth, GAMMA, 0.5, 0.4, 1.25, phi_r, 0.0) for phi_r in (1e-300, 1e-6))
    for a, b in zip(tiny, small):
        assert np.isfinite(a).all()
        np.testing.assert_allclose(a, b, rtol=1e-6)
    steep = squat_filling(depth, GAMMA, 0.5, 0.4, 1.25, 89.99, 0.0)
    assert all(np.isfinite(a).all() for a in steep)
    # z_V at n = -1 exactly: h_o + (z_o - h_o) ln X, X = (z - h_o) / (z_o - h_o) + 1 (h_o = 0)
    z_o = 1.25 / (0.5 * 0.4)
    assert tiny[2] == pytest.approx(GAMMA * z_o * np.log(depth / z_o + 1.0), rel=1e-9)
