"""Command line: ``siloflow validate | schema | render | run | post``.

The only module that prints, exits or sets up logging; everything else raises
siloflow's named errors, mapped here to a message and exit code 1.
"""
from __future__ import annotations

import json
import signal
from contextlib import contextmanager
import sys
import time
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from .case import Case
from .case_file import load_case
from .errors import ANSI_ESCAPES, CaseError, ReadError, SetupError, SiloflowError
from .run_folder import RunFolder

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Silo discharge DEM simulations: case file -> LIGGGHTS deck -> run -> results.")
err = Console(stderr=True)
out = Console()


def printable(text: str) -> str:
    """``text`` safe for a terminal: escape sequences removed, other control characters and
    undecodable bytes shown as escapes (engine output and case keys can hold anything)."""
    text = ANSI_ESCAPES.sub("", str(text))
    return "".join(c if c in "\n\t" or c.isprintable() else repr(c)[1:-1] for c in text)


def _fail(exc: SiloflowError) -> None:
    kind = "invalid case" if isinstance(exc, CaseError) else type(exc).__name__
    err.print(f"[bold red]siloflow: {kind}[/bold red]")
    err.print(printable(exc), markup=False, highlight=False)
    raise typer.Exit(1)


@app.command()
def validate(case_file: Path = typer.Argument(..., help="YAML case file")) -> None:
    """Check a case file; report every problem with its field path, and the physics warnings."""
    from .engine import get_engine
    from .engine.base import check_case
    try:
        case = load_case(case_file)
        engine = get_engine(case.engine.name)
        check_case(case, engine)                 # what the engine cannot do, before the plan
        d = plan_of(case, case_file)             # reads and checks the inserts' meshes too
        check_case(case, engine, d)
    except SiloflowError as exc:
        _fail(exc)
    out.print(printable(f"{case_file}: valid case '{case.name}' ({case.geometry.kind}, {case.materials.model})"),
              markup=False, highlight=False)
    _warn(d, engine, case)


@app.command()
def schema() -> None:
    """Print the JSON schema of case files (for editors)."""
    print(json.dumps(Case.model_json_schema(), indent=2))


def plan_of(case: Case, case_file: Path):
    """The case's run plan (``derive``), a refusal naming the case file and the field."""
    from .derived import derive
    try:
        return derive(case)
    except CaseError as exc:
        raise CaseError(exc.problems, str(case_file)) from None


FORCE_HELP = "replace an existing folder siloflow made (never one holding files it did not write)"
ALLOW_LONG_HELP = "run a case whose planned steps exceed the cap (siloflow.derived.MAX_RUN_STEPS)"


def _warn(d, engine, case) -> None:
    """Print the case's physics warnings and the engine's (each names its consequence)."""
    for line in [*d.warnings, *[w for w in engine.plan_warnings(case, d) if w not in d.warnings]]:
        err.print(printable(f"warning: {line}"), style="yellow", markup=False, highlight=False)


@app.command()
def render(case_file: Path = typer.Argument(..., help="YAML case file"),
           output: Path = typer.Option(..., "-o", "--output", help="deck folder to create"),
           force: bool = typer.Option(False, "--force", help=FORCE_HELP),
           allow_long: bool = typer.Option(False, help=ALLOW_LONG_HELP)) -> None:
    """Write a self-contained run folder (the engine's deck and meshes, case copy, run plan)."""
    from .derived import check_run_length
    from .engine import get_engine
    from .engine.base import check_case
    try:
        case = load_case(case_file)
        engine = get_engine(case.engine.name)
        check_case(case, engine)
        d = plan_of(case, case_file)
        check_run_length(d, allow_long)
        folder = engine.prepare(case, output, force=force, keep=[case_file], plan=d)
    except SiloflowError as exc:
        _fail(exc)
    _warn(d, engine, case)
    t = d.timestep
    out.print(f"deck written to {folder}: {d.fill.count} particles, dt = {t.dt:.3g} s "
              f"({t.fraction} x {t.critical_time_source} {t.critical_time:.3g} s)")
    for line in (clump_note(d), dust_note(d), profile_note(d.profile) if d.profile.name != "custom" else ""):
        if line:
            out.print(line)


def profile_note(p) -> str:
    """One line on the numerical profile a run uses and the error bounds that come with it."""
    what = f"profile {p.name}: time step {p.timestep_fraction:g} of the critical time, stiffness x {p.stiffness_scale:.3g}"
    if p.name == "fast" and p.overlap_ratio is not None:
        what += (f" (impact overlap {p.overlap_ratio:.3g} of the radius)" if p.stiffness_scale < 1.0 else
                 f" (stiffness kept: the grains are already softer than the profile's impact overlap of "
                 f"{p.overlap_ratio:.3g} of the radius)")
    if p.name == "fast":
        if p.error_bounds:
            bounds = ", ".join(f"{q} within {b:.1%}" for q, b in p.error_bounds.items())
            # proven on the benchmark's case: another case's error is its own (siloflow bench measures it)
            what += f"; against the reference, 95 % bounds measured on the benchmark's case: {bounds}"
            what += f" ({p.speedup:.3g}x faster there: {p.benchmark})" if p.speedup else ""
            what += "; another case's own error is not measured (siloflow bench measures it)"
        else:
            what += "; its error bounds are not measured yet (siloflow bench)"
    elif p.name == "reference":
        what += " (the papers' settings)"
    return what


def clump_note(d) -> str:
    """A clump shape's union volume and mass (empty without clumps)."""
    from .contact_physics import sphere_volume
    clump = next((sp for sp in d.grains if sp.kind == "clump"), None)
    if clump is None:
        return ""
    spheres = sum(sphere_volume(s[3]) for s in clump.spheres)
    return (f"clump: {clump.n_spheres} spheres, union volume {clump.volume * 1e9:.4g} mm3 (the spheres' sum "
            f"{spheres * 1e9:.4g} mm3), mass {clump.mass * 1e3:.4g} g")


def dust_note(d) -> str:
    """How much the dust shortens the time step, and the remedy (empty without dust)."""
    t = d.timestep
    if t.without_dust is None:
        return ""
    factor = t.without_dust / t.dt
    if factor <= 1.0 + 1e-9:
        return f"dust: {d.fill.dust_count} spheres; they do not set the time step"
    return (f"dust: {d.fill.dust_count} spheres shorten the time step {factor:.3g}x (without them "
            f"{t.without_dust:.3g} s); particles.dust.density_scale s lengthens dust contacts "
            f"sqrt(s)x (benchmarks/dust_density_scaling.py measures what it changes)")


def _interrupt(signum, frame):
    """SIGTERM stops a run like Ctrl-C: the engine is stopped and the folder marked."""
    raise KeyboardInterrupt


def _progress_bar():
    return Progress(TextColumn("[bold]{task.fields[stage]:>9}"), BarColumn(), TaskProgressColumn(),
                    TextColumn("step {task.fields[step]}"), TimeElapsedColumn(),
                    TextColumn("ETA"), TimeRemainingColumn(), console=err, transient=False)


@app.command()
def run(case_file: Optional[Path] = typer.Argument(None, help="YAML case file"),
        output: Optional[Path] = typer.Option(None, "-o", "--output", help="run folder to create"),
        resume: Optional[Path] = typer.Option(None, "--resume", help="finish this interrupted run folder "
                                              "(from its settled bed's restart file if it got that far)"),
        force: bool = typer.Option(False, "--force", help=FORCE_HELP),
        allow_long: bool = typer.Option(False, help=ALLOW_LONG_HELP),
        liggghts: Optional[str] = typer.Option(None, "--liggghts", envvar="SILOFLOW_LIGGGHTS",
                                               help="LIGGGHTS binary (default: liggghts on PATH)"),
        post_process: bool = typer.Option(True, "--post/--no-post", help="compute first results"),
        allow_large_output: bool = typer.Option(False, help="run even if the estimated output exceeds the free disk"),
        cache: Optional[Path] = typer.Option(None, "--cache", envvar="SILOFLOW_CACHE",
                                             help="fill cache folder: start from a cached settled bed of the same "
                                                  "fill, or cache this run's"),
        profile: Optional[str] = typer.Option(None, "--profile", help="numerical profile for this run, over the "
                                              "case's: reference (the papers': dt = t_c/50, full stiffness), fast "
                                              "(the accuracy benchmark's, with its error bounds) or custom")) -> None:
    """Render, run the case's engine with a progress bar, check the run, and compute first results."""
    from .runs import prepare_resume, prepare_run
    if resume is not None:
        if case_file is not None or output is not None:
            _fail(SiloflowError("--resume DIR takes no case file and no --output: the folder has both"))
        if profile is not None:
            _fail(SiloflowError("--resume DIR takes no --profile: a run resumes with the profile it started with"))
        try:
            prepared = prepare_resume(resume, executable=liggghts)
        except SiloflowError as exc:
            _fail(exc)
        signal.signal(signal.SIGTERM, _interrupt)
        out.print(f"resuming {resume} (it was {prepared.state_before})")
        _drive(prepared.folder, prepared.execute, post_process)
        return
    if case_file is None or output is None:
        _fail(SiloflowError("give a case file and -o/--output (or --resume DIR)"))
    try:
        prepared = prepare_run(case_file, output, force=force, allow_long=allow_long,
                               allow_large_output=allow_large_output, profile=profile, executable=liggghts)
    except SiloflowError as exc:
        _fail(exc)
    signal.signal(signal.SIGTERM, _interrupt)
    derived, folder, sizes = prepared.plan, prepared.folder, prepared.output_estimate
    if prepared.profile_replaced:
        out.print(f"--profile {profile} replaces the case's {', '.join(prepared.profile_replaced)}")
    _warn(derived, prepared.engine, prepared.case)
    out.print(profile_note(derived.profile))
    out.print(f"run folder: {folder} (expected output up to {sizes['total'] / 1e6:.0f} MB, "
              f"{sizes['frames']} dump frames)")
    if dust_note(derived):
        out.print(dust_note(derived))

    def hit(key: str) -> None:
        out.print(f"fill from the cache {cache} (key {key[:12]}): the settled bed is reused, the run starts "
                  "at its static stage")

    def warn(message: str) -> None:
        err.print(printable(f"warning: {message}"), markup=False, highlight=False)

    _drive(folder, lambda progress: prepared.execute(progress, cache=cache, on_cache_hit=hit, on_warning=warn),
           post_process)


def _drive(folder: Path, work, post_process: bool) -> None:
    """Run ``work(progress)`` (an engine run returning its record) under a progress bar; Ctrl-C
    and SIGTERM stop it with the folder marked interrupted; then the first results."""
    with _progress_bar() as bar:
        task = bar.add_task("run", total=None, stage="start", step=0)

        def progress(stage: str, step: int, total: int) -> None:
            bar.update(task, completed=step, total=total, stage=stage, step=f"{step}/{total}")

        try:
            record = work(progress)
            bar.update(task, completed=bar.tasks[0].total, stage="done")
        except KeyboardInterrupt:
            err.print(f"[yellow]interrupted: the engine was stopped; the run folder {folder} is kept "
                      f"and marked interrupted (finish it with: siloflow run --resume {folder})[/yellow]")
            raise typer.Exit(130)
        except SiloflowError as exc:
            bar.stop()
            _fail(exc)
    out.print(f"engine finished in {record.wall_time:.1f} s")
    if post_process:
        _post(folder)


def _post(folder: Path, measured: Path | None = None) -> None:
    from postprocess.report import clog_line, console_lines
    from .runs import post_process
    try:
        summary = post_process(folder, measured)
    except SiloflowError as exc:
        _fail(exc)
    fb, fr = summary["force_balance"], summary["flow_rate"]
    if fb:
        out.print(f"force balance of the settled bed: walls+bottom carry {fb['ratio']:.4f} x the weight "
                  f"({fb['wall_friction_share']:.2f} of it by wall friction)")
    from postprocess.numbers import mass_rate
    if summary.get("clogged"):
        out.print(clog_line(summary["clogged"], fr))
    else:
        out.print(f"steady flow rate: {mass_rate(fr['rate'], fr['stderr'])} (standard error by batch means); "
                  f"discharged {summary['discharged_mass_kg'] * 1000:.1f} g")
    fa = summary.get("frame_analyses", {})
    if "cross_section_solid_fraction" in fa:
        line = f"settled bulk solid fraction {fa['bulk_solid_fraction']:.3f}"
        if "coordination_settled" in fa:
            line += f", coordination number {fa['coordination_settled']['z_mean']:.2f}"
        wr = fa.get("flow_rate_surface", {})
        if wr.get("resolved", True):
            line += f"; free-surface flow rate / outlet flow rate = {fa['flow_rate_surface_over_outlet']:.3f}"
        else:
            line += f"; free-surface flow rate not resolved ({wr.get('reason', 'see the report')})"
        out.print(printable(line), markup=False, highlight=False)
    elif "bulk_solid_fraction" in fa:
        out.print(f"no bulk solid fraction: {fa['bulk_solid_fraction']['error']}")
    for line in console_lines(summary):
        out.print(printable(line), markup=False, highlight=False)
    out.print(f"results: {RunFolder(folder).results} (report.html: one page with every number, table and "
              "figure; report.md, summary.json, *.csv, *.parquet, *.png)")


@app.command()
def post(source: str = typer.Argument(..., help="a finished run folder, or dump file(s): a file, glob or folder"),
         contacts: Optional[str] = typer.Option(None, help="dump local file(s) of pair contacts for a dump source"),
         contact_keywords: Optional[str] = typer.Option(
             None, help="keywords of the pair/gran/local compute that wrote --contacts, e.g. pos,id,force "
                        "(names its columns)"),
         sphere: List[str] = typer.Option([], help="measurement sphere x,y,z,R in m (repeatable)"),
         every: int = typer.Option(1, min=1, help="analyse every n-th frame of a dump source"),
         measured: Optional[Path] = typer.Option(None, help="measured wall pressure CSV (time, band_<k> in Pa) "
                                                 "to compare a run with"),
         output: Optional[Path] = typer.Option(None, "-o", "--output",
                                               help="results folder for a dump source (default: <dumps>/siloflow_post)")) -> None:
    """(Re)compute the results of a run folder, or analyse dump files written by any LIGGGHTS/LAMMPS run."""
    path = Path(source)
    if path.is_dir() and RunFolder(path).is_run_folder():
        _post(path, measured)
        return
    from postprocess.any_dump import parse_sphere
    from postprocess.report.dumps import analyse_any
    from .engine.liggghts.tables import local_columns
    try:
        columns = local_columns(contact_keywords.split(",")) if contact_keywords else None
        regions = [parse_sphere(s, k + 1) for k, s in enumerate(sphere)] or None
        base = path if path.is_dir() else (path.parent if path.exists() else Path(source.split("*")[0]).parent)
        target = output or base / "siloflow_post"
        summary = analyse_any(source, target, contacts, columns, regions, every)
    except SiloflowError as exc:
        _fail(exc)
    out.print(f"{summary['frames']} frames; last step {summary['last_step']} with {summary['particles_last']} particles")
    if "porosity_last" in summary:
        out.print("porosity (last frame): " + ", ".join(f"{k} {v:.4f}" for k, v in summary["porosity_last"].items()))
    if "coordination_last" in summary:
        c = summary["coordination_last"]
        out.print(f"coordination number (last frame, from {c['source']}): {c['z_mean']:.3f} (mechanical {c['z_mech']:.3f})")
    out.print(f"results: {target}")


@app.command()
def status(folder: Path = typer.Argument(..., help="a run folder")) -> None:
    """The state of a run: rendered, running, complete, failed, interrupted or abandoned."""
    from .run_folder import run_state
    try:
        st = run_state(folder)
    except SiloflowError as exc:
        _fail(exc)
    extra = ", ".join(f"{k} {v}" for k, v in st.items() if k in ("stage", "step", "reason"))
    out.print(printable(f"{folder}: {st['state']}" + (f" ({extra})" if extra else "")), markup=False, highlight=False)


@app.command()
def cg(source: str = typer.Argument(..., help="a finished run folder, or dump file(s): a file, glob or folder"),
       output: Optional[Path] = typer.Option(None, "-o", "--output", help="results folder (default <run>/results/cg)"),
       kernel: str = typer.Option("gaussian", help="gaussian (paper B) or lucy"),
       width: float = typer.Option(2.0, help="kernel width w (Gaussian) or c (Lucy)"),
       unit: str = typer.Option("radius", help="unit of --width: radius (mean particle radius) or m"),
       nr: int = typer.Option(100, min=1, help="radial cells (or x and y cells of a Cartesian grid)"),
       nz: int = typer.Option(300, min=1, help="vertical cells"),
       grid: str = typer.Option("rz", help="rz (axisymmetric) or cartesian"),
       method: str = typer.Option("exact", help="rz sums: exact, or lattice (sources on a finer lattice, tabulated "
                                  "kernel moments: many times faster, small error; see docs/coarse_graining.md)"),
       refine: int = typer.Option(2, min=2, help="lattice nodes per grid cell and direction (even; --method lattice)"),
       species: Optional[str] = typer.Option("radius", help="partial fields by radius, type, or none"),
       per_frame: bool = typer.Option(False, help="keep per-frame fields (time evolution) as well"),
       every: int = typer.Option(1, min=1, help="use every n-th frame"),
       contacts: Optional[str] = typer.Option(None, help="dump local of contacts (for a dump source)"),
       contact_keywords: Optional[str] = typer.Option(None, help="keywords of the compute that wrote --contacts"),
       wall_contacts: Optional[str] = typer.Option(None, help="dump local of wall contacts (wall/gran/local pos id "
                                                   "force), boundary terms of the contact stress"),
       wall_contact_keywords: str = typer.Option("pos,id,force", help="keywords of the compute that wrote --wall-contacts"),
       r_max: Optional[float] = typer.Option(None, help="grid radius, m (dump source)"),
       z_lo: Optional[float] = typer.Option(None, help="grid bottom, m (dump source)"),
       z_hi: Optional[float] = typer.Option(None, help="grid top, m (dump source)"),
       z_outlet: float = typer.Option(0.0, help="outlet height, m (dump source)"),
       outlet_radius: Optional[float] = typer.Option(None, help="outlet radius R, m (dump source)"),
       particle_density: Optional[float] = typer.Option(None, help="kg/m3 when the dump has no mass column"),
       steps: Optional[str] = typer.Option(None, help="time window FIRST:LAST in timesteps (dump source)")) -> None:
    """Coarse-grain particles and contacts into continuum fields (paper B): fields.nc, profiles, figures."""
    from postprocess.cg_run import CgSetup, setup_from_run
    from postprocess.report.cg import run_cg
    from .run_folder import record_products
    from .engine.liggghts.tables import local_columns
    path = Path(source)
    try:
        if grid not in ("rz", "cartesian"):
            raise ReadError("--grid must be rz or cartesian")
        if method not in ("exact", "lattice") or (method == "lattice" and grid != "rz"):
            raise ReadError("--method must be exact or lattice, and lattice needs --grid rz")
        if path.is_dir() and RunFolder(path).is_run_folder():
            setup = setup_from_run(path)
            target = output or path / "results" / "cg"
        else:
            from postprocess.dumps import dump_files
            missing = [n for n, v in (("--r-max", r_max), ("--z-lo", z_lo), ("--z-hi", z_hi),
                                      ("--outlet-radius", outlet_radius)) if v is None]
            if missing:
                raise ReadError(f"a dump source needs {', '.join(missing)} (the grid and the outlet)")
            lo_hi = [None, None]
            if steps:
                try:
                    lo_hi = [int(v) if v else None for v in steps.split(":")]
                except ValueError:
                    raise ReadError(f"--steps {steps!r}: expected FIRST:LAST timesteps") from None
            setup = CgSetup(dump_files(source), dump_files(contacts) if contacts else None,
                            local_columns(contact_keywords.split(",")) if contact_keywords else None,
                            r_max, z_lo, z_hi, z_outlet, outlet_radius, particle_density, *lo_hi,
                            dump_files(wall_contacts) if wall_contacts else None,
                            local_columns(wall_contact_keywords.split(","), wall=True) if wall_contacts else None)
            target = output or Path("cg_results")
        since = time.time()
        try:
            summary = run_cg(setup, target, kernel, width, unit, nr, nz, None if species == "none" else species,
                             per_frame, grid, every, method, refine)
        finally:
            if path.is_dir() and RunFolder(path).is_run_folder():
                record_products(path, target, since)
    except SiloflowError as exc:
        _fail(exc)
    except ValueError as exc:
        _fail(SiloflowError(str(exc)))
    out.print(f"coarse-grained {summary['frames']} frames (steps {summary['steps'][0]}-{summary['steps'][1]}) "
              f"on a {grid} grid ({summary['method']} sums) with a {summary['kernel']} kernel; contacts: {summary['contacts']}, "
              f"wall contacts: {summary['wall_contacts']}")
    if "v_z_centre_outlet" in summary:
        out.print(f"outlet centre: solid fraction {summary['solid_fraction_centre_outlet']:.3f}, "
                  f"v_z {summary['v_z_centre_outlet']:.3f} m/s; kinetic pressure peaks "
                  f"{summary['kinetic_peak_height_m'] * 1000:.1f} mm above the outlet")
    out.print(f"results: {target} (fields.nc, *.csv, cg_summary.json, figures)")


@app.command("cg-scaling")
def cg_scaling(folders: List[Path] = typer.Argument(..., help="cg result folders of runs with different outlets"),
               output: Path = typer.Option(Path("cg_scaling.json"), "-o", "--output")) -> None:
    """Power-law fits across runs: outlet centre velocity v_z(0) ~ R^b and h_c ~ R^b (paper B)."""
    from postprocess.cg_run import scaling_across_runs
    from .atomic_files import write_json
    try:
        result = scaling_across_runs(folders)
    except SiloflowError as exc:
        _fail(exc)
    write_json(output, result)
    v = result["v_z0"]
    out.print(f"v_z(0) ~ R^{v['exponent']:.3f} +/- {v['exponent_stderr']:.3f} (paper B: 1/2)")
    if "h_c" in result:
        h = result["h_c"]
        out.print(f"h_c ~ R^{h['exponent']:.3f} +/- {h['exponent_stderr']:.3f} (paper B: 1)")
    out.print(f"written: {output}")


@app.command()
def sweep(case_file: Path = typer.Argument(..., help="YAML case file"),
          set_specs: List[str] = typer.Option([], "--set", help="PATH=V1,V2,...: a case field and its values "
                                              "(repeatable; every combination is run)"),
          seeds: int = typer.Option(1, "--seeds", min=1, help="seeds per combination: the case's seed, +1, +2, ..."),
          cores: Optional[int] = typer.Option(None, "--cores", min=1, help="the engine ranks of the runs at once add "
                                              "up to at most this (default: this machine's cores)"),
          output: Path = typer.Option(..., "-o", "--output", help="sweep folder: cases/, runs/, logs/, sweep.csv, "
                                      "sweep.json"),
          cache: Optional[Path] = typer.Option(None, "--cache", help="fill cache (default OUT/cache)"),
          slurm: bool = typer.Option(False, "--slurm", help="write Slurm job arrays and submit.sh instead of running"),
          max_array_size: int = typer.Option(1000, "--max-array-size", min=1, help="--slurm: most tasks of one job "
                                             "array (below Slurm's MaxArraySize, 1001 by default); more are split "
                                             "into several arrays, all submitted by submit.sh"),
          force: bool = typer.Option(False, "--force", help="use a non-empty folder that holds no sweep (nothing in "
                                     "it is deleted; a run folder already there is refused). Not needed to resume: "
                                     "run the same command again")) -> None:
    """Run a case over every combination of --set values and seeds: one fill per distinct settled bed, then
    the other runs from it, in parallel within --cores; the table of results is OUT/sweep.csv. To resume a
    stopped sweep, run the same command again (same case, --set and --seeds; --force is not needed): complete
    and failed runs are kept, interrupted ones resumed, the others run; a folder of another sweep is refused.
    A file siloflow wrote (the Slurm scripts, sweep.csv) is replaced only while unchanged: if you edited one,
    nothing is written."""
    import os
    import shlex
    from .sweep import prepare_sweep, run_sweep, table_summary, write_slurm
    again = shlex.join(["siloflow", "sweep", str(case_file), *[a for spec in set_specs for a in ("--set", spec)],
                        *(["--seeds", str(seeds)] if seeds != 1 else []), *(["--cores", str(cores)] if cores else []),
                        "-o", str(output), *(["--cache", str(cache)] if cache else [])])
    cache = cache or output / "cache"
    running = False
    try:
        from rich.progress import MofNCompleteColumn
        with Progress(TextColumn("[bold]{task.fields[stage]:>8}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=err) as bar:
            task = bar.add_task("prepare", total=None, stage="reading")

            def stage(name: str, done: int, total: int) -> None:
                bar.update(task, stage=name, completed=done, total=total)

            variants, groups = prepare_sweep(case_file, set_specs, seeds, output, force, need_binary=not slurm,
                                             progress=stage)
            if slurm:
                script = write_slurm(variants, groups, output, cache, max_array_size=max_array_size, progress=stage)
        if slurm:
            arrays = -(-len(groups) // max_array_size) + -(-(len(variants) - len(groups)) // max_array_size)
            out.print(f"{len(variants)} runs, {len(groups)} fill(s): submit with {script} ({arrays} job array(s): "
                      "the fills, then the runs after them)")
            return
        signal.signal(signal.SIGTERM, _interrupt)
        out.print(f"{len(variants)} runs, {len(groups)} distinct fill(s); logs in {output / 'logs'}")
        running = True
        with Progress(TextColumn("[bold]sweep"), BarColumn(), TextColumn("{task.completed}/{task.total} done"),
                      TimeElapsedColumn(), TextColumn("{task.fields[running]}"), console=err) as bar:
            task = bar.add_task("sweep", total=len(variants), running="")

            def progress(done: int, total: int, running: list) -> None:
                names = ", ".join(running)
                bar.update(task, completed=done, running=f"running {names[:60]}" if names else "")

            table = run_sweep(variants, output, cores or os.cpu_count() or 1, cache, progress=progress, groups=groups)
    except KeyboardInterrupt:
        if running:
            err.print(printable(f"interrupted: the running runs were stopped and their folders under "
                                f"{output / 'runs'} marked interrupted; {output / 'sweep.csv'} lists the runs "
                                f"finished so far. Resume the sweep with the same command (finished runs are kept, "
                                f"interrupted ones resumed): {again}"), markup=False, highlight=False)
        else:
            err.print(printable(f"interrupted before any run started; run the same command again: {again}"),
                      markup=False, highlight=False)
        raise typer.Exit(130)
    except SiloflowError as exc:
        _fail(exc)
    n = table_summary(table)
    out.print(f"{n['complete']} runs complete, {n['failed']} failed; fills: {n['computed']} computed, "
              f"{n['reused']} reused from the cache")
    for row in table[table.status != "complete"].head(5).itertuples():
        out.print(printable(f"failed: {row.name} (exit code {row.returncode}), see {row.log}"), markup=False,
                  highlight=False)
    out.print(f"table: {output / 'sweep.csv'} (siloflow beverloo {output / 'sweep.csv'} fits it)")


@app.command()
def bench(case_file: Path = typer.Argument(..., help="YAML case file (its settings are replaced by each candidate's)"),
          output: Path = typer.Option(..., "-o", "--output", help="bench folder: runs/, runs.csv, comparison.csv, "
                                      "pareto.png, recommended_profile.json (a second call resumes)"),
          seeds: int = typer.Option(3, "--seeds", min=2, help="runs (fills) per candidate: the case's seed, +1, ..."),
          candidates: Optional[str] = typer.Option(None, "--candidates", help="comma-separated candidate names "
                                                   "(default: all; the reference is always run)"),
          flow_tolerance: float = typer.Option(0.03, "--flow-tolerance", min=0.0, help="flow rate: largest "
                                               "relative 95 % error bound of the recommended profile"),
          static_tolerance: float = typer.Option(0.05, "--static-tolerance", min=0.0, help="static band pressure: "
                                                 "largest relative 95 % error bound"),
          conclude_only: bool = typer.Option(False, "--conclude", help="run nothing: tables and figure from the "
                                             "runs already in the folder"),
          validate_seeds: int = typer.Option(0, "--validate", min=0, help="then run the recommended profile with "
                                             "this many new seeds and check its errors stay in the bounds"),
          validate_fill_only: int = typer.Option(0, "--validate-fill-only", min=0, help="and this many new fill-only "
                                                 "seeds for the check (the static band pressure's fills)"),
          fill_only_seeds: int = typer.Option(0, "--fill-only-seeds", min=0, help="then this many seeds more, from "
                                              "the case's seed + 2000, each run only to the end of its static stage "
                                              "(about half a run): more fills for the settled bed's quantities "
                                              "(static band pressure, solid fraction, coordination), none for the "
                                              "flow rate or the speed-up")) -> None:
    """Run time against error: each candidate setting (time step, stiffness, ranks) over --seeds fills, against
    the reference (dt = t_c/50, full stiffness); errors with 95 % intervals, a Pareto figure and the fastest
    profile within the tolerances."""
    from .accuracy_bench import (REFERENCE, check_seed_count, choose_candidates, conclude, failing_candidates,
                                 run_bench, validate)
    from .bench_stats import best_bounds
    try:                            # before hours of runs, not after them
        check_seed_count(seeds, "--seeds")
        check_seed_count(validate_seeds, "--validate")
        check_seed_count(validate_fill_only, "--validate-fill-only")
        check_seed_count(fill_only_seeds, "--fill-only-seeds")
        chosen = choose_candidates(candidates, "--candidates")
    except SiloflowError as exc:
        _fail(exc)
    signal.signal(signal.SIGTERM, _interrupt)
    tolerances = {"flow_rate": flow_tolerance, "static_pressure": static_tolerance}
    with _study(output, "bench"):
        if not conclude_only:
            run_bench(case_file, output, seeds, chosen, report=_note, fill_only_seeds=fill_only_seeds)
        table, rec = conclude(output, tolerances, case_file=case_file)
        checking = (validate_seeds or validate_fill_only) and not conclude_only
        if rec is not None and checking and rec["candidate"] != REFERENCE.name:
            validate(case_file, output, rec["candidate"], validate_seeds, report=_note,
                     fill_only_seeds=validate_fill_only)
            table, rec = conclude(output, tolerances, case_file=case_file)
    cols = ["candidate", "quantity", "n_cand", "speedup", "rel_error", "ci_lo", "ci_hi", "verdict"]
    out.print(printable(table[cols].to_string(index=False, float_format=lambda v: f"{v:.3g}")), markup=False,
              highlight=False)
    for r in table[(table.pairs_lost > 0) & table.quantity.isin(tolerances)].itertuples():
        out.print(printable(f"note: {r.candidate} {r.quantity}: {r.pairs_lost} pair(s) lost to the candidate's failed "
                            "runs (see runs.csv's reason); a failure that follows the fill biases the pairs"),
                  markup=False, highlight=False)
    if rec is None:
        out.print("the reference has none of the bounded quantities: nothing to recommend (see comparison.csv)")
    elif rec["candidate"] == REFERENCE.name:
        out.print("no candidate faster than the reference is proven within the tolerances at 95 % confidence with "
                  "these runs (--seeds N resumes and narrows the intervals); the tightest bounds proven:")
        for q in tolerances:
            best = best_bounds(table[~table.candidate.isin({REFERENCE.name} | failing_candidates(table))], q)
            best = best[best.bound < float("inf")].sort_values("bound").head(3)
            out.print(printable(f"  {q}: " + "; ".join(f"{r.candidate} {r.bound:.1%} at {r.speedup:.3g}x"
                                                       f"{_fills_note(table, r.candidate, q)}"
                                                       for r in best.itertuples())), markup=False, highlight=False)
    else:
        bounds = ", ".join(f"{q} <= {b:.1%}" for q, b in rec["error_bounds"].items())
        out.print(printable(f"recommended fast profile: {rec['candidate']} (timestep_fraction "
                            f"{rec['timestep_fraction']:g}, stiffness_scale {rec['stiffness_scale']:g}, impact overlap "
                            f"{rec.get('overlap_ratio') or float('nan'):.3g} of the radius), {rec['speedup']:.3g}x faster "
                            f"than the reference; 95 % error bounds: {bounds}"), markup=False, highlight=False)
    for c in (rec or {}).get("validation") or []:
        bound = f"the bound {c['bound']:.1%}"
        verdict = (f"no interval (fewer than 2 new fills): {bound} not checked" if c.get("consistent", True) is None
                   else f"inside {bound}" if c["inside"] else f"outside {bound}, but its interval reaches into it"
                   if c.get("consistent") else f"OUTSIDE {bound}, the whole interval: the new seeds contradict it")
        out.print(printable(f"new seeds ({c['n']} runs): {c['quantity']} error {c['rel_error']:+.1%} [{c['ci_lo']:+.1%}, "
                            f"{c['ci_hi']:+.1%}]: {verdict}"), markup=False, highlight=False)
    out.print(f"tables and figure: {output} (comparison.csv, pareto.png, recommended_profile.json)")


def _fills_note(table, candidate: str, quantity: str) -> str:
    """`` (about N fills a side for the tolerance)`` from the bench table's ``fills_needed``."""
    n = table[(table.candidate == candidate) & (table.quantity == quantity)]["fills_needed"].iloc[0]
    if n != n:
        return ""
    from .bench_stats import MAX_FILLS
    return (f" (no ensemble at this error, or over {MAX_FILLS:,} fills)" if n == float("inf")
            else f" (about {n:.0f} fills a side for the tolerance)")


def _note(text: str) -> None:
    """One line of a study's progress (engine output stripped of escapes), on stderr."""
    err.print(printable(text), markup=False, highlight=False)


@contextmanager
def _study(output: Path, what: str):
    """A resumable study's errors: Ctrl-C says where the finished runs are, a siloflow error is a message,
    a runs.csv that is not the study's (a foreign or damaged table) says so."""
    try:
        yield
    except KeyboardInterrupt:
        err.print(f"[yellow]interrupted: the finished runs are in {output / 'runs.csv'}; the same command goes "
                  "on from there[/yellow]")
        raise typer.Exit(130)
    except SiloflowError as exc:
        _fail(exc)
    except (ValueError, KeyError) as exc:
        _fail(SiloflowError(f"{output / 'runs.csv'} is not a {what} table ({exc})"))


def _numbers(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        _fail(SiloflowError(f"{option}: '{text}' is not a comma-separated list of numbers"))
    if not values or not all(0 < v and v == v and v != float("inf") for v in values):
        _fail(SiloflowError(f"{option}: every value must be a positive finite number, not '{text}'"))
    return values


@app.command()
def stability(case_file: Path = typer.Argument(..., help="YAML case file"),
              output: Path = typer.Option(..., "-o", "--output", help="study folder: runs/, runs.csv, envelope.csv, "
                                          "edges.json, envelope.png (a second call resumes)"),
              fractions: str = typer.Option("0.05,0.1,0.2,0.3,0.5,0.7,1.0", "--fractions",
                                            help="time-step fractions of the critical time"),
              stiffness: str = typer.Option("1,0.01,0.0001", "--stiffness", help="stiffness scales"),
              dust: Optional[str] = typer.Option(None, "--dust", help="dust density scales (a case with dust)"),
              seed: Optional[int] = typer.Option(None, "--seed", help="seed of every run (default: the case's)"),
              burst: float = typer.Option(0.1, "--burst", min=1e-3, max=10.0, help="discharge burst, s")) -> None:
    """The numerical-stability envelope: short runs (fill impacts, settled bed, a discharge burst) over time-step
    fractions x stiffness scales with the instability guard on; the largest safe time step and its margin."""
    from .stability import check_options, conclude, run_envelope
    fr = _numbers(fractions, "--fractions")
    if max(fr) > 1.0 or min(fr) < 1e-3:
        _fail(SiloflowError(f"--fractions: time-step fractions must lie in [0.001, 1], not '{fractions}'"))
    st = _numbers(stiffness, "--stiffness")
    if max(st) > 1.0 or min(st) < 1e-8:
        _fail(SiloflowError(f"--stiffness: stiffness scales must lie in [1e-8, 1], not '{stiffness}'"))
    ds = _numbers(dust, "--dust") if dust is not None else None
    if ds and min(ds) < 1.0:
        _fail(SiloflowError(f"--dust: dust density scales must be >= 1, not '{dust}'"))
    try:                            # before any run: a bad option is one message, not one per point
        check_options(fr, st, ds, seed, burst)
    except SiloflowError as exc:
        _fail(exc)
    signal.signal(signal.SIGTERM, _interrupt)
    with _study(output, "stability"):
        rows = run_envelope(case_file, output, fr, st, ds, seed, burst, report=_note)
        edges = conclude(output, rows)
    for e in edges:
        what = f"stiffness x {e['stiffness_scale']:g}" + (f", dust x {e['dust_scale']:g}" if e["dust_scale"] else "")
        if e["safe"] != e["safe"]:
            line = f"{what}: no stable time step among {fractions}"
            if e["signal"] == "overlap":
                line += (" (every one stopped for overlap: the contacts are too soft for engine.guard.max_overlap, "
                         "whatever the time step)")
        elif e["unstable"] != e["unstable"]:
            line = f"{what}: stable up to {e['safe']:g} t_c (no unstable point: the edge lies beyond the grid)"
        else:
            line = (f"{what}: largest safe time step {e['safe']:g} t_c; unstable from {e['unstable']:g} t_c "
                    f"({e['signal']}): margin x{e['margin']:.2g}")
        out.print(printable(line), markup=False, highlight=False)
    out.print(f"envelope: {output} (envelope.csv, edges.json, envelope.png)")


@app.command()
def beverloo(folders: List[Path] = typer.Argument(..., help="finished run folders (different orifices or grains), "
                                                  "or one sweep table (sweep.csv: its complete runs)"),
             output: Path = typer.Option(Path("beverloo.csv"), "-o", "--output", help="table of the runs and the fit")) -> None:
    """Fit Beverloo's law W = C rho_b sqrt(g) (D0 - k d)^(5/2) across runs: C and k with standard errors."""
    from .answers import beverloo as fit_runs
    from .atomic_files import write_json, write_text
    try:
        table, fit = fit_runs(folders)
    except SiloflowError as exc:
        _fail(exc)
    except ValueError as exc:
        _fail(SiloflowError(str(exc)))
    write_text(output, table.to_csv(index=False))
    write_json(output.with_suffix(".json"), {"C": fit.C, "C_stderr": fit.C_stderr, "k": fit.k,
                                             "k_stderr": fit.k_stderr, "runs": fit.n_runs,
                                             "rms_relative_residual": fit.rms_relative_residual})
    out.print(f"Beverloo over {fit.n_runs} runs: C = {fit.C:.3f} +/- {fit.C_stderr:.3f}, "
              f"k = {fit.k:.2f} +/- {fit.k_stderr:.2f} (rms residual {fit.rms_relative_residual:.1%})")
    out.print(f"table: {output}; fit: {output.with_suffix('.json')}")


@app.command()
def design(case_file: Path = typer.Argument(..., help="YAML case file (its design section: the bulk solid)"),
           output: Path = typer.Option(Path("design"), "-o", "--output", help="folder for design_loads.csv and .png"),
           run_folder: Optional[Path] = typer.Option(None, "--run", help="a finished run of the case: its band "
                                                     "pressures beside the EN loads (design_vs_dem.csv)"),
           top: str = typer.Option("flat", help="free surface: flat (h_o = 0) or heap (a cone at the angle of repose)")) -> None:
    """EN 1991-4 design loads of the case's silo filled to its bed height: filling, discharge, patch, hopper."""
    import numpy as np
    from postprocess.en_verdicts import compare_with_dem
    from postprocess.report.figures import design_figure
    from .answers import design as design_of
    from .atomic_files import write_text
    try:
        result = design_of(case_file, run_folder, top=top)
        output.mkdir(parents=True, exist_ok=True)
    except SiloflowError as exc:
        _fail(exc)
    except ValueError as exc:
        _fail(SiloflowError(str(exc)))
    loads, bands = result.loads, result.bands
    if result.defaulted:
        out.print(f"note: the case has no design section: wheat (Annex E), wall D2, AAC 2; the DEM grains' bulk "
                  f"unit weight is about {result.bulk_unit_weight:.4g} N/m3 (design: unit_weight, K, mu to use them)")
    m, v = loads.material, loads.values["max_horizontal"]
    out.print(printable(f"{m.name}, {loads.wall_type}, AAC {loads.aac}: {loads.classification} silo ({loads.top} top), h_c/d_c "
                        f"{loads.aspect_ratio:.3g}; K {v.K:.3g}, mu {v.mu:.3g}, z_o {v.z_o:.3g} m; C_h {loads.C_h:.3g}, "
                        f"C_w {loads.C_w:.3g}, C_pe {loads.C_pe:.3g}, p_vft {loads.p_vft:.4g} Pa"), markup=False)
    out.print(f"{'z (m)':>9} {'p_hf':>10} {'p_wf':>10} {'p_vf':>10} {'p_he':>10} {'p_patch':>10}  (Pa)")
    for z in np.linspace(loads.transition, loads.surface - loads.h_o, 6)[::-1]:
        out.print(f"{z:9.4g} " + " ".join(f"{float(loads.at(c, z)):10.4g}" for c in ("p_hf", "p_wf", "p_vf", "p_he",
                                                                                    "p_patch")))
    for line in loads.notes:
        out.print(printable(f"note: {line}"), markup=False)
    write_text(output / "design_loads.csv", loads.table().to_csv(index=False))
    design_figure(loads, output / "design_loads.png", bands)
    if bands is not None:
        write_text(output / "design_vs_dem.csv", compare_with_dem(loads, bands).to_csv(index=False))
    out.print(f"written: {output / 'design_loads.csv'}, {output / 'design_loads.png'}"
              + (f", {output / 'design_vs_dem.csv'}" if bands is not None else ""))


cache_app = typer.Typer(help="The fill cache: settled beds reused by runs of the same fill.")
app.add_typer(cache_app, name="cache")
CACHE_OPTION = typer.Option(None, "--cache", envvar="SILOFLOW_CACHE", help="cache folder (default ~/.cache/siloflow)")


@cache_app.command("list")
def cache_list(cache: Optional[Path] = CACHE_OPTION) -> None:
    """List the cached fills: key, age, size, the run that made each; and what else is in the
    cache's folder (not siloflow's, or changed since it wrote it), with the reason."""
    from .fill_cache import FillCache
    store = FillCache(cache)
    entries, other = store.survey()
    for e in entries:
        size = sum(p.stat().st_size for p in e.files.values())
        age = (time.time() - e.info.get("time", time.time())) / 3600
        out.print(printable(f"{e.key[:16]}  {size / 1e6:8.2f} MB  {age:7.1f} h old  from {e.info.get('source')}"),
                  markup=False, highlight=False)
    out.print(f"{len(entries)} fill(s) in {store.fills}")
    _cache_others(store, other, "not fills (cache clear leaves them)")


def _cache_others(store, other: dict, what: str) -> None:
    if other:
        out.print(f"{len(other)} other item(s) in {store.fills}, {what}:")
        for name, why in other.items():
            out.print(printable(f"  {name}: {why}"), markup=False, highlight=False)


@cache_app.command("clear")
def cache_clear(key: Optional[str] = typer.Argument(None, help="a key (or its first characters); default: all"),
                cache: Optional[Path] = CACHE_OPTION) -> None:
    """Remove one cached fill, or all of them: only entries siloflow wrote whose files are unchanged
    since; anything else in the cache's folder is listed and left in place."""
    from .fill_cache import FillCache
    store = FillCache(cache)
    try:
        done = store.clear(key)
    except SiloflowError as exc:
        _fail(exc)
    out.print(f"removed {len(done.removed)} fill(s) from {store.fills}")
    _cache_others(store, done.left, "left in place")
    if key is not None and not done.removed:
        _fail(SetupError(f"no fill {key!r} was removed" + (": see above" if done.left else
                                                            f": no cached fill's key starts with it")))


def main() -> None:
    """The ``siloflow`` command: the app, with an operating-system error (a file that cannot be
    read or written) told in one line rather than a traceback."""
    from .atomic_files import os_error
    try:
        app()
    except OSError as exc:
        err.print("[bold red]siloflow: SetupError[/bold red]")
        err.print(printable(os_error(exc, exc.filename or "a file", "use")), markup=False, highlight=False)
        sys.exit(1)


if __name__ == "__main__":  # pragma: no cover
    main()
