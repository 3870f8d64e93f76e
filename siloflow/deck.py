"""Render a validated case into a self-contained LIGGGHTS deck folder.

The folder holds ``in.liggghts`` (Jinja, StrictUndefined), ``meshes/*.stl``, the validated
``case.yaml`` and ``derived.json`` (derived parameters and the wall manifest that
post-processing reads). Every value is checked on its way into the deck: numbers
must be finite, names must match the safe alphabet, and the rendered deck may only
contain the commands siloflow itself writes.
"""
from __future__ import annotations

import math
import re
from importlib import resources
from pathlib import Path

import jinja2

from . import __version__
from .atomic_files import new_folder, write_json, write_text
from .case import SAFE_NAME_PATTERN, Case, case_to_yaml
from .derived import Derived, _modulus_of, derive
from .engine_output import CONTACT_KEYWORDS, WALL_CONTACT_KEYWORDS, local_columns
from .errors import SetupError, SiloflowError
from .meshes import silo_meshes, write_stl
from .run_folder import MANIFEST_NAME, check_plain_tree, sha256

DECK_NAME = "in.liggghts"
RESUME_DECK_NAME = "in.resume.liggghts"
#: the settled bed, written by every deck once settling (and shrinking) ended; --resume starts there
RESTART_FILE = "output/restart/settled.restart"
DERIVED_NAME = "derived.json"
CASE_NAME = "case.yaml"

#: The only commands a siloflow deck may contain (no shell, include, python, ...).
ALLOWED_COMMANDS = frozenset("""
atom_style atom_modify boundary newton communicate units processors region create_box neighbor
neigh_modify hard_particles fix pair_style pair_coeff timestep compute variable thermo_style thermo
thermo_modify dump dump_modify print run unfix label next jump if set group read_restart write_restart
""".split())
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
    """Jinja environment of an engine's templates: StrictUndefined, strict filters, no autoescape."""
    root = resources.files("siloflow.templates") / engine
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(root)), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True, autoescape=False)
    env.filters.update(num=_num, int=_integer, safe_name=_safe_name)
    return env


def check_deck(text: str) -> None:
    """Refuse a rendered deck that holds a command siloflow does not write (defence in depth)."""
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        command = stripped.split()[0]
        if command not in ALLOWED_COMMANDS or FORBIDDEN_WORDS.search(stripped):
            raise DeckError(f"rendered deck line {lineno} is not allowed: {stripped[:120]!r}")


def check_deck_file(path: Path) -> None:
    """Refuse (``SetupError``) a deck file about to reach an engine that holds a command siloflow
    does not write, or cannot be read."""
    try:
        check_deck(Path(path).read_text(encoding="utf-8", errors="replace"))
    except OSError as exc:
        raise SetupError(f"no readable deck {path}: {exc.strerror}") from None
    except DeckError as exc:
        raise SetupError(f"{path} is not a deck siloflow wrote ({exc}): refusing to run it") from None


def _matrix(d: Derived, attr: str, particle_pairs: float | None = None) -> list[float]:
    """A peratomtypepair matrix (row-major, n_types^2) of ``attr`` from the per-type-pair
    parameters; ``particle_pairs`` overrides the particle-particle entries (frictionless fill).
    Entries between wall types are unused (walls do not touch walls); they repeat type 1's."""
    n, wall = d.n_types, d.wall_type
    out = []
    for i in range(1, n + 1):
        for j in range(1, n + 1):
            a, b = min(i, j), max(i, j)
            if a >= wall:         # wall-wall, face-face, wall-face: never in contact
                a = 1
            value = getattr(d.type_pairs[(a, b)], attr)
            if particle_pairs is not None and b != wall:
                value = particle_pairs
            out.append(value)
    return out


def _type_moduli(case: Case, d: Derived) -> list[tuple]:
    """(Young's modulus, Poisson ratio) per atom type: the species' materials, then the walls
    (and a slab's faces). None for the linear models, which have no modulus."""
    walls = [_modulus_of(case, None)] * (d.n_types - len(d.species))
    return [_modulus_of(case, sp.material) for sp in d.species] + walls


def _properties(case: Case, d: Derived, restored: bool = False) -> list[dict]:
    """``fix property/global`` entries: atom types 1..K are the size classes, type K+1 the walls."""
    m = case.materials
    props = []
    if m.model == "hertz":
        moduli = _type_moduli(case, d)
        props += [("youngsModulus", "peratomtype", [e for e, _ in moduli]),
                  ("poissonsRatio", "peratomtype", [nu for _, nu in moduli]),
                  ("coefficientRestitution", "peratomtypepair", _matrix(d, "restitution"))]
    else:
        props += [(name, "peratomtypepair", _matrix(d, name)) for name in ("kn", "kt", "gamman", "gammat")]
    poured = case.fill.frictionless and not restored      # restored later: friction_restore()
    friction = _matrix(d, "friction", 0.0 if poured else None)
    props.append(("coefficientFriction", "peratomtypepair", friction))
    if uses_rolling_friction(case):
        props.append(("coefficientRollingFriction", "peratomtypepair", _matrix(d, "rolling_friction")))
    return [{"id": f"material{i + 1}", "name": n, "style": s, "numbers": v}
            for i, (n, s, v) in enumerate(props)]


def particle_templates(case: Case, d: Derived) -> list[dict]:
    """The grain templates of the distribution (spheres per size class, or the clump shape);
    with paper B's shrinking, only the poured largest size."""
    grains = d.grains
    if d.shrink_classes:
        grains = [max(grains, key=lambda sp: sp.radius)]
        weights = [1.0]
    else:
        weights = d.mass_fractions
    ntry = getattr(case.particles, "monte_carlo_tries", 0)
    return [{"type": sp.type, "seed": d.seeds["templates"][sp.type - 1], "weight": w, "density": sp.density,
             "radius": sp.radius, "spheres": sp.spheres, "ntry": ntry, "volume_limit": volume_limit(sp.radius)}
            for sp, w in zip(grains, weights)]


#: LIGGGHTS' particletemplate/sphere refuses spheres smaller than its volume_limit (default 1e-12 m3,
#: a radius of 62 um) with "Volume expectancy too small"
LIGGGHTS_VOLUME_LIMIT = 1e-12


def volume_limit(radius: float) -> float | None:
    """The ``volume_limit`` a sphere template of ``radius`` (m) needs, m3: None (LIGGGHTS'
    default) unless the sphere is smaller than the default allows, then a tenth of its volume."""
    from .contact_physics import sphere_volume
    volume = sphere_volume(radius)
    return None if volume >= LIGGGHTS_VOLUME_LIMIT else volume / 10


def dust_insertion(d: Derived, particle_rate: float) -> dict | None:
    """Dust template and insertion (None without dust): batches in proportion to the grains', at
    their steps (the deck inserts the dust first: see the template)."""
    dust = d.dust
    if dust is None:
        return None
    out = {"type": dust.type, "seed": d.seeds["templates"][dust.type - 1], "density": dust.density,
           "radius": dust.radius, "volume_limit": volume_limit(dust.radius), "count": d.dust_count,
           "rate": particle_rate * d.dust_batch / d.insertion_batch, "region": "insertion", "plane": None}
    if d.has_faces:
        # a slab is a 2D model: the grains keep to its plane (clumps by fflag/tflag, spheres by
        # their size), and so must the dust, or it slips into the gaps between grains and faces.
        # Measured (paper_a_clumps_quick): free dust rattled there at 0.1-0.5 m/s while the bed
        # crept down, holding KE/PE at 5e-4 (grains alone: 1e-7)
        r = d.insertion_region
        out["region"] = "insertion_dust"
        out["plane"] = {**r, "ylo": -1e-3 * dust.radius, "yhi": 1e-3 * dust.radius}
    return out


def friction_restore(case: Case, d: Derived) -> dict | None:
    """The friction property as it must be after a frictionless fill (None if the fill has friction)."""
    if not case.fill.frictionless:
        return None
    prop = next(p for p in _properties(case, d) if p["name"] == "coefficientFriction")
    return {"id": prop["id"], "numbers": _matrix(d, "friction"),
            "particle_friction": case.materials.particle_particle.friction}


def uses_rolling_friction(case: Case) -> bool:
    m = case.materials
    return m.particle_particle.rolling_friction > 0 or m.particle_wall.rolling_friction > 0


def deck_context(case: Case, d: Derived, walls, resume: bool = False) -> dict:
    """Everything the LIGGGHTS template places, already computed and checked."""
    m = case.materials
    youngs = [e for e, _ in _type_moduli(case, d) if e is not None]
    particle_rate = d.insertion_batch / (d.insert_every * d.timestep)
    return {
        "name": case.name, "box": d.box, "skin": d.skin,
        "hard_particles": any(e > 1e9 for e in youngs),
        "properties": _properties(case, d, restored=resume),     # a resumed bed is past the fill
        "contact_model": "hertz" if m.model == "hertz" else "hooke/stiffness",   # hooke: kn, kt computed here
        "rolling": uses_rolling_friction(case),
        "timestep": d.timestep, "gravity": case.gravity,
        "walls": [{"name": w.name, "type": d.face_type if w.role == "face" else d.wall_type}
                  for w in walls if w.role != "outlet"],
        "planar": d.has_faces,
        "seeds": d.seeds, "density": m.particle.density, "radius": d.particle_radius,
        "friction_restore": friction_restore(case, d),
        "n_types": d.n_types, "wall_type": d.wall_type,
        "templates": particle_templates(case, d),
        "dust": dust_insertion(d, particle_rate),
        "clumps": d.has_clumps, "mass_weights": d.mass_weights,
        "plate_velocity": d.plate_velocity,
        "pour_type": d.radii.index(d.particle_radius) + 1 if d.shrink_classes else 0,
        "shrink_classes": [{"diameter": 2 * r, "fraction": f, "seed": seed, "type": d.radii.index(r) + 1}
                           for (r, f), seed in zip(d.shrink_classes, d.seeds["shrink"])],
        "insertion_region": d.insertion_region, "particle_count": d.particle_count,
        "particle_rate": particle_rate,
        "insert_every": d.insert_every, "insertion_speed": d.insertion_speed,
        "check_timestep": m.model == "hertz",
        # check/timestep/gran warns when dt exceeds this fraction of the Rayleigh or Hertz time it
        # measures; siloflow's dt is timestep_fraction of its own estimate, so a warning means
        # impacts far faster than estimated, and stops the run (siloflow.engine.liggghts_log)
        "timestep_guard": min(1.0, 1.5 * case.engine.timestep_fraction),
        "thermo_every": d.thermo_every, "sample_every": d.sample_every,
        "sample_repeat": d.sample_repeat, "sample_freq": d.sample_freq,
        "dump_every": d.dump_every, "vtk": case.outputs.vtk,
        "contact_keywords": list(CONTACT_KEYWORDS), "contact_columns": contact_columns(case, d),
        "wall_contact_keywords": list(WALL_CONTACT_KEYWORDS), "wall_contact_columns": contact_columns(case, d, wall=True),
        "empty_mass": case.discharge.empty_fraction * d.total_mass,
        "planned": d.planned_steps, "fill_steps": d.fill_steps,
        "settle_max_chunks": d.settle_max_chunks, "settle_chunk_steps": d.settle_chunk_steps,
        "settle_ratio": case.fill.settle.ke_pe_ratio, "static_steps": d.static_steps,
        "opening_speed": case.discharge.opening.speed, "open_steps": d.open_steps,
        "discharge_max_chunks": d.discharge_max_chunks, "discharge_chunk_steps": d.discharge_chunk_steps,
    }


def render_deck_text(case: Case, d: Derived, walls, resume: bool = False) -> str:
    """The rendered, checked ``in.liggghts`` text; with ``resume``, the deck that reads the settled
    bed's restart file and goes on from the static stage."""
    try:
        text = template_environment("liggghts").get_template("in.liggghts.j2").render(
            {**deck_context(case, d, walls, resume), "resume": resume, "restart_file": RESTART_FILE})
    except jinja2.UndefinedError as exc:
        raise DeckError(f"template needs a value siloflow did not provide: {exc}") from exc
    check_deck(text)
    return text


def contact_columns(case: Case, d: Derived, wall: bool = False) -> list[str]:
    """Column names of the pair-contact (or, with ``wall``, particle-wall contact) dump; empty
    when the case writes none."""
    if not (d.dump_every and case.outputs.contacts):
        return []
    return local_columns(WALL_CONTACT_KEYWORDS, wall=True) if wall else local_columns(CONTACT_KEYWORDS)


def write_deck(case: Case, folder: Path) -> Derived:
    """Write the deck files of ``case`` into the existing, empty ``folder``."""
    d = derive(case)
    walls = silo_meshes(case, d.outlet_z, d.outlet_disc_radius)
    text = render_deck_text(case, d, walls)
    (folder / "meshes").mkdir()
    for sub in ["output", "output/restart"] + (["output/dumps"] if d.dump_every else []) + (
            ["output/vtk"] if d.dump_every and case.outputs.vtk else []):
        (folder / sub).mkdir()
    for w in walls:
        write_stl(w, folder / "meshes" / f"{w.name}.stl")
    write_text(folder / DECK_NAME, text)
    # the run folder is self-contained: its case names the inserts' copies, already in metres
    stored = case.model_copy(update={"inserts": [
        ins.model_copy(update={"file": f"meshes/{ins.mesh_name}.stl", "scale": 1.0}) for ins in case.inserts]})
    write_text(folder / CASE_NAME, case_to_yaml(stored))
    info = d.to_json()
    info["siloflow_version"] = __version__
    info["engine"] = case.engine.name
    info["engine_ranks"] = case.engine.ranks
    info["gravity"] = case.gravity
    info["contact_columns"] = contact_columns(case, d)
    info["wall_contact_columns"] = contact_columns(case, d, wall=True)
    info["walls"] = [w.info() for w in walls]
    sectors = 2 if d.has_faces else case.sensors.sectors          # a slab: one section per side wall
    info["sensors"] = {"sectors": sectors, "bands": len([w for w in walls if w.role == "band"]) // sectors}
    write_json(folder / DERIVED_NAME, info)
    return d


def write_resume_deck(folder) -> Path:
    """Write ``in.resume.liggghts`` into a run folder, from its own case.yaml (whose inserts point at
    the folder's mesh copies); the other files of the folder are left as they are."""
    from .case import load_case
    folder = Path(folder)
    case = load_case(folder / CASE_NAME)
    d = derive(case)
    text = render_deck_text(case, d, silo_meshes(case, d.outlet_z, d.outlet_disc_radius), resume=True)
    write_text(folder / RESUME_DECK_NAME, text)
    return folder / RESUME_DECK_NAME


def write_manifest(folder: Path) -> None:
    """List every file of a freshly written deck folder, with its SHA-256, in the manifest
    (siloflow's marker: ``--force`` and ``--resume`` read it)."""
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    write_json(folder / MANIFEST_NAME, {"siloflow_version": __version__,
                                        "files": {f: sha256(folder / f) for f in files}})


def verify_deck(folder) -> None:
    """Check that a run folder's deck is the one its own validated case renders, before an
    engine runs it: the case is loaded and validated again, the deck rendered anew into a
    scratch folder, and ``in.liggghts``, ``derived.json`` and every mesh compared byte by byte
    (and the deck checked against the allowlist). A folder from elsewhere, edited by hand or
    rendered by another siloflow version is refused with the first file that differs."""
    import tempfile
    from .case import load_case
    folder = Path(folder)
    check_plain_tree(folder)        # no link or FIFO: the engine's writes stay inside, the reads end
    check_deck_file(folder / DECK_NAME)
    case = load_case(folder / CASE_NAME)
    with tempfile.TemporaryDirectory(prefix="siloflow-verify-") as scratch:
        fresh = Path(scratch)
        write_deck(case, fresh)
        names = [DECK_NAME, DERIVED_NAME] + sorted(p.relative_to(fresh).as_posix()
                                                   for p in (fresh / "meshes").glob("*.stl"))
        for name in names:
            mine = folder / name
            if not mine.is_file() or mine.read_bytes() != (fresh / name).read_bytes():
                raise SetupError(f"{mine} is not what the folder's {CASE_NAME} renders (edited, or written by "
                                 f"another siloflow version): refusing to run it; render the case anew with "
                                 f"'siloflow render {folder / CASE_NAME} -o NEW_FOLDER'")


def render(case: Case, folder, force: bool = False, keep=()) -> Path:
    """Render ``case`` into a new deck folder (atomically: all or nothing). Returns the folder.
    ``force`` replaces an existing siloflow folder (never one holding a file of ``keep``, the
    files being read, nor one holding files siloflow did not write)."""
    folder = Path(folder)
    keep = list(keep) + [ins.file for ins in case.inserts]
    with new_folder(folder, force=force, keep=keep) as tmp:
        write_deck(case, tmp)
        write_manifest(tmp)
    return folder.absolute()
