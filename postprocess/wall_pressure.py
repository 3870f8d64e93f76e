"""Normal wall pressure of sensor meshes (cylinder band sectors, slab wall sections) from their net force.

A flat sensor (a slab silo's wall section of area A facing ``normal``) under pressure p feels
p A along its normal. For cylinders:

A sector of a cylinder (radius R, height h, angular width dtheta centred on theta_c)
under a uniform normal pressure p feels a net horizontal force of magnitude
2 p R h sin(dtheta/2) along theta_c: the vector area of any surface spanned by the
sector's two vertical edges is h times the chord, so this holds for the faceted mesh
too. Projecting the sector force on theta_c, instead of taking |F_xy|, also removes
azimuthal friction. A full ring has zero net radial force, hence sectors (>= 3).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd


def sector_projected_area(radius: float, height: float, theta0: float, theta1: float) -> float:
    """|vector area| of a cylinder sector in the horizontal plane, 2 R h sin(dtheta/2), m2."""
    return 2.0 * radius * height * math.sin(0.5 * (theta1 - theta0))


def sector_pressure(fx, fy, radius: float, height: float, theta0: float, theta1: float):
    """Mean normal pressure (Pa) on a sector from the net force (N) the grains exert on it."""
    tc = 0.5 * (theta0 + theta1)
    radial = np.asarray(fx) * math.cos(tc) + np.asarray(fy) * math.sin(tc)
    return radial / sector_projected_area(radius, height, theta0, theta1)


def wide_forces(forces: pd.DataFrame, walls) -> pd.DataFrame:
    """The long ``wall_forces`` table of a run folder (step, time, wall, fx, fy, fz: N, the force
    the grains exert on each wall) as one row per sample: ``step`` and ``<wall>_fx/fy/fz``
    columns in the order of ``walls`` (the plan's ``Wall`` records)."""
    names = [w.name for w in walls if w.is_wall]
    by_wall = {name: part for name, part in forces.groupby("wall", sort=False)}
    missing = [n for n in names if n not in by_wall]
    if missing:
        raise ValueError(f"the wall-force table has no rows for wall(s) {', '.join(missing)}")
    step = by_wall[names[0]].step.to_numpy() if names else forces.step.unique()
    columns = {"step": step}
    for n in names:
        part = by_wall[n]
        if len(part) != len(step) or (part.step.to_numpy() != step).any():
            raise ValueError(f"the wall-force table's rows of wall {n} are not at the same steps as the others'")
        for k in ("fx", "fy", "fz"):
            columns[f"{n}_{k}"] = part[k].to_numpy()
    return pd.DataFrame(columns)


def band_pressures(forces: pd.DataFrame, walls) -> pd.DataFrame:
    """Tidy table of band pressure vs time.

    Parameters
    ----------
    forces : table with ``step`` and ``<wall>_fx/fy/fz`` columns (N, force on the wall; see
        :func:`wide_forces`).
    walls : the plan's walls (``siloflow.plan.Wall``); the sensors have role ``band``.

    Returns
    -------
    DataFrame with columns step, band, sector, z_mid (m), pressure (Pa), shear_force (N,
    downward load the sector carries by wall friction).
    """
    rows = []
    for w in walls:
        if w.role != "band":
            continue
        fx, fy = forces[f"{w.name}_fx"], forces[f"{w.name}_fy"]
        if w.normal is not None:        # the plan says where the sensor faces
            nx, ny = w.normal
            p = (np.asarray(fx) * nx + np.asarray(fy) * ny) / w.projected_area
        else:
            p = sector_pressure(fx, fy, w.radius, w.z1 - w.z0, w.theta0, w.theta1)
        rows.append(pd.DataFrame({"step": forces["step"].to_numpy(), "band": w.band, "sector": w.sector,
                                  "z_mid": 0.5 * (w.z0 + w.z1), "pressure": np.asarray(p),
                                  "shear_force": -forces[f"{w.name}_fz"].to_numpy()}))
    sectors = pd.concat(rows, ignore_index=True)
    return sectors


def band_mean(sectors: pd.DataFrame) -> pd.DataFrame:
    """Average the sectors of each band at each step (pressure mean, shear summed)."""
    return (sectors.groupby(["step", "band"], as_index=False)
            .agg(z_mid=("z_mid", "first"), pressure=("pressure", "mean"),
                 shear_force=("shear_force", "sum")))


def vertical_load(forces: pd.DataFrame, walls) -> pd.Series:
    """Total downward force (N) the grains exert on all walls, per sample."""
    cols = [f"{w.name}_fz" for w in walls if w.is_wall]
    return -forces[cols].sum(axis=1)
