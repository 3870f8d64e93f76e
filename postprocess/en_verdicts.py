"""A verdict per band on the DEM's wall pressures against EN 1991-4's, with the cause of a
difference where the run measured one.

EN 1991-4's filling pressure p_hf is Janssen's law with the wall friction fully mobilised and
the characteristic K (upper) and mu (lower) of its maximum-horizontal-pressure case. A DEM bed
differs from it for measurable reasons:

- **mobilisation**: a poured bed carries on its wall only part of the friction mu_w allows
  (Landry et al., PRE 67, 041303, 2003), and Janssen's pressure levels off at gamma D / (4 mu):
  the less friction mobilised, the higher. Measured by the force balance of the settled bed: the
  wall's friction force over its normal force is the mobilised mu_eff;
- **K**: the lateral ratio Janssen's law needs, with mu_eff, to carry the measured share of the
  weight on the wall (:func:`janssen_wall_share`), K_eff; and the bed's own K from the band-true
  Janssen fit, with dumps;
- **the free surface**: within half a diameter of it, the surface's cone changes the local depth;
- **scale**: a silo a few tens of grains across is not the continuum EN describes (not measured:
  said as a possible cause only).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.optimize import brentq

from siloflow.design_loads import janssen_pressure

#: a bed mobilises its wall friction "fully" above this share of Janssen's full-friction product
FULL_MOBILISATION = 0.8
#: fewer grains across than this: EN's continuum is a possible cause of any difference
CONTINUUM_GRAINS = 30
#: a DEM pressure agrees with EN's when it lies within this many standard errors
AGREE_SIGMAS = 2.0

#: the columns of :func:`compare_with_dem`
COMPARISON_COLUMNS = ("band", "z_mid", "depth", "en_p_hf", "en_p_he", "dem_static", "dem_max_dynamic",
                      "static_over_p_hf", "max_dynamic_over_p_he", "dem_discharge_factor", "en_C_h")


def compare_with_dem(loads, bands: pd.DataFrame) -> pd.DataFrame:
    """Per band: EN p_hf and p_he at the band centre z_mid (Pa), the DEM's static and maximum
    dynamic pressure, their ratios (DEM static / p_hf, DEM max dynamic / p_he; NaN where EN gives
    no pressure, above the fill or below the wall's foot), and the DEM's discharge factor (max
    dynamic / static) next to EN's C_h."""
    z = np.asarray(bands["z_mid"], float)
    static = np.asarray(bands["static_pressure"], float)
    dynamic = np.asarray(bands["max_dynamic_pressure"], float)
    p_hf, p_he = loads.at("p_hf", z), loads.at("p_he", z)
    outside = (z < loads.transition) | (z > loads.surface)
    p_hf, p_he = np.where(outside, np.nan, p_hf), np.where(outside, np.nan, p_he)

    def ratio(a, b):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.isfinite(b) & (b > 0), a / b, np.nan)

    band = bands["band"].to_numpy() if "band" in bands else np.arange(len(z))
    return pd.DataFrame({"band": band, "z_mid": z, "depth": loads.surface - z, "en_p_hf": p_hf, "en_p_he": p_he,
                         "dem_static": static, "dem_max_dynamic": dynamic,
                         "static_over_p_hf": ratio(static, p_hf), "max_dynamic_over_p_he": ratio(dynamic, p_he),
                         "dem_discharge_factor": ratio(dynamic, static), "en_C_h": loads.C_h},
                        columns=list(COMPARISON_COLUMNS))


def janssen_wall_share(height: float, diameter: float, mu_k: float) -> float:
    """Share of a bed's weight its cylinder wall carries by friction under Janssen's law: a bed of
    ``height`` (m) in a cylinder of ``diameter`` (m), wall friction times lateral ratio ``mu_k``:
    1 - (L/H)(1 - exp(-H/L)), L = D / (4 mu K)."""
    if mu_k <= 0:
        return 0.0
    L = diameter / (4.0 * mu_k)
    return 1.0 - (L / height) * (1.0 - math.exp(-height / L))


def mobilised_product(share: float, height: float, diameter: float) -> float:
    """The product mu K (Janssen) that makes the wall carry ``share`` of the weight; NaN outside
    (0, 1)."""
    if not (0.0 < share < 1.0) or height <= 0:
        return float("nan")
    return brentq(lambda mk: janssen_wall_share(height, diameter, mk) - share, 1e-9, 1e6, xtol=1e-12)


def bed_state(force_balance: dict | None, wall_normal_N: float | None, janssen: dict | None, height: float,
              diameter: float, mu_en: float, K_en: float, protocol: str, mu_w: float | None = None) -> dict:
    """How the settled bed stands (the cause side of the verdicts). From the force balance of a
    flat-bottomed cylinder: the wall-carried share of the weight, the friction it mobilises on
    average, mu_eff = wall friction force / wall normal force (``wall_normal_N``, N: the static
    band pressures over their areas), and the lateral ratio that Janssen's law needs to carry that
    share with mu_eff, K_eff (:func:`mobilised_product` / mu_eff). The bed's own K from its
    Janssen fit when resolved. EN's mu and K are those of its maximum-horizontal-pressure case;
    ``mu_w`` the grains' wall friction coefficient, the most the wall can mobilise (kept as given)."""
    state = {"protocol": protocol, "wall_friction_share": None, "janssen_share_en": janssen_wall_share(
        height, diameter, mu_en * K_en), "mu_eff": None, "K_eff": None, "K_bed": None, "K_bed_ci": None,
        "K_en": K_en, "mu_en": mu_en, "mu_w": mu_w}
    fb = force_balance or {}
    share, weight = fb.get("wall_friction_share"), fb.get("weight_N")
    if share is not None and np.isfinite(share) and weight and wall_normal_N and wall_normal_N > 0:
        state["wall_friction_share"] = float(share)
        state["mu_eff"] = float(share) * float(weight) / float(wall_normal_N)
        product = mobilised_product(float(share), height, diameter)
        state["K_eff"] = product / state["mu_eff"] if np.isfinite(product) and state["mu_eff"] > 0 else None
    if janssen and janssen.get("resolved") and "K" in janssen:
        state["K_bed"], state["K_bed_ci"] = janssen["K"], janssen.get("K_ci")
    return state


def static_verdict(dem: float, se: float, p_hf: float, depth: float, diameter: float, gamma: float, state: dict,
                   grains_across: float) -> tuple[str, list[str]]:
    """(verdict, causes) of one band's static pressure ``dem`` (Pa, standard error ``se``) against
    EN's ``p_hf`` (Pa) at ``depth`` (m) below the surface, ``gamma`` the unit weight EN used (N/m3).
    The causes are what the bed measured (:func:`bed_state`): its mobilised wall friction and
    lateral ratio, with Janssen's pressure on them beside the DEM's."""
    if not np.isfinite(p_hf):
        return "no EN filling pressure at this height (above the fill or below the vertical wall)", []
    if not np.isfinite(dem):
        return "no DEM static pressure", []
    diff = dem - p_hf
    if np.isfinite(se) and se > 0 and abs(diff) <= AGREE_SIGMAS * se:
        return f"agrees with EN p_hf ({dem / p_hf:.2f} x, within {AGREE_SIGMAS:g} standard errors)", []
    sigmas = f", {abs(diff) / se:.0f} standard errors" if np.isfinite(se) and se > 0 else ", its error not resolved"
    verdict = f"{'above' if diff > 0 else 'below'} EN p_hf ({dem / p_hf:.2f} x{sigmas})"
    causes = []
    mu_eff, K_eff, mu_en, K_en = state.get("mu_eff"), state.get("K_eff"), state["mu_en"], state["K_en"]
    if mu_eff is not None and K_eff is not None:
        own = float(janssen_pressure(depth, gamma, K_eff, mu_eff, diameter / 4.0))
        if (diff > 0 and mu_eff < FULL_MOBILISATION * mu_en) or (diff < 0 and mu_eff > mu_en / FULL_MOBILISATION):
            causes.append(f"the wall mobilises mu_eff = {mu_eff:.2g} ({mu_eff / mu_en:.2f} of EN's mu = {mu_en:.2g}): "
                          "Janssen's pressure levels off at gamma D / (4 mu), so it stands "
                          f"{'higher' if diff > 0 else 'lower'}")
        if (diff > 0) == (K_eff > K_en) and abs(K_eff / K_en - 1.0) > 1.0 - FULL_MOBILISATION:
            causes.append(f"the bed's lateral ratio K_eff = {K_eff:.2g} against EN's {K_en:.2g}")
        if causes:
            causes.append(f"Janssen with the bed's own mu_eff and K_eff gives {own:.3g} Pa here "
                          f"(DEM / that = {dem / own:.2f})" if own > 0 else "")
    K_bed, ci = state.get("K_bed"), state.get("K_bed_ci")
    if K_bed is not None and ci and all(np.isfinite(ci)) and not (ci[0] <= K_en <= ci[1]) and \
            (K_bed > K_en) == (diff > 0):
        causes.append(f"the bed's Janssen fit gives K = {K_bed:.2f} [{ci[0]:.2f}, {ci[1]:.2f}] against EN's {K_en:.2f}")
    if np.isfinite(depth) and depth < 0.5 * diameter:
        causes.append(f"the band is {depth * 1000:.0f} mm below EN's equivalent surface, inside the surface's "
                      "cone, where the local fill depth differs from EN's")
    causes = [c for c in causes if c]
    if not causes:
        causes.append("no measured cause: the bed's mobilised friction, lateral ratio and depth do not explain it")
    if grains_across < CONTINUUM_GRAINS:
        causes.append(f"possible, not measured: the silo is {grains_across:.0f} grains across, EN's loads are "
                      "for a continuum (silos thousands of grains across)")
    return verdict, causes


def dynamic_verdict(dem_max: float, p_he: float) -> str:
    """One band's maximum dynamic pressure (Pa) against EN's discharge pressure ``p_he`` (Pa)."""
    if not (np.isfinite(p_he) and np.isfinite(dem_max)):
        return "no comparison (no EN discharge pressure or no DEM maximum here)"
    r = dem_max / p_he
    if r <= 1.0:
        return f"within EN p_he ({r:.2f} x)"
    return (f"above EN p_he ({r:.2f} x): the DEM maximum is the largest sample over the discharge, a peak, "
            "where p_he is a characteristic value without the patch load")


def band_verdicts(compared, static_stderr, state: dict, diameter: float, gamma: float,
                  grains_across: float) -> list[dict]:
    """A verdict per row of :func:`compare_with_dem`'s table (``static_stderr``: the
    bands' static standard errors, Pa, in its order): static and dynamic, with the causes."""
    rows = []
    for row, se in zip(compared.itertuples(index=False), np.asarray(static_stderr, float)):
        verdict, causes = static_verdict(row.dem_static, se, row.en_p_hf, row.depth, diameter, gamma, state,
                                         grains_across)
        rows.append({"band": int(row.band), "static_verdict": verdict, "static_causes": causes,
                     "dynamic_verdict": dynamic_verdict(row.dem_max_dynamic, row.en_p_he)})
    return rows
