"""First results of a run folder: discharge curve and flow rate, band pressures (static and
dynamic), force balance of the settled bed; written as CSV/Parquet tables, summary.json
and one figure.

Reads only what the run left (derived.json, run_record.json, output/*.txt), so it runs
on any finished siloflow run folder.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd

from siloflow.atomic_files import write_json, write_text
from siloflow.engine_output import FLOW_COLUMNS, read_ave_time
from siloflow.errors import ReadError

from .discharge import discharge_table, steady_flow_rate
from .dump_results import analyse_dumps
from .janssen import compare_with_measurement
from .wall_pressure import band_mean, band_pressures, vertical_load, wall_force_columns

#: LIGGGHTS' f_<mesh>[1..3] of mesh/surface/stress is the force the grains exert on the mesh
FORCE_SIGN = 1.0
RESULTS = "results"


def _load_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ReadError(f"cannot read {path}: {exc}") from None


class RunOutputs:
    """The tables of one run folder, with the stage boundaries in time (s)."""

    def __init__(self, folder):
        self.folder = Path(folder)
        self.derived = _load_json(self.folder / "derived.json")
        self.record = _load_json(self.folder / "run_record.json")
        self.dt = float(self.derived["timestep"])
        self.walls = self.derived["walls"]
        self.flow = read_ave_time(self.folder / "output" / "flow.txt", FLOW_COLUMNS)
        self.forces = read_ave_time(self.folder / "output" / "wall_forces.txt", wall_force_columns(self.walls))
        steps = self.record["stage_steps"]
        missing = [s for s in ("static", "open", "discharge") if s not in steps]
        if missing:
            raise ReadError(f"{folder}: the run never reached stage(s) {', '.join(missing)}")
        self.stage_steps = {k: int(v) for k, v in steps.items()}
        self.sample_steps = int(self.derived["sample_freq"])

    def stage_time(self, stage: str) -> float:
        return self.stage_steps[stage] * self.dt


def static_window(forces: pd.DataFrame, run: RunOutputs) -> pd.Series:
    """Samples averaged wholly inside the static stage (the first step of a run doubles mesh forces)."""
    lo = run.stage_steps["static"] + run.sample_steps
    hi = run.stage_steps["open"]
    return (forces.step > lo) & (forces.step <= hi)


def analyse(folder, measured_pressure=None) -> dict:
    """Compute the results of a run folder; return the summary (also written to results/).

    ``measured_pressure``: optional CSV (``time`` s since opening, ``band_<k>`` Pa) compared
    band by band with the run (paper A's Table 3 and Eq. 34), written to pressure_comparison.csv.
    """
    run = RunOutputs(folder)
    out = run.folder / RESULTS
    out.mkdir(exist_ok=True)
    g = float(run.derived["gravity"])
    t_open = run.stage_time("open")

    # discharge
    dis = discharge_table(run.flow, run.dt, t_open)
    initial_mass = float(dis.loc[dis.step <= run.stage_steps["open"], "mass_total"].iloc[-1])
    after = dis[dis.step >= run.stage_steps["open"]]
    rate = steady_flow_rate(after.time, after.outlet_mass, t_open,
                            mass_in_silo=after.mass_in_silo, initial_mass=initial_mass)

    # wall pressure
    sectors = band_pressures(run.forces, run.walls, FORCE_SIGN)
    bands = band_mean(sectors)
    bands.insert(1, "time", bands.step * run.dt)
    static_mask = static_window(bands, run)
    if not static_mask.any():
        raise ReadError(f"{folder}: no wall-force sample inside the static window; "
                        "make fill.settle.static_window longer than outputs.sample_interval")
    static = bands[static_mask].groupby("band").agg(z_mid=("z_mid", "first"), static_pressure=("pressure", "mean"),
                                                    static_shear=("shear_force", "mean"))
    dynamic = bands[bands.step > run.stage_steps["open"] + run.sample_steps].groupby("band").agg(
        max_dynamic_pressure=("pressure", "max"))
    table = static.join(dynamic)
    with np.errstate(divide="ignore", invalid="ignore"):
        table["discharge_factor"] = table.max_dynamic_pressure / table.static_pressure
    table = table.reset_index()

    # force balance of the settled bed
    load = vertical_load(run.forces, run.walls, FORCE_SIGN)
    fmask = static_window(run.forces, run)
    fstatic = run.flow[(run.flow.step > run.stage_steps["static"]) & (run.flow.step <= run.stage_steps["open"])]
    weight = float(fstatic.mass_total.mean()) * g
    wall_load = float(load[fmask].mean())
    band_cols = [w["name"] for w in run.walls if w["role"] in ("band", "wall")]
    wall_shear = float(sum(-FORCE_SIGN * run.forces.loc[fmask, f"{n}_fz"].mean() for n in band_cols))

    # tables
    write_text(out / "discharge.csv", dis.to_csv(index=False))
    write_text(out / "wall_pressure.csv", bands.to_csv(index=False))
    write_text(out / "wall_pressure_sectors.csv", sectors.assign(time=sectors.step * run.dt).to_csv(index=False))
    write_text(out / "bands.csv", table.to_csv(index=False))
    try:
        sectors.to_parquet(out / "wall_pressure_sectors.parquet", index=False)
    except ImportError:  # pyarrow is a dependency; a missing one only loses the Parquet copy
        pass

    summary = {
        "particles_inserted": run.record.get("inserted"),
        "initial_mass_kg": initial_mass,
        "settled_ke_pe": run.record.get("settled_ke_pe"),
        "time_open_s": t_open,
        "force_balance": {"weight_N": weight, "wall_and_bottom_load_N": wall_load,
                          "ratio": wall_load / weight if weight > 0 else float("nan"),
                          "wall_friction_share": wall_shear / weight if weight > 0 else float("nan")},
        "flow_rate": asdict(rate),
        "discharged_mass_kg": float(dis.outlet_mass.iloc[-1]),
        "mass_in_silo_end_kg": float(dis.mass_in_silo.iloc[-1]),
        "bands": table.to_dict(orient="records"),
        "engine_wall_time_s": run.record.get("wall_time"),
        "engine_warnings": run.record.get("warnings", []),
    }
    summary["frame_analyses"] = analyse_dumps(run, out, table, dis, rate)
    if measured_pressure is not None:
        try:
            measured = pd.read_csv(measured_pressure)
        except (OSError, ValueError) as exc:
            raise ReadError(f"cannot read measured pressures {measured_pressure}: {exc}") from None
        try:
            comparison = compare_with_measurement(bands, measured, t_open)
        except ValueError as exc:
            raise ReadError(f"{measured_pressure}: {exc}") from None
        write_text(out / "pressure_comparison.csv", comparison.to_csv(index=False))
        summary["pressure_comparison"] = comparison.to_dict(orient="records")
    write_json(out / "summary.json", summary)
    from .figures import first_results_figure  # matplotlib only when figures are drawn
    first_results_figure(bands, dis, table, t_open, out / "first_results.png")
    return summary
