"""``siloflow post | cg | cg-scaling | beverloo | design | vtk``: results of finished runs or any dump, EN 1991-4
loads, and ParaView files."""
from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from ..errors import ReadError, SiloflowError
from ..run_folder import RunFolder
from .app import _fail, app, err, out, printable
from .run_commands import _post


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
                                               help="results folder for a dump source (default: <dumps>/siloflow_post)"),
         bands: Optional[str] = typer.Option(
             None, help="re-bin a finished run's wall pressure into bands with these edges, m above the side wall's "
                        "base, e.g. 0,0.02,0.04,0.1 (from its dumped wall contacts: results/rebinned_bands.csv)"),
         sectors: Optional[int] = typer.Option(None, help="sectors of a cylinder's re-binned bands (default: the run's)")) -> None:
    """(Re)compute the results of a run folder, or analyse dump files written by any LIGGGHTS/LAMMPS run."""
    path = Path(source)
    if path.is_dir() and RunFolder(path).is_run_folder():
        if bands is not None or sectors is not None:
            _rebin(path, bands, sectors)
        else:
            _post(path, measured)
        return
    if bands is not None or sectors is not None:
        _fail(ReadError(f"{source} is not a siloflow run folder: --bands and --sectors re-bin a finished run"))
    from postprocess.any_dump import parse_sphere
    from postprocess.dumps import local_columns
    from postprocess.report.dumps import analyse_any
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
def _rebin(folder: Path, bands: Optional[str], sectors: Optional[int]) -> None:
    """Re-bin a finished run's side-wall contacts into ``bands`` (comma-separated edges, m) and ``sectors``."""
    from postprocess.rebin import rebin_run
    from postprocess.report.rebin import write_rebinned
    if bands is None:
        _fail(ReadError("--sectors re-bins the run's wall pressure: give the bands' edges with --bands too"))
    try:
        heights = [float(h) for h in bands.split(",")]
    except ValueError:
        _fail(ReadError(f"--bands: {bands!r} is not a comma-separated list of heights in m"))
    try:
        rebinned = rebin_run(folder, heights, sectors)
        path = write_rebinned(folder, rebinned)
    except SiloflowError as exc:
        _fail(exc)
    t = rebinned.table
    out.print(f"{len(rebinned.totals)} dump frames; {len(heights) - 1} bands x {rebinned.sectors} sectors; "
              f"errors: {rebinned.error_method}")
    for band, grp in t.groupby("band"):
        p, se = grp.static_pressure.mean(), float(np.sqrt((grp.static_pressure_stderr ** 2).sum())) / len(grp)
        frames = int(grp.static_frames.min())
        static = f"static {p:.1f} +/- {se:.1f} Pa ({frames} frames)" if frames else "static: no frame in the static window"
        out.print(f"  band {band}: z {grp.z_lo.iloc[0]:.4g}-{grp.z_hi.iloc[0]:.4g} m, {static}, "
                  f"discharge {grp.dynamic_pressure.mean():.1f} Pa")
    out.print(f"results: {path}")


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
    from postprocess.dumps import local_columns
    from postprocess.report.cg import run_cg

    from ..run_folder import record_products
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
    except MemoryError:
        _fail(SiloflowError(f"out of memory coarse-graining on {nr} x {nz} cells (--nr, --nz): choose fewer cells"))
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

    from ..atomic_files import write_json
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


def _beverloo_page_digests(page: Path, fit_file: Path) -> list[str]:
    """The SHA-256s of the page ``siloflow beverloo`` last wrote at ``page``, as its fit file
    (``<output>.json``, ``page_sha256``) records them. Refuses (``SetupError``) a ``page`` that
    exists and is not one of them: a file siloflow did not write, or edited since."""
    import os

    from ..atomic_files import read_json
    from ..errors import SetupError
    from ..run_folder import sha256
    try:
        recorded = read_json(fit_file, "a Beverloo fit").get("page_sha256")
    except ReadError:
        recorded = None
    recorded = [h for h in recorded if isinstance(h, str)] if isinstance(recorded, list) else []
    if os.path.lexists(page) and (page.is_symlink() or not page.is_file() or sha256(page) not in recorded):
        raise SetupError(f"{page} was not written by siloflow beverloo, or was edited since: siloflow does not "
                         "overwrite it, and nothing was written; move it out of the folder, or choose another -o")
    return recorded


@app.command()
def beverloo(folders: List[Path] = typer.Argument(..., help="finished run folders (different orifices or grains), "
                                                  "or one sweep table (sweep.csv: its complete runs)"),
             output: Path = typer.Option(Path("beverloo.csv"), "-o", "--output", help="table of the runs and the fit; "
                                         "beside it the fit (.json) and its page (.html)")) -> None:
    """Fit Beverloo's law W = C rho_b sqrt(g) (D0 - k d)^(5/2) across runs: C and k with standard errors.
    A run that clogged or never flowed steadily is left out, and named; a fit of fewer than 3 runs,
    or missing them by more than 20 % (rms), is refused. The page beside the table (.html): the fit, its
    runs with links to their own pages, the figure with its 95 % band; replaced only while it holds what
    siloflow wrote there."""
    import hashlib

    from postprocess.report.sweep_page import beverloo_report

    from ..answers import beverloo as fit_runs
    from ..atomic_files import write_json, write_text
    from ..errors import SetupError
    page_file, fit_file = output.with_suffix(".html"), output.with_suffix(".json")
    try:
        if output in (page_file, fit_file):
            raise SetupError(f"-o {output}: the table is written beside its .json fit and .html page, so it cannot "
                             "end in .json or .html; give a .csv")
        table, fit = fit_runs(folders)
        owned = _beverloo_page_digests(page_file, fit_file)       # before anything is written
    except SiloflowError as exc:
        _fail(exc)
    except ValueError as exc:
        _fail(SiloflowError(str(exc)))
    left = {row.run: row.left_out for row in table.itertuples() if row.left_out}
    g = float(table[table.left_out == ""].g.iloc[0])
    page = beverloo_report(table, fit, g, page_file.absolute().parent, output.name)
    digest = hashlib.sha256(page.encode("utf-8")).hexdigest()
    record = {"C": fit.C, "C_stderr": fit.C_stderr, "k": fit.k, "k_stderr": fit.k_stderr, "runs": fit.n_runs,
              "rms_relative_residual": fit.rms_relative_residual, "left_out": left}
    write_text(output, table.to_csv(index=False))
    # the fit file knows the old page and the new one while the page is written: one cut short stays siloflow's
    write_json(fit_file, {**record, "page_sha256": sorted(set(owned) | {digest})})
    write_text(page_file, page)
    write_json(fit_file, {**record, "page_sha256": [digest]})
    for run, why in left.items():
        out.print(printable(f"left out of the fit: {run}: {why}"), markup=False, highlight=False)
    out.print(f"Beverloo over {fit.n_runs} runs: C = {fit.C:.3f} +/- {fit.C_stderr:.3f}, "
              f"k = {fit.k:.2f} +/- {fit.k_stderr:.2f} (rms residual {fit.rms_relative_residual:.1%})")
    out.print(f"table: {output}; fit: {fit_file}; page: {page_file}")


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

    from ..answers import design as design_of
    from ..atomic_files import write_text
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


@app.command()
def vtk(source: Path = typer.Argument(..., help="a run folder, or a coarse-graining's fields.nc (or its folder)"),
        output: Optional[Path] = typer.Option(None, "-o", "--output",
                                              help="folder of the ParaView files (default <run>/results/paraview)"),
        every: int = typer.Option(1, min=1, help="write every n-th particle dump frame"),
        wall_every: int = typer.Option(1, min=1, help="write the walls at every n-th wall-force sample"),
        theta: int = typer.Option(48, min=3, help="sectors an axisymmetric coarse-graining is revolved into"),
        cg: bool = typer.Option(True, help="also write every results/**/fields.nc as VTK beside it")) -> None:
    """ParaView files of a run (either engine): particles from the dumps, walls with their sensor
    pressures, and the coarse-grained fields, in .pvd collections with times in seconds."""
    from postprocess.report.paraview import EmptyDumpWarning, write_cg_vtk, write_run_paraview
    try:
        if source.is_dir() and RunFolder(source).is_run_folder():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", EmptyDumpWarning)      # said below, from the summary
                summary = write_run_paraview(source, output, every, wall_every, theta, cg)
        elif source.name == "fields.nc" or (source / "fields.nc").is_file():
            written = write_cg_vtk(source, theta)
            out.print(f"written: {', '.join(str(p) for p in written)}")
            return
        else:
            raise ReadError(f"{source} is neither a siloflow run folder nor a coarse-graining's fields.nc")
    except SiloflowError as exc:
        _fail(exc)
    except ValueError as exc:
        _fail(SiloflowError(str(exc)))
    except MemoryError:
        _fail(SiloflowError(f"out of memory writing the VTK files of {source} (--theta {theta}: fewer sectors?)"))
    target = output or source / "results" / "paraview"
    p = summary["particles"]
    if p["skipped_empty_dumps"]:
        skipped = p["skipped_empty_dumps"]
        err.print(printable(f"warning: {len(skipped)} empty particle dump file(s) skipped (no frame in them): "
                            f"{', '.join(skipped)}; listed in {target / 'paraview.json'}"),
                  style="yellow", markup=False, highlight=False)
    line = f"{p['frames']} particle frames"
    if p["frames"]:
        line += f" ({p['times_s'][0]:.4g} s to {p['times_s'][-1]:.4g} s)"
    if "walls" in summary:
        line += f", walls at {summary['walls']['samples']} samples"
    out.print(line)
    for path in summary.get("cg", []):
        out.print(f"coarse-grained fields: {source / path}")
    out.print(f"open in ParaView: {target / 'run.pvd'}")
