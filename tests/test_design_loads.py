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
from postprocess.design_figure import compare_with_dem, design_figure

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
    assert classify(2.0) == "slender" and classify(1.999) == "intermediate"
    assert classify(1.0001) == "intermediate" and classify(1.0) == "squat"
    assert classify(0.4) == "squat" and classify(0.399) == "retaining"
    assert classify(0.399, flat_bottom=False) == "squat"      # a hopper silo is never "retaining"
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
