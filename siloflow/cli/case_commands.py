"""``siloflow validate | schema | render | example``: a case file checked, the schema, a deck folder
without a run, the shipped example cases."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from ..case import Case
from ..case_file import load_case
from ..errors import CaseError, SiloflowError
from ..plan import unbounded_note
from .app import _fail, app, err, out, printable


@app.command()
def validate(case_file: Path = typer.Argument(..., help="YAML case file")) -> None:
    """Check a case file; report every problem with its field path, and the physics warnings."""
    from ..engine import get_engine
    from ..engine.base import check_case
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
    from ..derived import derive
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
    from ..derived import check_run_length
    from ..engine import get_engine
    from ..engine.base import check_case
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


@app.command()
def example(name: Optional[str] = typer.Argument(None, help="example case to copy out (omit: list them)"),
            output: Optional[Path] = typer.Option(None, "-o", "--output",
                                                  help="file to write (default NAME.yaml here; '-': standard output)"),
            force: bool = typer.Option(False, "--force", help="replace an existing file")) -> None:
    """List the example cases siloflow ships (the demo, the quick case, the papers' cases), or copy one
    out to edit, render or run (they are installed with siloflow: decks/ in the repository)."""
    from ..atomic_files import write_bytes, write_text
    from ..resources import example_case, example_companions, example_file, example_names
    try:
        if name is None:
            for stem in example_names():
                first = example_case(stem).read_text(encoding="utf-8").splitlines()[:1] or [""]
                out.print(printable(f"{stem}: {first[0].lstrip('#').strip()}"), markup=False, highlight=False,
                          soft_wrap=True)
            return
        text = example_case(name).read_text(encoding="utf-8")
    except SiloflowError as exc:
        _fail(exc)
    if output is not None and str(output) == "-":
        print(text, end="")
        return
    target = output or Path(Path(name).stem + ".yaml")
    # a silo from STL ships its walls beside the case: they go beside the copy, under the same names
    companions = {target.parent / f: example_file(f) for f in example_companions(name)}
    for path in [target, *companions]:
        if path.exists() and not force:
            err.print(printable(f"siloflow: {path} exists (--force replaces it)"), markup=False, highlight=False)
            raise typer.Exit(1)
    for path, data in companions.items():
        write_bytes(path, data)
    write_text(target, text)
    also = f" (and {', '.join(str(p) for p in companions)})" if companions else ""
    out.print(printable(f"example case {Path(name).stem} written to {target}{also}"), markup=False, highlight=False)


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
            what += f"; proven for {p.question.replace('_', ' ')}" if p.question else ""
            what += f"; against the reference, 95 % bounds measured on the benchmark's case: {bounds}"
            what += f" ({p.speedup:.3g}x faster there: {p.benchmark})" if p.speedup else ""
            what += unbounded_note(p.unbounded, p.measured)
            what += "; another case's own error is not measured (siloflow bench measures it)"
        else:
            what += "; its error bounds are not measured yet (siloflow bench)"
    elif p.name == "reference":
        what += " (the papers' settings)"
    return what


def clump_note(d) -> str:
    """A clump shape's union volume and mass (empty without clumps)."""
    from ..contact_physics import sphere_volume
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
