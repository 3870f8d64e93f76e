"""Render a validated case into a self-contained run folder (engine-neutral part).

The folder holds the validated ``case.yaml`` and the run plan ``plan.json`` (``siloflow.plan``),
and what the case's engine writes beside them (its deck, meshes and dump layout: each engine's
deck writer lives with the engine, e.g. ``siloflow.engine.liggghts.deck``). Every value is
checked on its way into a deck by the filters here: numbers must be finite, names must match
the safe alphabet, and the rendered deck may only contain the commands its engine allows.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import jinja2

from ._version import __version__
from .atomic_files import write_json, write_text
from .case import SAFE_NAME_PATTERN, Case
from .case_file import case_to_yaml
from .errors import SetupError, SiloflowError
from .resources import template_text
from .run_folder import CASE_NAME, MANIFEST_NAME, RunFolder, check_plain_tree, new_folder, sha256
from .silos.registry import silo_kind

#: words no deck line may hold, whatever its command (LIGGGHTS and LAMMPS both have ``shell``)
FORBIDDEN_WORDS = re.compile(r"\b(shell|include|python|system|popen)\b", re.IGNORECASE)
_SAFE = re.compile(SAFE_NAME_PATTERN.replace("{0,63}", "{0,127}").replace("_.-", "_./-"))


class DeckError(SiloflowError):
    """Raised when a value cannot be placed in a deck safely (non-finite number, unsafe name)."""


def _num(value) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeckError(f"deck value {value!r} is not a number")
    if not math.isfinite(value):
        raise DeckError(f"deck value {value!r} is not finite")
    return f"{float(value):.10g}"


def _integer(value) -> str:
    if isinstance(value, bool) or not isinstance(value, int):
        raise DeckError(f"deck value {value!r} is not an integer")
    return str(value)


def _safe_name(value) -> str:
    if not isinstance(value, str) or not _SAFE.match(value):
        raise DeckError(f"deck name {value!r} is not in the safe alphabet")
    return value


def template_environment(engine: str = "liggghts") -> jinja2.Environment:
    """Jinja environment of an engine's templates (package resources, :mod:`siloflow.resources`):
    StrictUndefined, strict filters, no autoescape."""
    env = jinja2.Environment(loader=jinja2.FunctionLoader(lambda name: template_text(engine, name)),
                             undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True, autoescape=False)
    env.filters.update(num=_num, int=_integer, safe_name=_safe_name)
    return env


def check_commands(text: str, allowed: frozenset) -> None:
    """Refuse (``DeckError``) a rendered deck holding a command not in ``allowed`` or a
    forbidden word (defence in depth)."""
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        command = stripped.split()[0]
        if command not in allowed or FORBIDDEN_WORDS.search(stripped):
            raise DeckError(f"rendered deck line {lineno} is not allowed: {stripped[:120]!r}")


def check_deck_file(path: Path, allowed: frozenset) -> None:
    """Refuse (``SetupError``) a deck file about to reach an engine that holds a command siloflow
    does not write (not in ``allowed``), or cannot be read."""
    try:
        check_commands(Path(path).read_text(encoding="utf-8", errors="replace"), allowed)
    except OSError as exc:
        raise SetupError(f"no readable deck {path}: {exc.strerror}") from None
    except DeckError as exc:
        raise SetupError(f"{path} is not a deck siloflow wrote ({exc}): refusing to run it") from None


def write_manifest(folder: Path) -> None:
    """List every file of a freshly written deck folder, with its SHA-256, in the manifest
    (siloflow's marker: ``--force`` and ``--resume`` read it)."""
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    write_json(folder / MANIFEST_NAME, {"siloflow_version": __version__,
                                        "files": {f: sha256(folder / f) for f in files}})


def stored_container(case: Case, folder: Path):
    """A mesh silo's walls copied into the run folder (``meshes/container.stl``, in metres, in the
    files' frame) and the case's geometry naming that copy, every length in metres (scale 1), so
    that the folder's case renders the same deck without the user's files."""
    from .derived import measured
    from .geometry import WallMesh, write_stl
    g = measured(case).geometry
    write_stl(WallMesh("container", "wall", g.container.source), folder / "meshes" / "container.stl")
    s, o = g.scale, g.outlet
    outlet = {"z": o.z * s}
    if o.radius is not None:
        outlet.update(center=(o.center[0] * s, o.center[1] * s), radius=o.radius * s)
    else:
        outlet["polygon"] = o.scaled_polygon(s)
    return g.model_copy(update={"files": ["meshes/container.stl"], "scale": 1.0,
                                "outlet": o.model_copy(update=outlet), "axis": g.origin[:2]})


def write_run_folder(case: Case, plan, engine, folder: Path) -> None:
    """Write the files of a run folder into the existing, empty ``folder``: the validated case (its
    inserts naming the folder's own mesh copies, in metres), the plan, and the engine's deck."""
    folder = Path(folder)
    engine.write_deck(plan, folder)
    stored = case.model_copy(update={"inserts": [
        ins.model_copy(update={"file": f"meshes/{ins.mesh_name}.stl", "scale": 1.0}) for ins in case.inserts]})
    if silo_kind(case.geometry.kind).reads_files:
        stored = stored.model_copy(update={"geometry": stored_container(case, folder)})
    write_text(folder / CASE_NAME, case_to_yaml(stored))
    RunFolder(folder).write_plan(plan)


def verify_deck(folder, get_engine) -> None:
    """Check that a run folder's deck is the one its own validated case renders, before an
    engine runs it: the case is loaded and validated again, the folder rendered anew into a
    scratch folder by the case's engine (``get_engine(name)``: the engine registry,
    ``siloflow.engine.get_engine``, passed in by the engine asking), and every file of that
    render (deck, plan, meshes, ...) compared byte by byte. A folder from elsewhere, edited by
    hand or rendered by another siloflow version is refused with the first file that differs."""
    import tempfile
    from .case_file import load_case
    from .derived import derive
    folder = Path(folder)
    check_plain_tree(folder)        # no link or FIFO: the engine's writes stay inside, the reads end
    case = load_case(folder / CASE_NAME)
    engine = get_engine(case.engine.name)
    engine.check_deck_files(folder)
    with tempfile.TemporaryDirectory(prefix="siloflow-verify-") as scratch:
        fresh = Path(scratch)
        write_run_folder(case, derive(case), engine, fresh)
        names = sorted(p.relative_to(fresh).as_posix() for p in fresh.rglob("*") if p.is_file())
        for name in names:
            mine = folder / name
            if not mine.is_file() or mine.read_bytes() != (fresh / name).read_bytes():
                raise SetupError(f"{mine} is not what the folder's {CASE_NAME} renders (edited, or written by "
                                 f"another siloflow version): refusing to run it; render the case anew with "
                                 f"'siloflow render {folder / CASE_NAME} -o NEW_FOLDER'")


def render(case: Case, folder, force: bool = False, keep=(), plan=None, *, engine) -> Path:
    """Render ``case`` into a new run folder (atomically: all or nothing). Returns the folder.
    ``plan`` is the case's (``derive(case)``, computed here when not given), ``engine`` the
    case's engine (``Engine.prepare`` passes itself; this module imports no engine). ``force``
    replaces an existing siloflow folder (never one holding a file of ``keep``, the files being
    read, nor one holding files siloflow did not write)."""
    from .derived import derive
    folder = Path(folder)
    plan = plan if plan is not None else derive(case)
    keep = list(keep) + [ins.file for ins in case.inserts] + list(getattr(case.geometry, "files", []))
    with new_folder(folder, force=force, keep=keep) as tmp:
        write_run_folder(case, plan, engine, tmp)
        write_manifest(tmp)
    return folder.absolute()
