"""Two-body runs for the contact-law tests, in LIGGGHTS or LAMMPS.

Two spheres (or one sphere and a floor, the plane z = 0 of the walls' material) with the contact
lines of the deck each engine renders for the case (LIGGGHTS' resumed deck, friction restored;
LAMMPS' ``model`` and ``restore_friction`` sections), so the chain case -> plan -> deck -> engine
is measured. Every step is dumped (full precision) and read back as per-step arrays.
"""
from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from unittest import mock

import numpy as np

from siloflow.deck import template_environment

ENGINES = ("liggghts", "lammps")
#: the dump's columns after the atom id (then, with a floor, the floor's force on the atom)
STATE = ("x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz")
_environment = lru_cache(maxsize=None)(template_environment)


@dataclass(frozen=True)
class Body:
    """A sphere of a plan's species: position (m), velocity (m/s), angular velocity (rad/s)."""

    species: str
    position: tuple
    velocity: tuple = (0.0, 0.0, 0.0)
    omega: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Setup:
    """What is run: ``bodies`` for ``steps`` steps of ``dt`` s; ``floor`` adds the plane z = 0,
    ``gravity`` (m/s2) pulls along -z, ``hold`` zeroes the forces (torques still act)."""

    bodies: list = field(default_factory=list)
    dt: float = 0.0
    steps: int = 0
    floor: bool = False
    gravity: float = 0.0
    hold: bool = False


def run(engine: str, case, plan, folder: Path, setups: list) -> list[dict]:
    """Run ``setups`` in ``engine`` (in ``folder``); per setup and frame (step 0 first): ``time``
    (s), ``x``, ``v``, ``omega`` (frame, body, 3) and, with a floor, ``wall`` (the floor's force
    on each body, N)."""
    if engine == "liggghts":
        out = run_liggghts({"run": (case, plan, setups)}, folder)["run"]
        assert not isinstance(out, str), out
        return out
    dumps = _dumps(folder, "lammps", setups)
    for setup, dump in zip(setups, dumps):
        _run_lammps(plan, setup, dump)
    return _read(setups, dumps)


def run_liggghts(jobs: dict, folder: Path) -> dict:
    """Every job's setups (``{name: (case, plan, setups)}``) in one LIGGGHTS process: Open MPI's
    singleton start takes half a second a process. When it fails, each job runs alone. Returns
    ``{name: what run returns}``, or LIGGGHTS' log tail for a job that failed."""
    folder = Path(folder)
    decks, dumps = {}, {}
    for name, (case, plan, setups) in jobs.items():
        dumps[name] = _dumps(folder, name, setups)
        decks[name] = _liggghts_decks(case, plan, setups, dumps[name])
    if _liggghts(folder, "all", list(decks.values())) is None:
        return {name: _read(jobs[name][2], dumps[name]) for name in jobs}
    out = {}
    for name in jobs:
        error = _liggghts(folder, name, [decks[name]])
        out[name] = error if error is not None else _read(jobs[name][2], dumps[name])
    return out


def read_dump(path: Path, n: int, dt: float, wall: bool = False) -> dict:
    """The per-step arrays of a ``dump custom`` of ``n`` atoms (sorted by id, every step)."""
    lines = Path(path).read_text().splitlines()
    frame = 9 + n
    frames = len(lines) // frame
    steps = np.array([int(lines[k * frame + 1]) for k in range(frames)])
    rows = " ".join(lines[k * frame + 9 + i] for k in range(frames) for i in range(n))
    data = np.array(rows.split(), dtype=float).reshape(frames, n, -1)
    out = {"time": steps * dt, "x": data[:, :, 1:4], "v": data[:, :, 4:7], "omega": data[:, :, 7:10]}
    if wall:
        out["wall"] = data[:, :, 10:13]
    return out


def _dumps(folder: Path, name: str, setups: list) -> list[Path]:
    return [Path(folder) / f"{name}-{k}.dump" for k in range(len(setups))]


def _read(setups: list, dumps: list) -> list[dict]:
    return [read_dump(dump, len(s.bodies), s.dt, wall=s.floor) for s, dump in zip(setups, dumps)]


def _species(plan, name):
    return next(sp for sp in plan.species if sp.name == name)


def _head(plan, setup: Setup, atoms: str, n_types: int) -> str:
    """Units, the engine's ``atoms`` lines, the box (a cube of 40 of the largest radius) and the
    neighbour settings."""
    box = 20 * max(_species(plan, b.species).radius for b in setup.bodies)
    return f"""units           si
{atoms}
boundary        f f f
newton          off
region          domain block {-box!r} {box!r} {-box!r} {box!r} {-box!r} {box!r} units box
create_box      {n_types} domain
neighbor        {box / 40!r} bin
neigh_modify    delay 0
"""


def _atoms(plan, setup: Setup, types: dict, omega_keywords) -> str:
    """The atoms (one per body), their velocities and the integration, both engines' syntax."""
    lines = [f"timestep        {setup.dt!r}"]
    for k, b in enumerate(setup.bodies, 1):
        sp = _species(plan, b.species)
        x, y, z = b.position
        vx, vy, vz = b.velocity
        lines += [f"create_atoms    {types[b.species]} single {x!r} {y!r} {z!r} units box",
                  f"set             atom {k} diameter {2 * sp.radius!r} density {sp.density!r}",
                  f"set             atom {k} vx {vx!r} vy {vy!r} vz {vz!r}"]
        if any(b.omega):
            lines.append(f"set             atom {k} {omega_keywords(b.omega)}")
    if setup.gravity:
        lines.append(f"fix             gravity all gravity {setup.gravity!r} vector 0.0 0.0 -1.0")
    if setup.hold:
        lines.append("fix             hold all setforce 0.0 0.0 0.0")
    lines.append("fix             integrate all nve/sphere")
    return "\n".join(lines) + "\n"


def _dump(path, wall_columns: list, format_line) -> str:
    columns = ["id", *STATE, *wall_columns]
    return (f"dump            traj all custom 1 {path} {' '.join(columns)}\n"
            f"dump_modify     traj sort id {format_line(len(columns))}\n")


def rendered(module, *args) -> str:
    """``module.render_deck_text(*args)`` with one jinja environment per engine: siloflow makes
    (and compiles its template in) a new one per deck, a third of a second each."""
    with mock.patch.object(module, "template_environment", _environment):
        return module.render_deck_text(*args)


# ------------------------------------------------------------------ LIGGGHTS

LIGGGHTS_ATOMS = "atom_style      granular\natom_modify     map array\ncommunicate     single vel yes"

def liggghts_contact_lines(plan, case) -> tuple[list[str], str]:
    """The contact-law lines of the case's resumed LIGGGHTS deck (friction restored) and its
    walls' ``fix wall/gran`` line."""
    from siloflow.engine.liggghts import deck
    text = rendered(deck, plan, True).splitlines()
    law = [ln for ln in text if ln.startswith(("fix             material", "pair_style", "pair_coeff"))]
    walls = next(ln for ln in text if ln.startswith("fix             walls "))
    return law, walls


def liggghts_floor(walls: str, wall_type: int) -> str:
    """The deck's ``fix walls ... mesh n_meshes N meshes ...`` as a primitive plane z = 0 of the
    walls' atom type (the model keywords kept, the force stored for the dump)."""
    words = walls.split()
    at = words.index("mesh")
    n = int(words[at + 2])
    words[at:at + 4 + n] = ["primitive", "type", str(wall_type), "zplane", "0.0", "store_force", "yes"]
    words[1] = "wall"
    return " ".join(words)


def _liggghts_decks(case, plan, setups: list, dumps: list) -> str:
    """The LIGGGHTS input running ``setups`` one after another (``clear`` between them)."""
    from siloflow.engine.liggghts.encoding import encode
    enc = encode(plan)
    law, walls = liggghts_contact_lines(plan, case)
    decks = []
    for setup, dump in zip(setups, dumps):
        deck = _head(plan, setup, LIGGGHTS_ATOMS, enc.n_types) + "\n".join(law) + "\n"
        if setup.floor:
            deck += liggghts_floor(walls, enc.wall_type) + "\n"
        deck += _atoms(plan, setup, enc.types, lambda w: f"omegax {w[0]!r} omegay {w[1]!r} omegaz {w[2]!r}")
        wall_columns = [f"f_force_wall[{i}]" for i in (1, 2, 3)] if setup.floor else []
        deck += _dump(dump.name, wall_columns, lambda n: 'format "%d' + " %.17g" * (n - 1) + '"')
        decks.append(deck + f"run             {setup.steps}\n")
    return "clear\n".join(decks)


def _liggghts(folder: Path, name: str, decks: list) -> str | None:
    """Run the decks in one LIGGGHTS process in ``folder``: None, or the log's tail if it failed."""
    (folder / f"in.{name}").write_text("clear\n".join(decks))
    done = subprocess.run(["liggghts", "-in", f"in.{name}", "-log", f"log.{name}", "-screen", "none"], cwd=folder,
                          capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
    if done.returncode == 0:
        return None
    log = folder / f"log.{name}"
    return (log.read_text(errors="replace") if log.is_file() else done.stdout + done.stderr)[-2000:]


# ------------------------------------------------------------------ LAMMPS

LAMMPS_ATOMS = "atom_style      sphere\natom_modify     map array sort 0 0.0\ncomm_modify     vel yes"

def lammps_contact_lines(plan) -> tuple[int, list[str], dict]:
    """Of the case's LAMMPS deck: its atom types' count, its ``pair_style`` and ``pair_coeff`` lines
    (the fill's, then those restoring friction) and each species' wall model text (``fix ...
    wall/gran/region granular <text> region side``, the side wall's)."""
    from siloflow.engine.lammps import deck
    parts = deck.sections(rendered(deck, plan))
    n_types = int(next(ln for ln in parts["box"] if ln.startswith("create_box")).split()[1])
    pairs = [ln for ln in parts["model"] + parts.get("restore_friction", []) if ln.startswith(("pair_style", "pair_coeff"))]
    groups = {"all": [k + 1 for k in range(len(plan.species))]}
    for ln in parts["model"]:
        words = ln.split()
        if words[0] == "group" and words[2] == "type":
            groups[words[1]] = [int(t) for t in words[3:]]
    walls = {}
    for ln in parts["model"]:
        m = re.match(r"fix\s+\S+\s+(\S+)\s+wall/gran/region granular (.*) region side contacts$", ln)
        if m:
            for t in groups[m.group(1)]:
                walls[plan.species[t - 1].name] = m.group(2)
    return n_types, pairs, walls


def _run_lammps(plan, setup: Setup, dump: Path) -> None:
    from siloflow.engine.lammps.module import load_lammps
    n_types, pairs, walls = lammps_contact_lines(plan)
    deck = _head(plan, setup, LAMMPS_ATOMS, n_types) + "\n".join(pairs) + "\n"
    if setup.floor:
        (name,) = {b.species for b in setup.bodies}
        deck += ("region          floor plane 0.0 0.0 0.0 0.0 0.0 1.0 side in units box\n"
                 f"fix             wall all wall/gran/region granular {walls[name]} region floor contacts\n")
    deck += _atoms(plan, setup, {sp.name: k + 1 for k, sp in enumerate(plan.species)},
                   lambda w: f"omega {w[0]!r} {w[1]!r} {w[2]!r}")
    # the wall fix's per-atom contacts: the flag, then the force on the particle
    wall_columns = [f"f_wall[{i}]" for i in (2, 3, 4)] if setup.floor else []
    deck += _dump(dump, wall_columns, lambda n: "format float %.17g")
    lmp = load_lammps().lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        lmp.commands_string(deck)
        lmp.command(f"run {setup.steps}")
    finally:
        lmp.close()
