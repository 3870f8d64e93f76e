"""Write a run plan as a LIGGGHTS 3.8 deck: ``in.liggghts`` (template ``in.liggghts.j2``), the
walls as ASCII STL under ``meshes/``, and the dump layout; the resumed run's ``in.resume.liggghts``.

The template holds deck syntax only: every value comes from the plan (physics) and its
LIGGGHTS encoding (:mod:`.encoding`), and passes the deck filters on its way in. The rendered
deck may only contain the commands of :data:`ALLOWED_COMMANDS`.
"""
from __future__ import annotations

from pathlib import Path

import jinja2

from ...atomic_files import write_text
from ...contact_physics import sphere_volume
from ...deck import DeckError, check_commands, template_environment
from ...engines import ENGINE_FILES
from ...fill_placement import Batch, fill_batches, fill_steps
from ...geometry import write_stl
from ...plan import RunPlan
from ...run_folder import RESTART_FILE, DumpLayout, RunFolder
from .encoding import LiggghtsEncoding, encode
from .side_walls import binned_pieces, on_primitive, primitive_sides, sampled_walls
from .tables import CONTACT_KEYWORDS, WALL_CONTACT_KEYWORDS, local_columns

DECK_NAME = ENGINE_FILES["liggghts"].names["deck"]
RESUME_DECK_NAME = ENGINE_FILES["liggghts"].names["resume_deck"]

#: The only commands a siloflow LIGGGHTS deck may contain (no shell, include, python, ...).
ALLOWED_COMMANDS = frozenset("""
atom_style atom_modify boundary newton communicate units processors region create_box neighbor
neigh_modify hard_particles soft_particles fix pair_style pair_coeff timestep compute variable thermo_style thermo
thermo_modify dump dump_modify print run unfix label next jump if set group read_restart write_restart read_dump
""".split())

#: LIGGGHTS' particletemplate/sphere refuses spheres smaller than its volume_limit (default 1e-12 m3,
#: a radius of 62 um) with "Volume expectancy too small"
LIGGGHTS_VOLUME_LIMIT = 1e-12
#: Pa: LIGGGHTS 3.8 refuses a smaller youngsModulus in SI units without 'soft_particles yes'
LIGGGHTS_SOFT_LIMIT = 5e6


def check_deck(text: str) -> None:
    """Refuse a rendered LIGGGHTS deck holding a command siloflow does not write (``DeckError``)."""
    check_commands(text, ALLOWED_COMMANDS)


def before_stage_run(text: str, stage: str) -> str:
    """A rendered deck up to its stage ``stage``'s first ``run`` line (left out), newline-ended:
    the set-up and the stage's own commands, for a test or benchmark to run part of the stage."""
    start = text.index(f"SILOFLOW_STAGE {stage}")
    return text[:text.index("\nrun ", start) + 1]


def volume_limit(radius: float) -> float | None:
    """The ``volume_limit`` a sphere template of ``radius`` (m) needs, m3: None (LIGGGHTS'
    default) unless the sphere is smaller than the default allows, then a tenth of its volume."""
    volume = sphere_volume(radius)
    return None if volume >= LIGGGHTS_VOLUME_LIMIT else volume / 10


def _matrix(plan: RunPlan, enc: LiggghtsEncoding, attr: str, particle_pairs: float | None = None) -> list[float]:
    """A peratomtypepair matrix (row-major, n_types^2) of ``attr`` from the per-type-pair
    parameters; ``particle_pairs`` overrides the particle-particle entries (frictionless fill).
    Entries between wall types are unused (walls do not touch walls); they repeat type 1's."""
    n, wall = enc.n_types, enc.wall_type
    out = []
    for i in range(1, n + 1):
        for j in range(1, n + 1):
            a, b = min(i, j), max(i, j)
            if a >= wall:         # wall-wall, face-face, wall-face: never in contact
                a = 1
            value = getattr(enc.type_pairs[(a, b)], attr)
            if particle_pairs is not None and b != wall:
                value = particle_pairs
            out.append(value)
    return out


def _type_moduli(plan: RunPlan, enc: LiggghtsEncoding) -> list[tuple]:
    """(Young's modulus, Poisson ratio) per atom type: the species' materials, then the walls
    (and a slab's faces)."""
    wall = plan.materials["wall"]
    walls = [(wall.youngs_modulus, wall.poisson_ratio)] * (enc.n_types - len(plan.species))
    return [(plan.materials[sp.material].youngs_modulus, plan.materials[sp.material].poisson_ratio)
            for sp in plan.species] + walls


def uses_rolling_friction(plan: RunPlan) -> bool:
    return plan.pairs["particle_particle"].rolling_friction > 0 or plan.pairs["particle_wall"].rolling_friction > 0


def _properties(plan: RunPlan, enc: LiggghtsEncoding, restored: bool = False) -> list[dict]:
    """``fix property/global`` entries: atom types 1..K are the species, type K+1 the walls."""
    props = []
    if plan.contact_model == "hertz":
        moduli = _type_moduli(plan, enc)
        props += [("youngsModulus", "peratomtype", [e for e, _ in moduli]),
                  ("poissonsRatio", "peratomtype", [nu for _, nu in moduli]),
                  ("coefficientRestitution", "peratomtypepair", _matrix(plan, enc, "restitution"))]
    else:
        props += [(name, "peratomtypepair", _matrix(plan, enc, name)) for name in ("kn", "kt", "gamman", "gammat")]
    poured = plan.fill.frictionless and not restored      # restored later: friction_restore()
    props.append(("coefficientFriction", "peratomtypepair", _matrix(plan, enc, "friction", 0.0 if poured else None)))
    if uses_rolling_friction(plan):
        props.append(("coefficientRollingFriction", "peratomtypepair", _matrix(plan, enc, "rolling_friction")))
    return [{"id": f"material{i + 1}", "name": n, "style": s, "numbers": v}
            for i, (n, s, v) in enumerate(props)]


def particle_templates(plan: RunPlan, enc: LiggghtsEncoding, monte_carlo_tries: int) -> list[dict]:
    """The grain templates of the distribution (spheres per size class, or the clump shape);
    with paper B's shrinking, only the poured largest size."""
    grains = plan.grains
    if plan.fill.shrink_classes:
        grains = [max(grains, key=lambda sp: sp.radius)]
        weights = [1.0]
    else:
        weights = plan.fill.mass_fractions
    return [{"type": enc.types[sp.name], "seed": enc.seeds["templates"][enc.types[sp.name] - 1], "weight": w,
             "density": sp.density, "radius": sp.radius, "spheres": sp.spheres, "ntry": monte_carlo_tries,
             "volume_limit": volume_limit(sp.radius)}
            for sp, w in zip(grains, weights)]


def dust_insertion(plan: RunPlan, enc: LiggghtsEncoding, particle_rate: float) -> dict | None:
    """Dust template and insertion (None without dust): batches in proportion to the grains', at
    their steps (the deck inserts the dust first: see the template)."""
    dust = plan.dust
    if dust is None:
        return None
    t = enc.types[dust.name]
    out = {"type": t, "seed": enc.seeds["templates"][t - 1], "density": dust.density,
           "radius": dust.radius, "volume_limit": volume_limit(dust.radius), "count": plan.fill.dust_count,
           "rate": particle_rate * plan.fill.dust_batch / plan.fill.batch, "region": "insertion", "plane": None}
    if plan.planar:
        # a slab is a 2D model: the grains keep to its plane (clumps by fflag/tflag, spheres by
        # their size), and so must the dust, or it slips into the gaps between grains and faces.
        # Measured (paper_a_clumps_quick): free dust rattled there at 0.1-0.5 m/s while the bed
        # crept down, holding KE/PE at 5e-4 (grains alone: 1e-7)
        r = plan.fill.region.model_dump()
        out["region"] = "insertion_dust"
        out["plane"] = {**r, "ylo": -1e-3 * dust.radius, "yhi": 1e-3 * dust.radius}
    return out


def friction_restore(plan: RunPlan, enc: LiggghtsEncoding) -> dict | None:
    """The friction property as it must be after a frictionless fill (None if the fill has friction)."""
    if not plan.fill.frictionless:
        return None
    prop = next(p for p in _properties(plan, enc) if p["name"] == "coefficientFriction")
    return {"id": prop["id"], "numbers": _matrix(plan, enc, "friction"),
            "particle_friction": plan.pairs["particle_particle"].friction}


def guarded(plan: RunPlan) -> bool:
    """Does the deck carry the instability guard's signals (``engine.guard.enabled``)?"""
    return plan.guard is not None and plan.guard.enabled


def pair_keywords(plan: RunPlan) -> list[str]:
    """Keywords of the deck's one pair/gran/local compute (LIGGGHTS allows one): the dumped
    contacts' and, with the guard, the overlap ``delta``; empty when the deck needs none."""
    keys = list(CONTACT_KEYWORDS) if plan.outputs.contacts else []
    return keys + ["delta"] if guarded(plan) else keys


def contact_columns(plan: RunPlan, wall: bool = False) -> list[str]:
    """Column names of the pair-contact (or, with ``wall``, particle-wall contact) dump; empty
    when the run writes none."""
    if not plan.outputs.contacts:
        return []
    return local_columns(WALL_CONTACT_KEYWORDS, wall=True) if wall else local_columns(pair_keywords(plan))


#: where a deck's placed fill batches are, in its folder (read by ``read_dump``)
FILL_FOLDER = "fill"


def batch_file_name(index: int) -> str:
    """The file of the fill's batch ``index`` (from 0) under :data:`FILL_FOLDER`."""
    return f"batch_{index + 1:04d}.txt"


def placed_fill(plan: RunPlan, enc: LiggghtsEncoding) -> dict | None:
    """The fill stage's batches as the deck reads them (``siloflow.fill_placement``): each one's
    file, step and the steps run after it (the last also runs the fall); the densities the deck
    sets by type. None for clumps: LIGGGHTS' multisphere insertion places them."""
    if plan.has_clumps:
        return None
    batches = fill_batches(plan)
    total = fill_steps(plan, len(batches))
    steps = [b.step for b in batches] + [total]
    kinds = {k for b in batches for k in b.kinds}
    return {"batches": [{"name": batch_file_name(i), "step": b.step, "run": steps[i + 1] - b.step}
                        for i, b in enumerate(batches)],
            "densities": [{"type": enc.types[plan.species[k].name], "density": plan.species[k].density}
                          for k in sorted(kinds)],
            "steps": total,
            # the atom-sorting and neighbour bin: LAMMPS' default once grains are in (half the neighbour
            # cut-off, 2 r_max + skin), set because the empty box before the first batch has no cut-off
            # (its default bin is then the box's x size, refused in a thin slab)
            "bin": max(sp.bounding_radius for sp in plan.species) + 0.5 * enc.skin}


def batch_dump_text(plan: RunPlan, enc: LiggghtsEncoding, batch: Batch, first_id: int) -> str:
    """A placed batch as a LIGGGHTS dump snapshot at its step (``read_dump ... add yes``): atom
    IDs from ``first_id``, the species' atom types, moving down at the insertion speed."""
    box, vz = enc.box, -plan.fill.insertion_speed
    lines = ["ITEM: TIMESTEP", str(batch.step), "ITEM: NUMBER OF ATOMS", str(len(batch.kinds)),
             "ITEM: BOX BOUNDS ff ff ff", *(f"{box[a + 'lo']!r} {box[a + 'hi']!r}" for a in "xyz"),
             "ITEM: ATOMS id type x y z vx vy vz radius"]
    for n, (k, p) in enumerate(zip(batch.kinds, batch.centres)):
        sp = plan.species[k]
        lines.append(f"{first_id + n} {enc.types[sp.name]} {float(p[0])!r} {float(p[1])!r} {float(p[2])!r} "
                     f"0.0 0.0 {float(vz)!r} {float(sp.radius)!r}")
    return "\n".join(lines) + "\n"


def deck_context(plan: RunPlan, enc: LiggghtsEncoding, monte_carlo_tries: int, resume: bool = False) -> dict:
    """Everything the LIGGGHTS template places, already computed and checked."""
    fill = None if resume else placed_fill(plan, enc)
    planned = plan.planned_steps(enc.open_steps)
    if fill is not None:
        planned["fill"] = fill["steps"]
    youngs = [e for e, _ in _type_moduli(plan, enc) if e is not None]
    f = plan.fill
    particle_rate = f.batch / (f.insert_every * plan.dt)
    radii = f.radii
    return {
        "name": plan.name, "box": enc.box, "skin": enc.skin,
        "boundary_y": "p" if plan.geometry.periodic_depth else "f",     # a slab periodic along y
        # LIGGGHTS refuses moduli outside 5e6-1e9 Pa in SI units unless told (docs/engine_facts.md)
        "hard_particles": any(e > 1e9 for e in youngs), "soft_particles": any(e < LIGGGHTS_SOFT_LIMIT for e in youngs),
        "properties": _properties(plan, enc, restored=resume),     # a resumed bed is past the fill
        "contact_model": "hertz" if plan.contact_model == "hertz" else "hooke/stiffness",   # hooke: kn, kt here
        "rolling": uses_rolling_friction(plan),
        "timestep": plan.dt, "gravity": plan.gravity,
        "walls": [{"name": w.name, "fid": fix_id(w.name, w.role, resume),
                   "type": enc.face_type if w.role == "face" else enc.wall_type, "stress": plan.outputs.wall_forces,
                   "move": floor_offset(plan, w.role) if resume else None}
                  for w in plan.walls if w.is_wall and not on_primitive(plan, w)],
        # the side walls as primitives, their pieces' forces binned in the engine (.side_walls)
        "primitive_sides": primitive_sides(plan),
        "binned_pieces": binned_pieces(plan) if plan.outputs.wall_forces else [],
        "sampled_walls": sampled_walls(plan, lambda w: fix_id(w.name, w.role, resume))
        if plan.outputs.wall_forces else [],
        "store_side_force": plan.outputs.wall_forces or plan.outputs.contacts,
        "outlet_id": fix_id("outlet", "outlet", resume), "plate_id": fix_id("plate", "plate", resume),
        "planar": plan.planar,
        "seeds": enc.seeds, "density": plan.grains[0].density, "radius": plan.particle_radius,
        "friction_restore": friction_restore(plan, enc),
        "n_types": enc.n_types, "wall_type": enc.wall_type,
        "templates": particle_templates(plan, enc, monte_carlo_tries),
        "dust": dust_insertion(plan, enc, particle_rate),
        "clumps": plan.has_clumps, "mass_weights": enc.mass_weights,
        "plate_velocity": enc.plate_velocity,
        "pour_type": radii.index(plan.particle_radius) + 1 if f.shrink_classes else 0,
        "shrink_classes": [{"diameter": 2 * r, "fraction": fr, "seed": seed, "type": radii.index(r) + 1}
                           for (r, fr), seed in zip(f.shrink_classes, enc.seeds["shrink"])],
        "insertion_region": f.region.model_dump(), "particle_count": f.count,
        "particle_rate": particle_rate,
        "insert_every": f.insert_every, "insertion_speed": f.insertion_speed,
        "check_timestep": plan.contact_model == "hertz",
        # check/timestep/gran warns when dt exceeds this fraction of the Rayleigh or Hertz time it
        # measures; siloflow's dt is timestep_fraction of its own estimate, so a warning means
        # impacts far faster than estimated, and stops the run (siloflow.engine.liggghts.log)
        "timestep_guard": min(1.0, 1.5 * plan.timestep.fraction),
        "thermo_every": plan.outputs.thermo_every, "sample_every": enc.sample_every,
        "sample_repeat": enc.sample_repeat, "sample_freq": enc.sample_freq,
        "dump_every": plan.outputs.dump_every, "vtk": plan.outputs.vtk,
        "pair_keywords": pair_keywords(plan), "contact_columns": contact_columns(plan),
        "delta_column": local_columns(pair_keywords(plan)).index("delta") + 1 if guarded(plan) else 0,
        "wall_contact_keywords": list(WALL_CONTACT_KEYWORDS), "wall_contact_columns": contact_columns(plan, wall=True),
        "empty_mass": plan.discharge.empty_mass,
        "planned": planned, "fill_steps": f.steps, "placed_fill": fill,
        "settle_max_chunks": plan.settle.max_chunks, "settle_chunk_steps": plan.settle.chunk_steps,
        "settle_ratio": plan.settle.ke_pe_ratio, "static_steps": plan.static_steps,
        "opening_speed": plan.opening.speed, "open_steps": enc.open_steps,
        "discharge_max_chunks": plan.discharge.max_chunks, "discharge_chunk_steps": plan.discharge.chunk_steps,
        "steady": plan.discharge.steady, "mobilise": plan.fill.mobilise,
        "guard": plan.guard if guarded(plan) else None,
    }


#: walls a resumed deck defines as new fixes: LIGGGHTS restores a restarted fix's mesh from the
#: restart file ("data will be taken from restart file"), so a run from a cached fill with another
#: orifice would keep the fill's floor, plate and counting disc (docs/engine_facts.md)
NEW_ON_RESUME = ("bottom", "plate", "outlet")


def fix_id(name: str, role: str, resume: bool) -> str:
    """The fix ID of a mesh: its name, or a new one in a resumed deck for the floor's meshes."""
    return f"{name}_resumed" if resume and role in NEW_ON_RESUME else name


def floor_offset(plan: RunPlan, role: str) -> float | None:
    """Where a resumed deck's new floor mesh starts, m along z: lowered by the mobilising step
    (``fill.mobilise``) if the fill had one, else where its STL file puts it (None)."""
    m = plan.fill.mobilise
    if m is None or role not in ("bottom", "plate"):
        return None
    return -m.drop


def monte_carlo_tries(plan: RunPlan) -> int:
    """LIGGGHTS' multisphere template's Monte Carlo tries (0 for spheres): the case's
    ``particles.monte_carlo_tries``, which the plan carries in its engine options."""
    return plan.engine.options.get("monte_carlo_tries", 0)


def render_deck_text(plan: RunPlan, resume: bool = False,
                     enc: LiggghtsEncoding | None = None) -> str:
    """The rendered, checked ``in.liggghts`` text; with ``resume``, the deck that reads the settled
    bed's restart file and goes on from the static stage. ``enc``: the plan's encoding, if made."""
    enc = enc if enc is not None else encode(plan)
    try:
        text = template_environment("liggghts").get_template("in.liggghts.j2").render(
            {**deck_context(plan, enc, monte_carlo_tries(plan), resume), "resume": resume,
             "restart_file": RESTART_FILE})
    except jinja2.UndefinedError as exc:
        raise DeckError(f"template needs a value siloflow did not provide: {exc}") from exc
    check_deck(text)
    return text


def write_deck(plan: RunPlan, folder: Path) -> None:
    """Write the LIGGGHTS deck of ``plan`` into the run folder ``folder`` being rendered: the deck,
    the walls' STL meshes, the output folders the deck writes into, the dump layout."""
    folder = Path(folder)
    enc = encode(plan)
    text = render_deck_text(plan, enc=enc)
    (folder / "meshes").mkdir()
    out = plan.outputs
    for sub in ["output", "output/restart"] + (["output/dumps"] if out.dump_every else []) + (
            ["output/vtk"] if out.vtk else []):
        (folder / sub).mkdir()
    for w in plan.meshes:
        write_stl(w, folder / "meshes" / f"{w.name}.stl")
    if not plan.has_clumps:
        (folder / FILL_FOLDER).mkdir()
        first_id = 1
        for i, batch in enumerate(fill_batches(plan)):
            write_text(folder / FILL_FOLDER / batch_file_name(i), batch_dump_text(plan, enc, batch, first_id))
            first_id += len(batch.kinds)
    write_text(folder / DECK_NAME, text)
    RunFolder(folder).write_dump_layout(DumpLayout(
        engine="liggghts", types={t: name for name, t in enc.types.items()},
        contact_columns=contact_columns(plan), wall_contact_columns=contact_columns(plan, wall=True),
        clump_mass="body",          # multisphere: every sphere carries its clump's mass
        primitive_walls=[{"name": w["fid"], "style": w["style"], "args": w["args"]} for w in primitive_sides(plan)]
        if plan.outputs.contacts else []))


def write_resume_deck(plan: RunPlan, folder) -> Path:
    """Write ``in.resume.liggghts`` into a run folder (the other files are left as they are)."""
    path = Path(folder) / RESUME_DECK_NAME
    write_text(path, render_deck_text(plan, resume=True))
    return path


#: the deck that reads a cached settled bed back (siloflow.fill_cache checks it against the plan before a
#: run starts from it): the restart file ``bed.restart`` in, its atoms' type, radius and mass out, full precision
BED_DECK_NAME = "in.bed.liggghts"
BED_RESTART = "bed.restart"
BED_DUMP = "bed.txt"
BED_DECK = f"""# siloflow: a cached settled bed read back for its check against the case (siloflow.fill_cache)
atom_modify     map array
units           si
read_restart    {BED_RESTART}
write_dump      all custom {BED_DUMP} type radius mass modify format "%d %.17g %.17g"
"""
