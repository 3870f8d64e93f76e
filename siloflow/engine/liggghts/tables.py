"""LIGGGHTS' tables: its ``fix ave/time`` files read as pandas DataFrames and turned into the
engine-neutral ``flow`` and ``wall_forces`` tables (``siloflow.run_folder``), and the column
layouts of its ``pair/gran/local`` and ``wall/gran/local`` contact dumps."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from ...errors import ReadError

#: column names of output/flow.txt, in the order the deck writes them (massflow/mesh's counts)
FLOW_COLUMNS = ["step", "atoms", "mass_total", "mass_silo", "outlet_mass", "outlet_count",
                "deleted_mass", "deleted_count", "ke", "pe"]
#: LIGGGHTS' f_<mesh>[1..3] of mesh/surface/stress is the force the grains exert on the mesh
FORCE_SIGN = 1.0


def neutral_flow(flow: pd.DataFrame, dt: float) -> pd.DataFrame:
    """The engine-neutral ``flow`` table of LIGGGHTS' flow.txt (``FLOW_COLUMNS``); ``dt`` in s."""
    return pd.DataFrame({"step": flow.step, "time": flow.step * dt, "atoms": flow.atoms,
                         "mass_total": flow.mass_total, "mass_silo": flow.mass_silo,
                         "discharged_mass": flow.outlet_mass, "discharged_count": flow.outlet_count,
                         "ke": flow.ke, "pe": flow.pe})


def wall_force_columns(walls) -> list[str]:
    """Column names of output/wall_forces.txt: step, then fx fy fz of each wall in deck order
    (``walls``: the plan's, the counting disc excluded)."""
    names = ["step"]
    for w in walls:
        if w.is_wall:
            names += [f"{w.name}_fx", f"{w.name}_fy", f"{w.name}_fz"]
    return names


def neutral_wall_forces(path, plan) -> pd.DataFrame:
    """The engine-neutral ``wall_forces`` table (long: one row per sample and wall, in the plan's
    wall order) of LIGGGHTS' wall_forces.txt; empty when the plan samples no wall forces."""
    walls = [w for w in plan.walls if w.is_wall] if plan.outputs.wall_forces else []
    if not walls:
        return pd.DataFrame({"step": np.zeros(0, np.int64), "time": np.zeros(0), "wall": np.zeros(0, object),
                             "fx": np.zeros(0), "fy": np.zeros(0), "fz": np.zeros(0)})
    wide = read_ave_time(path, wall_force_columns(plan.walls))
    step = wide.step.to_numpy()
    n = len(step)
    return pd.DataFrame({
        "step": np.tile(step, len(walls)), "time": np.tile(step * plan.dt, len(walls)),
        "wall": np.repeat([w.name for w in walls], n),
        **{k: np.concatenate([FORCE_SIGN * wide[f"{w.name}_{k}"].to_numpy() for w in walls]) if walls else []
           for k in ("fx", "fy", "fz")}})


def read_ave_time(path, names: list[str] | None = None) -> pd.DataFrame:
    """Read a scalar ``fix ave/time`` file (``#`` header lines, then one row per sample).

    Column names come from the file's second header line unless ``names`` is given.
    A row cut short by a killed run is dropped. Raises ``ReadError`` if the file is
    missing or its column count does not match ``names``.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            header = [next(fh) for _ in range(2)]
    except (OSError, StopIteration) as exc:
        raise ReadError(f"cannot read engine table {path}: {exc}") from None
    file_names = header[1].lstrip("#").split()
    if names is not None and len(names) != len(file_names):
        raise ReadError(f"{path}: expected {len(names)} columns, the file has {len(file_names)}")
    table = pd.read_csv(path, sep=r"\s+", comment="#", header=None, names=names or file_names,
                        engine="c", on_bad_lines="skip")
    table = table.apply(pd.to_numeric, errors="coerce").dropna()
    table = table.drop_duplicates(subset=table.columns[0], keep="last")
    table[table.columns[0]] = table[table.columns[0]].astype("int64")
    return table.reset_index(drop=True)


#: column names a LIGGGHTS ``compute pair/gran/local`` writes, per keyword, in LIGGGHTS' fixed
#: output order (which does not depend on the order the keywords were given in)
PAIR_LOCAL_LAYOUT = {
    "pos": ["x1", "y1", "z1", "x2", "y2", "z2"],
    "vel": ["vx1", "vy1", "vz1", "vx2", "vy2", "vz2"],
    "id": ["id1", "id2", "periodic"],
    "force": ["fx", "fy", "fz"],
    "force_normal": ["fnx", "fny", "fnz"],
    "force_tangential": ["ftx", "fty", "ftz"],
    "torque": ["tx", "ty", "tz"],
    "history": ["h1", "h2", "h3"],
    "contactArea": ["area"],
    "delta": ["delta"],
}
#: ``compute wall/gran/local`` uses the same order, but ``id`` is (mesh id, triangle id, particle id)
#: and ``pos`` is (contact point on the wall, particle centre): seen in LIGGGHTS 3.8 output, where
#: the first point lies on the cylinder (r = R) and the second at r = R - radius
WALL_LOCAL_ID = ["mesh", "triangle", "id1"]
WALL_LOCAL_POS = ["xw", "yw", "zw", "x1", "y1", "z1"]
#: what siloflow decks ask of wall/gran/local (the force is the force on the particle)
WALL_CONTACT_KEYWORDS = ("pos", "id", "force")
#: what siloflow decks ask of pair/gran/local
CONTACT_KEYWORDS = ("pos", "id", "force", "force_normal")


def local_columns(keywords: Sequence[str], wall: bool = False) -> list[str]:
    """Column names of a LIGGGHTS pair/gran/local (or wall/gran/local) compute with these keywords."""
    unknown = [k for k in keywords if k not in PAIR_LOCAL_LAYOUT]
    if unknown:
        raise ReadError(f"unknown pair/gran/local keyword(s) {unknown}; known: {list(PAIR_LOCAL_LAYOUT)}")
    names: list[str] = []
    for key, cols in PAIR_LOCAL_LAYOUT.items():
        if key in keywords:
            if wall and key == "id":
                cols = WALL_LOCAL_ID
            elif wall and key == "pos":
                cols = WALL_LOCAL_POS
            names += cols
    return names
