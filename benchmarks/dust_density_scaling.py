"""The dust time-step remedy, measured: the same clumps + dust silo run with the dust at its own
density and with the dust density scaled (``particles.dust.density_scale``), each with several
seeds to show the run-to-run noise any change must exceed.

Prints, per run: time step, engine wall time, dust mass share, static wall pressure of the
lowest band, steady flow rate Wf and settled bulk solid fraction; then per scale the change of
each against the true density with its standard error.

    python benchmarks/dust_density_scaling.py [case.yaml] [--scales 25 200] [--seeds 3]

Default case: tests/data/clump_silo.yaml (600 wheat clumps, 60 dust balls, Hertz), scales 25
and 200 (1000 did not settle in the allowed time), three seeds each, the true density
included: the seeds give each mean a standard error, and a change is called measured only
beyond twice the combined error. About 10-15 minutes on this machine (multisphere runs on one
core). A variant that fails (e.g. a bed that no longer settles) is reported as such.
"""
from __future__ import annotations

import argparse
import copy
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from postprocess.first_results import analyse  # noqa: E402
from siloflow.case_file import case_from_dict  # noqa: E402
from siloflow.derived import derive  # noqa: E402
from siloflow.engine import LiggghtsEngine  # noqa: E402
from siloflow.errors import EngineRunError  # noqa: E402


#: every run's measurements, written before the report is printed
RAW_TABLE = Path(tempfile.gettempdir()) / "siloflow_dust_density_scaling.csv"


def measure(data: dict, folder: Path) -> dict:
    case = case_from_dict(data)
    d = derive(case)
    record = LiggghtsEngine().run(case, folder)
    summary = analyse(folder)
    dust_mass = d.fill.dust_count * d.dust.mass
    fa = summary.get("frame_analyses", {})
    return {"scale": case.particles.dust.density_scale, "seed": case.seed, "dt": d.dt,
            "dt_without_dust": d.timestep.without_dust, "wall_s": record.wall_time,
            "dust_mass_share": dust_mass / d.total_mass,
            "p_static_band0": summary["bands"][0]["static_pressure"],
            "flow_rate": summary["flow_rate"]["rate"],
            "bulk_phi": fa.get("bulk_solid_fraction") if isinstance(fa.get("bulk_solid_fraction"), float) else float("nan")}


def variant_data(base: dict, scale: float, seed: int, keep_dt: bool) -> dict:
    """The case of one run: dust density x ``scale``; with ``keep_dt`` the time step of the true
    density (timestep_fraction lowered), so that the dust's mass is all that changes."""
    data = copy.deepcopy(base)
    data["particles"]["dust"]["density_scale"] = scale
    data["seed"] = seed
    if keep_dt:
        true = variant_data(base, 1.0, seed, keep_dt=False)
        engine = data.setdefault("engine", {})
        fraction = derive(case_from_dict(data)).timestep.fraction        # the case's, or the profile's
        engine["timestep_fraction"] = fraction * derive(case_from_dict(true)).dt / derive(case_from_dict(data)).dt
    return data


def main(case_file: Path, scales: list[float], seeds: int, keep_dt: bool = True) -> None:
    base = yaml.safe_load(case_file.read_text())
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        variants = [(scale, base["seed"] + k, False) for scale in [1.0] + scales for k in range(seeds)]
        if keep_dt:
            variants += [(scale, base["seed"] + k, True) for scale in scales for k in range(seeds)]
        for k, (scale, seed, same_dt) in enumerate(variants):
            label = f"{scale:g}" + (" @dt1" if same_dt else "")
            try:
                runs.append({"variant": label, **measure(variant_data(base, scale, seed, same_dt), Path(tmp) / f"run{k}")})
            except EngineRunError as exc:          # a failed variant is a result too: say what failed
                print(f"density_scale {label} seed {seed}: FAILED: {str(exc).splitlines()[0]}", flush=True)
                continue
            r = runs[-1]
            print(f"density_scale {label} seed {seed}: dt {r['dt']:.3g} s (without dust {r['dt_without_dust']:.3g} s), "
                  f"engine {r['wall_s']:.1f} s, dust {100 * r['dust_mass_share']:.2f} % of the mass", flush=True)
    table = pd.DataFrame(runs)
    if not table.empty:          # the raw runs first: a report that fails below loses nothing
        table.to_csv(RAW_TABLE, index=False)
        print(f"runs written to {RAW_TABLE}")
    report(table)


def report(table: pd.DataFrame) -> None:
    """Print the runs and, per scale, the changes against the true density."""
    if table.empty or not (table.scale == 1.0).any():
        print("no run at the true dust density finished: nothing to compare against")
        return
    if "variant" not in table:                         # a table written before variants had labels
        table = table.assign(variant=[f"{v:g}" for v in table.scale])
    table = table.assign(variant=table.variant.astype(str))
    ref = table[table.variant == "1"].iloc[0]
    print(f"\n{'scale':>10} {'seed':>6} {'dt/dt1':>7} {'time/t1':>8} {'dust %':>7} {'p0 (Pa)':>9} "
          f"{'Wf (g/s)':>9} {'phi':>6}")
    for _, r in table.iterrows():
        print(f"{r['variant']:>10} {int(r['seed']):>6} {r['dt'] / ref['dt']:>7.2f} {r['wall_s'] / ref['wall_s']:>8.2f} "
              f"{100 * r['dust_mass_share']:>7.2f} {r['p_static_band0']:>9.1f} {1000 * r['flow_rate']:>9.2f} "
              f"{r['bulk_phi']:>6.3f}")
    print(f"\nper scale, over seeds: mean and its standard error; change against the true density with the "
          f"combined standard error (a change within 2 of them is not measured)")
    print(f"{'scale':>10} {'runs':>5} {'time/t1':>8} {'p0 change %':>16} {'Wf change %':>16} {'phi change':>18}")
    one = table[table.variant == "1"]
    for scale, grp in table[table.variant != "1"].groupby("variant", sort=False):
        cells = []
        for col, pct in (("p_static_band0", True), ("flow_rate", True), ("bulk_phi", False)):
            diff, se = mean_change(grp[col].to_numpy(float), one[col].to_numpy(float))
            f = 100.0 / one[col].mean() if pct else 1.0
            flag = "*" if abs(diff) > 2 * se else " "
            cells.append(f"{diff * f:+7.2f} +/- {se * f:5.2f}{flag}" if pct else f"{diff:+8.4f} +/- {se:6.4f}{flag}")
        print(f"{scale:>10} {len(grp):>5} {grp.wall_s.mean() / one.wall_s.mean():>8.2f} {cells[0]:>16} {cells[1]:>16} {cells[2]:>18}")
    print("* : beyond twice the combined standard error; @dt1: the true density's time step kept, so "
          "only the dust's mass changed")


def mean_change(values: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """Difference of the means and its standard error (each side's sample std / sqrt n; NaN with
    one run on either side)."""
    def se2(v):
        return v.var(ddof=1) / len(v) if len(v) > 1 else float("nan")
    return float(values.mean() - reference.mean()), float(np.sqrt(se2(values) + se2(reference)))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="dust density scaling: time step and run time against "
                                     "static pressure, flow rate and solid fraction")
    parser.add_argument("case", nargs="?", type=Path, default=ROOT / "tests" / "data" / "clump_silo.yaml")
    parser.add_argument("--scales", type=float, nargs="+", default=[25.0, 200.0])
    parser.add_argument("--seeds", type=int, default=3, help="runs (seeds) per scale, the true density included")
    parser.add_argument("--report", type=Path, help="only print the report of a runs table written before")
    parser.add_argument("--no-keep-dt", action="store_true", help="skip the runs that keep the true density's "
                        "time step (they separate the dust's mass from the time step's effect)")
    args = parser.parse_args()
    if args.report:
        report(pd.read_csv(args.report))
        sys.exit(0)
    if args.seeds < 1 or any(not (1.0 <= s <= 1.0e6) for s in args.scales):
        parser.error("--seeds must be >= 1 and --scales within [1, 1e6]")
    main(args.case, args.scales, args.seeds, keep_dt=not args.no_keep_dt)
