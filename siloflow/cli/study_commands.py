"""``siloflow sweep | bench | stability | paper-a | paper-b``: resumable studies of many runs."""
from __future__ import annotations

import signal
from contextlib import contextmanager
from pathlib import Path
from typing import List, Optional

import typer
from rich.progress import (
    BarColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from ..errors import SiloflowError
from .app import _fail, _note, app, err, out, printable
from .run_commands import _interrupt


def write_sweep_report(out) -> Path:
    """Write the sweep's page ``out/report.html`` (``postprocess.report.sweep_page.sweep_report``, its
    Beverloo fit by ``siloflow.answers.beverloo``) atomically, and only while the file holds what
    siloflow wrote there, as ``sweep.csv`` (``siloflow.sweep_folder.write_owned``); returns its path.
    Raises ``SetupError`` for a folder without a sweep record or a ``report.html`` siloflow did not
    write or that changed since (nothing is written), and ``ReadError`` when ``sweep.csv`` cannot be read."""
    from postprocess.report.sweep_page import sweep_report

    from ..answers import beverloo
    from ..errors import SetupError
    from ..sweep import PAGE_NAME
    from ..sweep_folder import RECORD_NAME, check_owned, read_record, write_owned
    out = Path(out).absolute()
    record = read_record(out)
    if record is None:
        raise SetupError(f"{out} holds no sweep (no {RECORD_NAME}): its page is written by siloflow sweep")
    check_owned(out, record, {PAGE_NAME: None})          # before the figures are drawn
    write_owned(out, record, {PAGE_NAME: sweep_report(out, beverloo)})
    return out / PAGE_NAME


@app.command()
def sweep(case_file: Path = typer.Argument(..., help="YAML case file"),
          set_specs: List[str] = typer.Option([], "--set", help="PATH=V1,V2,...: a case field and its values "
                                              "(repeatable; every combination is run)"),
          seeds: int = typer.Option(1, "--seeds", min=1, help="seeds per combination: the case's seed, +1, +2, ..."),
          cores: Optional[int] = typer.Option(None, "--cores", min=1, help="the engine ranks of the runs at once add "
                                              "up to at most this (default: this machine's cores)"),
          output: Path = typer.Option(..., "-o", "--output", help="sweep folder: cases/, runs/, logs/, sweep.csv, "
                                      "sweep.json, report.html"),
          cache: Optional[Path] = typer.Option(None, "--cache", help="fill cache (default OUT/cache)"),
          slurm: bool = typer.Option(False, "--slurm", help="write Slurm job arrays and submit.sh instead of running"),
          max_array_size: int = typer.Option(1000, "--max-array-size", min=1, help="--slurm: most tasks of one job "
                                             "array (below Slurm's MaxArraySize, 1001 by default); more are split "
                                             "into several arrays, all submitted by submit.sh"),
          force: bool = typer.Option(False, "--force", help="use a non-empty folder that holds no sweep (nothing in "
                                     "it is deleted; a run folder already there is refused). Not needed to resume: "
                                     "run the same command again")) -> None:
    """Run a case over every combination of --set values and seeds: one fill per distinct settled bed, then
    the other runs from it, in parallel within --cores; the table of results is OUT/sweep.csv, its page
    OUT/report.html (the runs with links to their own pages, Beverloo's fit, flow rate and wall loads against
    each swept value). To resume a stopped sweep, run the same command again (same case, --set and --seeds;
    --force is not needed): complete and failed runs are kept, interrupted ones resumed, the others run; a
    folder of another sweep is refused. A file siloflow wrote (the Slurm scripts, sweep.csv, report.html) is
    replaced only while unchanged: if you edited one, nothing is written."""
    import os
    import shlex

    from ..slurm import write_slurm
    from ..sweep import prepare_sweep, run_sweep, table_summary
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
    for row in table[table.clogged.eq(True)].itertuples():
        out.print(printable(f"clogged: {row.name} (its discharge stopped with grains left: no steady flow rate; "
                            f"siloflow beverloo leaves it out)"), markup=False, highlight=False)
    out.print(f"table: {output / 'sweep.csv'} (siloflow beverloo {output / 'sweep.csv'} fits it)")
    try:        # the runs and their table are the sweep's results: a page not written does not fail it
        page = write_sweep_report(output)
    except (SiloflowError, OSError, ValueError) as exc:
        err.print(printable(f"warning: the sweep's page {output / 'report.html'} was not written: {exc}"), markup=False,
                  highlight=False)
    else:
        out.print(f"page: {output / page.name}")


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
    from ..accuracy_bench import (
        REFERENCE,
        check_seed_count,
        choose_candidates,
        conclude,
        failing_candidates,
        question_tolerances,
        recommended_candidates,
        run_bench,
        validate,
    )
    from ..bench_stats import best_bounds
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
        checked: set[str] = set()
        # the recommendation's, then each question's; one the new seeds contradict is passed over, and
        # the next proven candidate is checked in turn
        while checking and (todo := [n for n in recommended_candidates(rec) if n not in checked]):
            for name in todo:
                validate(case_file, output, name, validate_seeds, report=_note, fill_only_seeds=validate_fill_only)
                checked.add(name)
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
    for question, r in ((rec or {}).get("questions") or {}).items():
        if r is None or r["candidate"] == REFERENCE.name:
            out.print(printable(f"question {question}: nothing faster than the reference is proven within "
                                f"{_tolerance_text(question_tolerances(tolerances)[question])}"),
                      markup=False, highlight=False)
            continue
        confirmed = {c["quantity"]: c for c in r.get("validation") or []}
        out.print(printable(f"question {question}: {r['candidate']}, {r['speedup']:.3g}x; 95 % bounds "
                            + ", ".join(f"{q} {b:.1%}" + ("" if q in confirmed else " (no new seeds yet)")
                                        for q, b in r["error_bounds"].items())), markup=False, highlight=False)
        for p in r.get("passed_over") or []:
            out.print(printable(f"  passed over: {p['candidate']}, {p['speedup']:.3g}x: its new seeds put "
                                + ", ".join(f"{c['quantity']} at {c['rel_error']:+.1%}, outside {c['bound']:.1%}"
                                            for c in p["validation"] if not c["inside"])), markup=False, highlight=False)
    out.print(f"tables and figure: {output} (comparison.csv, pareto.png, recommended_profile.json)")


def _tolerance_text(tolerances: dict) -> str:
    return ", ".join(f"{q} {t:.0%}" for q, t in tolerances.items())


def _fills_note(table, candidate: str, quantity: str) -> str:
    """`` (about N fills a side for the tolerance)`` from the bench table's ``fills_needed``."""
    n = table[(table.candidate == candidate) & (table.quantity == quantity)]["fills_needed"].iloc[0]
    if n != n:
        return ""
    from ..bench_stats import MAX_FILLS
    return (f" (no ensemble at this error, or over {MAX_FILLS:,} fills)" if n == float("inf")
            else f" (about {n:.0f} fills a side for the tolerance)")
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
    from ..stability import check_options, conclude, run_envelope
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


@app.command("paper-a")
def paper_a(scale: str = typer.Option("quick", "--scale", help="quick (minutes, lengths x 1/4) or paper (the paper's "
                                      "silo: hours to days; asks for --yes)"),
            seeds: int = typer.Option(1, "--seeds", help="runs of each model (seeds narrow the intervals)"),
            runs: Path = typer.Option(Path("runs/paper_a"), "--runs", help="where the runs go (reused when finished)"),
            output: Path = typer.Option(Path("reports/paper_a"), "-o", "--output", help="the report's folder"),
            decks: Optional[Path] = typer.Option(None, "--decks", help="a folder of paper A's decks (default: "
                                                 "siloflow's shipped ones)"),
            from_data: bool = typer.Option(False, "--from-data", help="write the report again from its data/ "
                                           "(no run)"),
            yes: bool = typer.Option(False, "--yes", help="run even when the cost estimate exceeds this machine")) -> None:
    """Paper A's claims: run its sphere and multi-element models, write report.md/.html with every claim
    beside our number, its 95 % interval and a computed verdict."""
    from ..reproduce_paper_a import run_paper_a
    try:
        if from_data:
            from postprocess.report.paper_a import regenerate_paper_a_report
            written = regenerate_paper_a_report(output)
        else:
            signal.signal(signal.SIGTERM, _interrupt)
            with _bar() as progress:
                written = run_paper_a(scale, seeds, decks, runs, output, confirm=yes, say=out.print,
                                      progress=progress)
    except SiloflowError as exc:
        _fail(exc)
    out.print(f"paper A's report: {output / 'report.html'} ({len(written)} files)")


@app.command("paper-b", context_settings={"allow_extra_args": True, "ignore_unknown_options": True,
                                          "help_option_names": []})
def paper_b(ctx: typer.Context) -> None:
    """Paper B's claims: the polydisperse silo at three apertures sharing one fill, coarse-grained, and
    reports/paper_b (report.md/.html, every claim beside our number and a computed verdict). Options:
    siloflow paper-b --help (--scale quick|paper, --yes, --slurm, --from-results DIR, ...)."""
    from ..reproduce_paper_b import main
    try:
        code = main(ctx.args)
    except SiloflowError as exc:
        _fail(exc)
    raise typer.Exit(code)


@contextmanager
def _bar():
    """A progress callback drawing one engine run's bar at a time (a new task per run)."""
    from .run_commands import _progress_bar
    with _progress_bar() as bar:
        tasks: dict = {}

        def progress(stage: str, step: int, total: int) -> None:
            if not tasks or (stage == "fill" and step < tasks.get("last", 0)):
                tasks["id"] = bar.add_task("run", total=total, stage=stage, step=0)
            tasks["last"] = step
            bar.update(tasks["id"], completed=step, total=total, stage=stage, step=f"{step}/{total}")
        yield progress
