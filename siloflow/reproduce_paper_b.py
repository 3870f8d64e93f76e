"""``make paper-b SCALE=quick|paper`` (issue 38): paper B's polydisperse silo at three apertures
that share one fill, coarse-grained, and the claims report ``reports/paper_b/`` (report.md,
report.html, figures, and the small result tables it is made from).

    siloflow paper-b --scale quick            # run what is missing, post-process, report
    siloflow paper-b --scale paper [--yes]    # the paper's size: prints the cost, stops unless --yes
    siloflow paper-b --from-results reports/paper_b/results   # the report from committed results

(``python -m siloflow.reproduce_paper_b`` takes the same options.) Everything runs in this process from
siloflow's shipped decks (``siloflow example``), so an installed wheel runs it from any folder; the
default folders (``runs/paper_b_<scale>``, ``reports/paper_b``) are relative to the current one.

What it runs: the scale's deck (``decks/paper_b_quick.yaml`` or ``decks/paper_b.yaml``) with the
outputs paper B needs (no wall-pressure sensors, which cost time and which paper B does not read:
``docs/skipping.md``), swept over the apertures (``siloflow sweep --set geometry.orifice_radius=...``)
with one fill for all (the fill cache: paper B shrinks the grains after settling, then opens the
outlet), then ``siloflow cg`` and ``siloflow cg-scaling`` on the runs. Resumable: a finished run,
its cg and its extracted results are kept. The claims are computed by ``postprocess.paper_b`` and
written by ``postprocess.report.claims_report``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml
from postprocess.cg_run import scaling_across_runs, setup_from_run
from postprocess.paper_b import RUNS, analyse, extract, read_tables
from postprocess.report.cg import run_cg as coarse_grain
from postprocess.report.files import write_tables
from postprocess.report.paper_b import write_paper_b_report

from .atomic_files import read_json, write_json, write_text
from .case_file import case_from_dict
from .derived import derive
from .disk_estimate import estimate_bytes
from .errors import ReadError
from .resources import example_text
from .run_folder import RunFolder, record_products
from .slurm import write_slurm
from .sweep import prepare_sweep, run_sweep as run_variants

#: where the report goes, and the result tables it is made from (relative to the current folder)
REPORT_DIR = Path("reports") / "paper_b"
RESULTS_DIR_NAME = "results"
#: what paper B reads of a run: no wall pressure (sensor meshes cost 1.5x the time), the dumps of
#: the free surface (Wr), the bulk solid fraction and the coarse-graining (particles and contacts)
PAPER_B_RESULTS = ["flow_rate", "force_balance", "free_surface", "porosity", "coarse_graining"]


@dataclass(frozen=True)
class Scale:
    """One scale of the study: the deck, the apertures (in r_b, the largest radius), the dump
    interval (s), the batches of the steady window, and the kernel widths (in r_b) of the flow
    fields (phi, v_z) and of the stress fields."""

    name: str
    deck: str
    apertures_rb: tuple
    dump_interval: float | None     # s; None: the deck's
    batches: int
    width_flow_rb: float
    width_stress_rb: float
    why: str
    engine: dict | None = None      # engine fields that replace the deck's


SCALES = {
    "quick": Scale(
        "quick", "decks/paper_b_quick.yaml", (4.5, 5.5, 6.5), 0.02, 5, 1.0, 1.0,
        "R = 4.5, 5.5 and 6.5 r_b: the quick silo (Rc = 16 r_b, 8,000 grains) holds an outlet up to "
        "about 0.4 Rc; the smallest is 9 r_b = 5.5 mean grain diameters wide, above the 3D clogging "
        "range (about 4-5 diameters, docs/results.md), and the three span a factor 1.44 in R for the "
        "v_z(0) ~ sqrt(R) and h_c ~ R fits. Kernel width w = r_b for every field: at R/r_b = 4.5-6.5 "
        "paper B's w = 2 r_b for phi and v_z would smooth the outlet profile over a third to a half of "
        "R, and w = r_b/2 for the pressures leaves too few grains per kernel at 8,000 grains (paper B's "
        "Fig. 9 finds h_c invariant to w). Time step t_c/10 instead of the deck's t_c/50 and one MPI rank: "
        "the accuracy benchmark (docs/accuracy.md) measured dt = 0.1 t_c within its 3 % flow-rate "
        "tolerance, and on this shared 2-core machine one rank runs faster than two (MPI ranks spin "
        "while they wait).", {"ranks": 1, "timestep_fraction": 0.1}),
    "paper": Scale(
        "paper", "decks/paper_b.yaml", (8.0, 10.0, 12.0), None, 10, 2.0, 0.5,
        "R = 8, 10 and 12 r_b (paper B: 12 r_b among others), paper B's kernel widths: w = 2 r_b for "
        "phi and v_z, w = r_b/2 for the pressures."),
}


def rb_of(deck_data: dict) -> float:
    """The largest grain radius r_b (m) of a paper-B case."""
    return float(max(deck_data["particles"]["radii"]))


def deck_data(scale: Scale) -> dict:
    """The scale's deck as shipped with siloflow (``siloflow example paper_b_quick``), as fields."""
    return yaml.safe_load(example_text(Path(scale.deck).stem))


def study_case(scale: Scale) -> dict:
    """The scale's deck with the outputs paper B reads and the scale's dump interval."""
    data = deck_data(scale)
    data["outputs"] = {**data.get("outputs", {}), "results": list(PAPER_B_RESULTS)}
    if scale.dump_interval:
        data["outputs"]["dump_interval"] = scale.dump_interval
    if scale.engine:
        data["engine"] = {**data.get("engine", {}), **scale.engine}
    return data


def orifice_set(scale: Scale, data: dict) -> str:
    """``--set geometry.orifice_radius=...``: the apertures in metres."""
    rb = rb_of(data)
    return "geometry.orifice_radius=" + ",".join(f"{a * rb:.10g}" for a in scale.apertures_rb)


def write_study_case(scale: Scale, work: Path) -> Path:
    """Write the study's case (unchanged when it is already there: the sweep resumes)."""
    path = work / f"paper_b_{scale.name}.yaml"
    text = (f"# paper B's {scale.name} study (siloflow/reproduce_paper_b.py): {scale.deck} with the outputs it reads\n"
            + yaml.safe_dump(study_case(scale), sort_keys=False))
    work.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        write_text(path, text)
    return path


def run_sweep(scale: Scale, work: Path, slurm: bool = False, progress=None) -> Path:
    """``siloflow sweep`` over the apertures, in this process (resumes a stopped one; ``slurm``: writes
    the cluster jobs instead; ``progress`` as ``siloflow.sweep.run_sweep``'s); the sweep folder."""
    case = write_study_case(scale, work)
    out = work / "sweep"
    data = yaml.safe_load(case.read_text())
    spec = orifice_set(scale, data)
    cores = int((scale.engine or {}).get("ranks", data.get("engine", {}).get("ranks", 2)))
    print(f"$ siloflow sweep {case} --set {spec} --cores {cores} -o {out}" + (" --slurm" if slurm else ""), flush=True)
    variants, groups = prepare_sweep(case, [spec], 1, out, need_binary=not slurm)
    cache = out / "cache"
    if slurm:
        print(f"submit with {write_slurm(variants, groups, out, cache)}", flush=True)
    else:
        run_variants(variants, out, cores, cache, progress=progress, groups=groups)
    return out


# ------------------------------------------------------------------ the paper scale's cost

def measured_rate(results: Path = REPORT_DIR / RESULTS_DIR_NAME) -> tuple[float | None, str]:
    """The engine's particle-steps per second measured by the quick study's runs (its committed
    study.json, under the current folder by default), and where it came from; (None, why) when there is none."""
    try:
        study = read_json(results / "study.json", "paper B's study", allow_nan=True)
        rate = float(study["throughput"]["particle_steps_per_s"])
        return rate, (f"measured by the quick study's {len(study['runs'])} runs on {study['throughput']['ranks']} "
                      f"rank(s) ({_from_here(results)}/study.json)")
    except (OSError, ValueError, KeyError, TypeError, ReadError):
        return None, "no measured rate (run `make paper-b SCALE=quick` first, or give --rate)"


def paper_cost(scale: Scale, rate: float | None) -> dict:
    """Particles x planned steps of the study (one fill, then each aperture's static, opening and
    discharge stages; the settle stages at their cap: an upper bound), the engine time and
    core-hours at ``rate`` particle-steps/s, and the disk its dumps take (upper bound)."""
    data = study_case(scale)
    data["geometry"] = {**data["geometry"], "orifice_radius": scale.apertures_rb[-1] * rb_of(data)}
    case = case_from_dict(data, scale.deck)
    plan = derive(case)
    steps = plan.planned_steps()
    fill = sum(v for k, v in steps.items() if k in ("fill", "settle", "shrink", "mobilise", "resettle"))
    after = sum(v for k, v in steps.items() if k in ("static", "open", "discharge"))
    n = plan.fill.count
    ranks = int(plan.engine.ranks)
    particle_steps = n * (fill + len(scale.apertures_rb) * after)
    disk = estimate_bytes(case, plan)["total"] * len(scale.apertures_rb)
    out = {"particles": n, "fill_steps": fill, "steps_per_aperture": after, "apertures": len(scale.apertures_rb),
           "particle_steps": particle_steps, "ranks": ranks, "disk_bytes": disk,
           "disk_free_bytes": shutil.disk_usage(Path.cwd()).free, "cores": os.cpu_count() or 1}
    if rate:
        out["engine_hours"] = particle_steps / rate / 3600
        out["core_hours"] = out["engine_hours"] * ranks
    return out


def cost_lines(scale: Scale, cost: dict, rate: float | None, rate_source: str) -> list[str]:
    lines = [f"paper B at {scale.name} scale ({scale.deck}): {cost['particles']:,} particles, apertures "
             f"{', '.join(f'{a:g}' for a in scale.apertures_rb)} r_b sharing one fill",
             f"  steps: {cost['fill_steps']:,} for the fill (settle stages at their cap) + "
             f"{cost['apertures']} x {cost['steps_per_aperture']:,} (static, opening, discharge)",
             f"  particles x steps: {cost['particle_steps']:.3g} particle-steps (upper bound)"]
    if rate:
        lines += [f"  engine rate: {rate:.3g} particle-steps/s, {rate_source}",
                  f"  engine time: {cost['engine_hours']:.3g} h on {cost['ranks']} rank(s) = "
                  f"{cost['core_hours']:.3g} core-hours"]
    else:
        lines.append(f"  engine rate: unknown: {rate_source}")
    lines.append(f"  disk: {cost['disk_bytes'] / 1e9:.3g} GB of dumps and tables (upper bound; "
                 f"{cost['disk_free_bytes'] / 1e9:.3g} GB free here)")
    beyond = (rate is None or cost["engine_hours"] > 24 or cost["disk_bytes"] > cost["disk_free_bytes"])
    lines.append("  this exceeds this machine (more than a day, or more disk than is free)" if beyond
                 else "  this fits this machine")
    return lines


# ------------------------------------------------------------------ coarse-graining, extraction, report

def run_folders(sweep: Path) -> list[Path]:
    """The sweep's run folders, in aperture order (the sweep's own order)."""
    return sorted((sweep / "runs").iterdir())


#: ``siloflow cg``'s settings for each run: w = 2 mean radii, a 50 x 150 rz grid, the lattice sums
CG_SETTINGS = {"kernel_name": "gaussian", "width": 2.0, "unit": "radius", "nr": 50, "nz": 150, "species": "radius",
               "grid_kind": "rz", "method": "lattice"}


def run_cg(folders: list[Path], work: Path) -> dict | None:
    """``siloflow cg`` on each run (``CG_SETTINGS``; skipped where done), then ``siloflow cg-scaling``
    across them, in this process; the scaling fit (also ``work/cg_scaling.json``)."""
    for f in folders:
        target = f / "results" / "cg"
        if not (target / "cg_summary.json").is_file():
            print(f"$ siloflow cg {f} --width 2 --unit radius --nr 50 --nz 150 --method lattice", flush=True)
            since = time.time()
            try:
                coarse_grain(setup_from_run(f), target, **CG_SETTINGS)
            finally:
                record_products(f, target, since)
    out = work / "cg_scaling.json"
    print(f"$ siloflow cg-scaling {' '.join(str(f / 'results' / 'cg') for f in folders)} -o {out}", flush=True)
    write_json(out, scaling_across_runs([f / "results" / "cg" for f in folders]))
    return read_json(out, "the cg-scaling fit", allow_nan=True)


def _record(folder: Path) -> dict:
    try:
        return read_json(folder / "run_record.json", "a run record", allow_nan=True)
    except ReadError:
        return {}


def study_record(scale: Scale, folders: list[Path], tables: dict, cg_scaling: dict | None) -> dict:
    """What the report says about the study besides the tables: the scale, why these apertures,
    each run's engine time and whether its bed came from the fill cache, the engine's measured rate."""
    runs = tables[RUNS]
    rows, ps, secs = [], 0.0, 0.0
    for f, r in zip(folders, runs.itertuples()):
        rec = _record(f)
        cache = rec.get("fill_cache") or {}
        stage = rec.get("stage_steps") or {}
        flow = pd_read_steps(f)
        first = stage.get("static", 0) if cache.get("hit") else 0
        steps = max(0, flow - first) if flow else None
        rows.append({"R_over_rb": float(r.R_over_rb), "R": float(r.R), "particles": int(r.particles),
                     "engine_wall_s": round(float(rec.get("wall_time", float("nan"))), 1),
                     "fill_from_cache": bool(cache.get("hit")), "steps_run": steps})
        if steps and rec.get("wall_time"):
            ps += float(r.particles) * steps
            secs += float(rec["wall_time"])
    if cg_scaling:      # the committed record names the runs from the checkout, not this machine's path
        cg_scaling = {**cg_scaling, "runs": [{**r, "folder": _from_here(r["folder"])}
                                             for r in cg_scaling.get("runs", [])]}
    data = deck_data(scale)
    ranks = (scale.engine or {}).get("ranks", data.get("engine", {}).get("ranks", 2))
    return {"scale": scale.name, "deck": scale.deck, "why": scale.why, "apertures_rb": list(scale.apertures_rb),
            "runs": rows, "cg_scaling": cg_scaling,
            "throughput": {"particle_steps_per_s": float(f"{ps / secs:.3g}") if secs else None, "ranks": ranks,
                           "note": "particles inserted x steps run / engine wall time, summed over the runs, "
                                   "on a machine shared with other jobs"}}


def _from_here(path) -> str:
    """``path`` relative to the current folder (the checkout, as committed) when it is inside it,
    else as it is."""
    p, here = Path(path).absolute(), Path.cwd()
    return p.relative_to(here).as_posix() if p.is_relative_to(here) else str(path)


def pd_read_steps(folder: Path) -> int | None:
    """The last step of a run's flow table."""
    try:
        return int(RunFolder(folder).flow().step.max())
    except (OSError, ValueError, KeyError, AttributeError):
        return None


def write_results(folder: Path, tables: dict, study: dict) -> None:
    """The result tables and the study's record, as the report is made from them."""
    write_tables(tables, folder)
    write_text(folder / "study.json", json.dumps(study, indent=1, sort_keys=True) + "\n")


def report_from_results(results: Path, out: Path = REPORT_DIR) -> list[Path]:
    """The report from result tables and study.json alone (no run folder, no engine)."""
    tables = read_tables(results)
    study = read_json(results / "study.json", "paper B's study", allow_nan=True)
    written = write_paper_b_report(out, analyse(tables, study), study)
    print(f"wrote {out / 'report.md'} and report.html ({len(written)} files)")
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="siloflow paper-b", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scale", choices=sorted(SCALES), default="quick")
    ap.add_argument("--work", type=Path, help="the study's folder (default runs/paper_b_<scale>)")
    ap.add_argument("--out", type=Path, help="the report's folder (default reports/paper_b; other scales: "
                                             "runs/paper_b_<scale>/report)")
    ap.add_argument("--yes", action="store_true", help="run the paper scale after its cost estimate")
    ap.add_argument("--slurm", action="store_true", help="write the sweep's Slurm job arrays instead of running")
    ap.add_argument("--rate", type=float, help="engine particle-steps/s for the cost estimate (default: measured)")
    ap.add_argument("--runs-only", action="store_true", help="run the sweep, nothing else")
    ap.add_argument("--from-results", type=Path, metavar="DIR",
                    help="make the report from committed result tables (DIR: reports/paper_b/results)")
    args = ap.parse_args(argv)
    if args.from_results:
        report_from_results(args.from_results, args.out or REPORT_DIR)
        return 0
    scale = SCALES[args.scale]
    work = args.work or Path("runs") / f"paper_b_{scale.name}"
    if scale.name == "paper":
        rate, source = (args.rate, "given by --rate") if args.rate else measured_rate()
        for line in cost_lines(scale, paper_cost(scale, rate), rate, source):
            print(line)
        if not (args.yes or args.slurm):
            print("not run: add --yes (make paper-b SCALE=paper CONFIRM=yes) to run it here, or --slurm "
                  "to write cluster jobs")
            return 2
    sweep = run_sweep(scale, work, slurm=args.slurm)
    if args.runs_only or args.slurm:
        return 0
    folders = run_folders(sweep)
    cg_scaling = run_cg(folders, work)
    print(f"extracting {len(folders)} runs in {scale.batches} batches each ...", flush=True)
    tables = extract(folders, scale.batches, scale.width_flow_rb, scale.width_stress_rb)
    out = args.out or (REPORT_DIR if scale.name == "quick" else work / "report")
    results = out / RESULTS_DIR_NAME
    write_results(results, tables, study_record(scale, folders, tables, cg_scaling))
    report_from_results(results, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
