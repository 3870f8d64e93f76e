"""The engines' sampled tables, engine-neutral: both engines write ``output/flow.txt`` and
``output/wall_forces.txt`` as scalar ``fix ave/time`` files in one column layout
(:data:`FLOW_COLUMNS`, :func:`wall_force_columns`); this module reads them and turns them into
the engine-neutral ``flow`` and ``wall_forces`` tables of ``siloflow.run_folder`` (SI)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ReadError

#: column names of output/flow.txt, in the order the decks write them (massflow/mesh's counts)
FLOW_COLUMNS = ["step", "atoms", "mass_total", "mass_silo", "outlet_mass", "outlet_count",
                "deleted_mass", "deleted_count", "ke", "pe"]
#: the sign that makes output/wall_forces.txt's columns the force the grains exert on the wall
#: (LIGGGHTS' f_<mesh>[1..3] of mesh/surface/stress is that force; the LAMMPS driver writes it so)
FORCE_SIGN = 1.0


def neutral_flow(flow: pd.DataFrame, dt: float) -> pd.DataFrame:
    """The engine-neutral ``flow`` table of an engine's flow.txt (``FLOW_COLUMNS``); ``dt`` in s."""
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
    wall order) of an engine's wall_forces.txt; empty when the plan samples no wall forces."""
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
