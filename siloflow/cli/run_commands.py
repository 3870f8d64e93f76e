"""``siloflow run | status``: one run with its progress bar, ETA and signals; a folder's state."""
from __future__ import annotations

import signal
from pathlib import Path
from typing import Optional

import typer
from rich.progress import (
    BarColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from ..errors import CaseError, SiloflowError
from ..run_folder import RunFolder, record_products
from .app import _fail, app, err, out, printable
from .case_commands import ALLOW_LONG_HELP, FORCE_HELP, _warn, dust_note, profile_note


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
        executable: Optional[str] = typer.Option(None, "--engine-executable", "--liggghts",
                                                 help="the engine's binary, for engines that run one (LIGGGHTS; "
                                                 "default: $SILOFLOW_LIGGGHTS, else liggghts on PATH); "
                                                 "--liggghts is its older name"),
        post_process: bool = typer.Option(True, "--post/--no-post", help="compute first results"),
        allow_large_output: bool = typer.Option(False, help="run even if the estimated output exceeds the free disk"),
        cache: Optional[Path] = typer.Option(None, "--cache", envvar="SILOFLOW_CACHE",
                                             help="fill cache folder: start from a cached settled bed of the same "
                                                  "fill, or cache this run's"),
        profile: Optional[str] = typer.Option(None, "--profile", help="numerical profile for this run, over the "
                                              "case's: reference (the papers': dt = t_c/50, full stiffness), fast "
                                              "(the accuracy benchmark's, with its error bounds) or custom"),
        slurm: bool = typer.Option(False, "--slurm", help="render the folder and write its Slurm batch script "
                                   "(DIR/job.sbatch: one MPI job over --nodes x --ntasks-per-node ranks) instead "
                                   "of running here; prints the sbatch line"),
        nodes: int = typer.Option(1, "--nodes", help="--slurm: nodes"),
        ntasks_per_node: Optional[int] = typer.Option(None, "--ntasks-per-node", help="--slurm: MPI ranks per node "
                                                      "(default: the case's engine.ranks spread over --nodes)"),
        time_limit: str = typer.Option("24:00:00", "--time", help="--slurm: wall-time limit (minutes, HH:MM:SS, "
                                       "D-HH:MM:SS)"),
        partition: Optional[str] = typer.Option(None, "--partition", help="--slurm: partition"),
        account: Optional[str] = typer.Option(None, "--account", help="--slurm: account"),
        launcher: str = typer.Option("mpirun", "--launcher", help="--slurm: the engine's MPI launcher: mpirun (the "
                                     "site's, over the allocation) or srun"),
        requeue: bool = typer.Option(False, "--requeue", help="--slurm: the job requeues itself when its time "
                                     "limit stops the run, which then resumes")) -> None:
    """Render, run the case's engine with a progress bar, check the run, and compute first results."""
    from ..runs import prepare_resume, prepare_run
    if slurm:
        if resume is not None or case_file is None or output is None:
            _fail(SiloflowError("--slurm takes a case file and -o/--output (a job resumes a folder itself)"))
        _write_slurm_run(case_file, output, force, allow_long, allow_large_output, profile, executable, cache,
                         dict(nodes=nodes, ntasks_per_node=ntasks_per_node, time=time_limit, partition=partition,
                              account=account, launcher=launcher, requeue=requeue))
        return
    if resume is not None:
        if case_file is not None or output is not None:
            _fail(SiloflowError("--resume DIR takes no case file and no --output: the folder has both"))
        if profile is not None:
            _fail(SiloflowError("--resume DIR takes no --profile: a run resumes with the profile it started with"))
        try:
            prepared = prepare_resume(resume, executable=executable)
        except SiloflowError as exc:
            _fail(exc)
        signal.signal(signal.SIGTERM, _interrupt)
        with prepared:                  # the folder's lock, held until the results are written
            out.print(f"resuming {resume} (it was {prepared.state_before})")
            _drive(prepared.folder, prepared.execute, post_process)
        return
    if case_file is None or output is None:
        _fail(SiloflowError("give a case file and -o/--output (or --resume DIR)"))
    try:
        prepared = prepare_run(case_file, output, force=force, allow_long=allow_long,
                               allow_large_output=allow_large_output, profile=profile, executable=executable)
    except SiloflowError as exc:
        _fail(exc)
    signal.signal(signal.SIGTERM, _interrupt)
    with prepared:                      # the folder's lock, held until the results are written
        _run_prepared(prepared, profile, cache, post_process)


def _write_slurm_run(case_file: Path, output: Path, force: bool, allow_long: bool, allow_large_output: bool,
                     profile: Optional[str], executable: Optional[str], cache: Optional[Path], options: dict) -> None:
    """``siloflow run --slurm``: the folder rendered for ``nodes`` x ``ntasks_per_node`` ranks (default:
    the case's ranks over the nodes), its batch script, and the line that submits it."""
    import time

    from ..case_file import load_case
    from ..runs import prepare_run
    from ..slurm import slurm_job, write_run_script
    try:
        if options["ntasks_per_node"] is None:
            ranks = load_case(case_file).engine.ranks
            if ranks % options["nodes"]:
                raise CaseError([("--ntasks-per-node", f"the case's engine.ranks ({ranks}) do not split evenly over "
                                                       f"--nodes {options['nodes']}: give --ntasks-per-node")],
                                "siloflow run --slurm")
            options = {**options, "ntasks_per_node": ranks // options["nodes"]}
        job = slurm_job(**options)
        with prepare_run(case_file, output, force=force, allow_long=allow_long, allow_large_output=allow_large_output,
                         profile=profile, executable=executable, ranks=job.ranks, runs_here=False) as prepared:
            since = time.time()
            script, line = write_run_script(job, prepared.folder, prepared.case.name, prepared.case.engine.name,
                                            cache=cache)
            record_products(prepared.folder, prepared.folder, since)
    except SiloflowError as exc:
        _fail(exc)
    out.print(f"rendered {prepared.folder} for {job.ranks} MPI ranks ({job.nodes} node(s) x {job.ntasks_per_node}); "
              f"its batch script: {script}")
    out.print(printable(f"submit it with: {line}"), markup=False, highlight=False)


def _run_prepared(prepared, profile: Optional[str], cache: Optional[Path], post_process: bool) -> None:
    """What ``siloflow run`` prints before the run, then the run and its first results."""
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

    from ..runs import post_process
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
def status(folder: Path = typer.Argument(..., help="a run folder")) -> None:
    """The state of a run: rendered, running, complete, failed, interrupted or abandoned."""
    from ..run_folder import run_state
    try:
        st = run_state(folder)
    except SiloflowError as exc:
        _fail(exc)
    extra = ", ".join(f"{k} {v}" for k, v in st.items() if k in ("stage", "step", "reason"))
    out.print(printable(f"{folder}: {st['state']}" + (f" ({extra})" if extra else "")), markup=False, highlight=False)
