"""Reading LIGGGHTS screen/log output: stage markers, thermo rows, warnings and errors,
and turning a failure into a message with its likely cause and fix."""
from __future__ import annotations

import math
import re
import signal
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from ...errors import ANSI_ESCAPES
from ...guard import GuardTrip, RunGuard
from .deck import LIGGGHTS_VOLUME_LIMIT

_STAGE = re.compile(r"^SILOFLOW_STAGE (\w+) (\d+)\s*$")
_MARK = re.compile(r"^SILOFLOW_(INSERTED|SETTLED|NOT_SETTLED|DONE)\s*(\S*)\s*$")
#: why an until_steady discharge stopped (steady, empty, max_time; clogged: nothing flowed over the
#: batches after the start-up) and the rate's relative error then
_STOP = re.compile(r"^SILOFLOW_STOP (steady|empty|max_time|clogged) (\S+)\s*$")
_THERMO = re.compile(r"^\s*(\d+)\s+([-+0-9.eE]+)\s+(\d+)(\s+[-+0-9.eEnaif]+)*\s*$")
#: an insertion fix's report of one batch (fix id, templates: a clump or a sphere each)
_INSERT_BATCH = re.compile(r"^INFO: Particle insertion (\S+): inserted (\d+) particle templates")
#: read_dump's count of the atoms a placed batch added (siloflow.fill_placement)
_READ_BATCH = re.compile(r"^\s*(\d+) atoms added\s*$")
#: the fix-like name under which the placed batches are counted
PLACED = "read_dump"
#: the warning after a batch placed short (it names no fix: the batch reported just before)
_SHORT_BATCH = re.compile(r"Particle insertion: Less insertions than requested")
#: warnings a siloflow deck causes knowingly: wall/gran/local skips the primitive side walls, whose
#: touching grains the deck dumps itself (siloflow.engine.liggghts.side_walls)
_EXPECTED_WARNING = re.compile(r"Compute wall/gran/local detected primitive wall")
_ERROR = re.compile(r"^(ERROR( on proc \d+)?:.*)$")
_WARNING = re.compile(r"^(WARNING:.*)$")
#: check/timestep/gran's verdict that the time step is too large: a failure, not a warning
_TIMESTEP = re.compile(r"time-step is .* of (rayleigh|hertz) time", re.I)

STAGE_ORDER = ("fill", "settle", "shrink", "mobilise", "resettle", "static", "open", "discharge")
#: thermo columns of a deck with the guard (step ... outlet_count, speed, overlap, escaped)
THERMO_GUARD_COLUMNS = 11


@dataclass
class LogState:
    """What has been read so far from a LIGGGHTS output stream.

    ``planned`` holds the upper bound of steps of each announced stage; ``stage_steps``
    the step at which each stage began.
    """

    planned: dict[str, int] = field(default_factory=dict)
    stage_steps: dict[str, int] = field(default_factory=dict)
    stage: Optional[str] = None
    step: int = 0
    atoms: Optional[int] = None
    inserted: Optional[int] = None              # atoms (spheres) in the box after the fill
    templates: dict[str, int] = field(default_factory=dict)   # per insertion fix: grains or dust spheres
    batches: dict[str, list] = field(default_factory=dict)    # per insertion fix: templates placed per batch
    short_batches: dict[str, list] = field(default_factory=dict)  # per insertion fix: what short batches placed
    last_batch_fix: str = ""                    # the insertion fix that reported the last batch
    settled_ke_pe: Optional[float] = None
    not_settled_ke_pe: Optional[float] = None
    done: bool = False
    discharge_stop: Optional[dict] = None       # until_steady: {"reason", "relative_error"}
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    fatal: bool = False             # the run must be stopped (an error the engine itself does not end on)
    guard: Optional[RunGuard] = None            # watches the thermo rows (siloflow.guard)
    count_lost: bool = False                    # spheres: atoms gone without passing the outlet are lost
    guard_trip: Optional[GuardTrip] = None

    def feed(self, line: str) -> bool:
        """Read one line; return True when the progress (step or stage) changed."""
        line = line.rstrip("\r\n")
        m = _THERMO.match(line)
        if m:
            self.step = int(m.group(1))
            self.atoms = int(m.group(3))
            if self.guard is not None and self.guard_trip is None:
                self._watch(line.split())
            return True
        m = _STAGE.match(line)
        if m:
            self.stage = m.group(1)
            self.planned[self.stage] = int(m.group(2))
            self.stage_steps[self.stage] = self.step
            return True
        m = _MARK.match(line)
        if m:
            kind, value = m.groups()
            if kind == "INSERTED":
                self.inserted = int(float(value))
            elif kind == "SETTLED":
                self.settled_ke_pe = float(value)
            elif kind == "NOT_SETTLED":
                self.not_settled_ke_pe = float(value)
            elif kind == "DONE":
                self.done = True
            return False
        m = _STOP.match(line)
        if m:
            try:
                error = float(m.group(2))
            except ValueError:
                error = None
            self.discharge_stop = {"reason": m.group(1), "relative_error": error}
            return False
        m = _INSERT_BATCH.match(line) or _READ_BATCH.match(line)
        if m:
            fix, n = (m.group(1), int(m.group(2))) if m.re is _INSERT_BATCH else (PLACED, int(m.group(1)))
            self.templates[fix] = self.templates.get(fix, 0) + n
            self.batches.setdefault(fix, []).append(n)
            self.last_batch_fix = fix
            return False
        m = _ERROR.match(line)
        if m:
            self.errors.append(m.group(1).strip())
            return False
        m = _WARNING.match(line)
        if m and _SHORT_BATCH.search(line):     # follows the INFO line of the batch it is about
            placed = self.batches.get(self.last_batch_fix, [0])[-1]
            self.short_batches.setdefault(self.last_batch_fix, []).append(placed)
        if m and _TIMESTEP.search(line) and not self.fatal:
            self.errors.append(m.group(1).strip())
            self.fatal = True
        elif m and m.group(1) not in self.warnings and len(self.warnings) < 50 and not _EXPECTED_WARNING.search(line):
            self.warnings.append(m.group(1).strip())
        return False

    def _watch(self, cols: list[str]) -> None:
        """Hand one thermo row (the deck's columns: step time atoms ke pe mass_silo outlet_mass
        outlet_count speed overlap escaped) to the guard; a trip makes the run fatal."""
        if len(cols) < THERMO_GUARD_COLUMNS:
            return
        try:
            v = [float(c) for c in cols[3:THERMO_GUARD_COLUMNS]]
        except ValueError:
            return
        ke, pe, _, _, out_count, speed, overlap, escaped = v
        lost = None
        if self.count_lost and self.inserted is not None and math.isfinite(out_count):
            lost = int(self.inserted - self.atoms - round(out_count))
        trip = self.guard.check(self.stage, self.step, ke, pe, speed=speed, overlap=overlap, escaped=escaped,
                                lost=lost, atoms=self.atoms or 0)
        if trip is not None:
            self.guard_trip = trip
            self.errors.append(f"siloflow guard ({trip.signal}): {trip.message}")
            self.fatal = True

    def guard_trip_record(self) -> Optional[dict]:
        """The guard's trip as the run record keeps it (None when it did not trip)."""
        t = self.guard_trip
        return None if t is None else {"signal": t.signal, "stage": t.stage, "step": t.step, "value": t.value,
                                       "limit": t.limit}

    def total_steps(self, planned_all: dict[str, int]) -> int:
        """Upper bound of the run's total steps, given every stage's planned steps.

        Stages already finished count as they ran; the current and later ones as planned.
        """
        if self.stage is None:
            return sum(planned_all.values())
        idx = STAGE_ORDER.index(self.stage) if self.stage in STAGE_ORDER else 0
        started = self.stage_steps.get(self.stage, self.step)
        total = started + sum(planned_all.get(s, 0) for s in STAGE_ORDER[idx:])
        return max(total, self.step)


def parse_log_text(text: str) -> LogState:
    state = LogState()
    for line in text.splitlines():
        state.feed(line)
    return state


def printable(text: str) -> str:
    """``text`` with printable characters only (and line breaks): escape sequences, control characters
    and undecodable bytes are dropped, tabs become spaces. Engine output passes through this before it
    reaches a message, a status or a log tail."""
    if "\ufffd" not in text and text.replace("\n", "").isprintable():
        return text                                   # the usual line: nothing to drop
    text = ANSI_ESCAPES.sub("", text).replace("\t", " ")
    return "".join(c for c in text if c == "\n" or (c.isprintable() and c != "\ufffd"))


def decode(raw: bytes) -> str:
    """Engine output as printable text (:func:`printable`): stray binary bytes after ERROR lines and
    escape sequences are dropped, not fatal."""
    return printable(raw.decode("utf-8", errors="replace"))


# ----------------------------------------------------------------- diagnosis
#: LIGGGHTS' default volume_limit of particletemplate/sphere and /multisphere, m3 (fix_template_sphere.cpp);
#: the deck lowers it for small spheres, so the refusal is left to clumps
VOLUME_LIMIT = LIGGGHTS_VOLUME_LIMIT
#: radius of a sphere of that volume, m (about 62 um)
VOLUME_LIMIT_RADIUS = (3 * VOLUME_LIMIT / (4 * 3.141592653589793)) ** (1 / 3)
_TEMPLATE_ID = re.compile(r"\(id (\S+)\): Volume expectancy too small")
_MESH_ID = re.compile(r"Mesh (\S+?):")


def _volume_diagnosis(text: str) -> tuple[str, str]:
    m = _TEMPLATE_ID.search(text)
    fix_id = m.group(1) if m else ""
    field = ("particles.dust.radius" if fix_id == "pts_dust" else
             "particles.radius (particles.radii, or a clump's size: particles.length and width)")
    what = "the dust spheres" if fix_id == "pts_dust" else "the grains"
    cause = (f"{what} are too small for LIGGGHTS: a particle template's volume is below LIGGGHTS' default "
             f"'volume_limit' of {VOLUME_LIMIT:g} m3 (a sphere of radius {VOLUME_LIMIT_RADIUS * 1e6:.0f} um), and "
             "LIGGGHTS refuses to insert it")
    fix = (f"raise {field} to at least {VOLUME_LIMIT_RADIUS:.2g} m (the case is in SI units: a radius "
           "given in mm must be written in m)")
    return cause, fix


def _mesh_fields(mesh: str) -> str:
    """The case fields that shape a wall mesh named by its deck id."""
    if mesh.startswith("insert_"):
        name = mesh[len("insert_"):]
        return f"the STL file of insert '{name}' (inserts[].file): re-mesh it with better-shaped triangles"
    if mesh.startswith(("face", "hopper", "cone")):
        return "geometry.half_angle_deg, geometry.outlet_width or geometry.outlet_radius"
    if mesh.startswith(("bottom", "plate", "outlet")):
        return "geometry.orifice_radius (or outlet_radius / outlet_width) or geometry.mesh_segments"
    if mesh.startswith(("band", "wall")):
        return "sensors.heights or sensors.bands, geometry.height"
    return "the geometry section"


def _mesh_diagnosis(text: str) -> tuple[str, str]:
    m = _MESH_ID.search(text)
    mesh = m.group(1) if m else ""
    where = f"the wall mesh meshes/{mesh}.stl" if mesh else "a wall mesh"
    cause = (f"LIGGGHTS refused {where} ('Bad mesh'): a triangle with an angle below its curvature limit "
             "(0.256 deg), or duplicate or degenerate triangles")
    fix = ("re-render the deck with this siloflow ('siloflow render'), which checks every wall and "
           "re-triangulates slivers (an older deck may hold them)")
    if mesh:
        fix += f"; if it persists, change {_mesh_fields(mesh)}"
    return cause, fix


_KNOWN = [
    (_TIMESTEP,
     "the time step is too large for the contacts this run sees (LIGGGHTS' check/timestep/gran: faster "
     "impacts or smaller grains than siloflow's estimate); the run was stopped",
     "lower engine.timestep_fraction (or, with dust, raise particles.dust.density_scale)"),
    (re.compile(r"Cannot open mesh file|Cannot open STL|Can not open file", re.I),
     "a mesh file named in the deck is missing or unreadable",
     "re-render the deck with 'siloflow render' and do not move files out of the run folder"),
    # before MPI_ABORT: on several ranks these errors end in an MPI abort too
    (re.compile(r"Volume expectancy too small", re.I), _volume_diagnosis, None),
    (re.compile(r"minimum angle of mesh element|minumum angle of mesh element|Bad mesh", re.I), _mesh_diagnosis, None),
    (re.compile(r"youngsModulus (<= 1e9|>= 5e6)", re.I),
     "a Young's modulus above 1e9 Pa without 'hard_particles yes', or below 5e6 Pa without 'soft_particles yes'",
     "this is a siloflow bug (it writes both flags for such cases): report it with the case file"),
    (re.compile(r"Lost atoms", re.I),
     "particles left the simulation box (through a wall): time step too large or walls too soft",
     "lower engine.timestep_fraction, or raise the wall stiffness"),
    (re.compile(r"Unknown (command|fix style|pair style|compute style)", re.I),
     "the LIGGGHTS build lacks a command the deck needs",
     "install Debian's liggghts 3.8 package (make install-engine)"),
    (re.compile(r"not enough slots|There are not enough slots", re.I),
     "more MPI ranks than cores",
     "lower engine.ranks to the number of cores"),
    (re.compile(r"MPI_ABORT was invoked", re.I),
     "LIGGGHTS aborted without an ERROR line (in 3.8 this happens when a mesh file is missing or "
     "unreadable)", "re-render the deck with 'siloflow render' and check the meshes/ folder"),
    (re.compile(r"Less insertions than requested", re.I),
     "the insertion region could not hold the requested particles",
     "enlarge the silo above the bed, or lower fill.batch_volume_fraction"),
]


def diagnose(errors: list[str], warnings: list[str], returncode: Optional[int],
             extra: tuple[str, ...] = (), folder=None,
             files: tuple[str, ...] = ("log.liggghts", "screen.txt")) -> tuple[str, str, str]:
    """(message, likely cause, fix) for a failed run, printable text only; ``extra``: other output
    lines to search (the last lines the engine printed). The fix names a file of the run ``folder``
    only if it exists there (of ``files``; none without a folder)."""
    errors = [printable(e) for e in errors]
    warnings = [printable(w) for w in warnings]
    extra = tuple(printable(x) for x in extra)
    text = "\n".join(errors + warnings + list(extra))
    if errors:
        message = f"LIGGGHTS stopped with an error: {errors[0]}"
    elif returncode is not None and returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        message = f"LIGGGHTS was killed by {name}"
        if name == "SIGSEGV":
            return (message, "the engine crashed (segmentation fault); in LIGGGHTS 3.8 this follows "
                    "unreadable meshes, '-screen none', or particles exploding out of walls",
                    "check the last log lines; lower engine.timestep_fraction; re-render the deck")
        return message, "the run was stopped from outside (signal)", "run it again"
    else:
        message = f"LIGGGHTS exited with code {returncode}"
    for pattern, cause, fix in _KNOWN:
        if pattern.search(text):
            if callable(cause):
                cause, fix = cause(text)
            return message, cause, fix
    existing = [name for name in files if folder is not None and (Path(folder) / name).is_file()]
    where = f"; the engine's full output is in {' and '.join(existing)} in the run folder" if existing else ""
    if not text.strip():
        return (message, "the engine printed nothing: the program siloflow ran may not be LIGGGHTS, or it "
                "failed before its first line",
                "check that --liggghts or SILOFLOW_LIGGGHTS names the LIGGGHTS 3.8 binary ('liggghts -h' prints "
                f"its help){where}")
    return message, "", f"read the engine's last lines below{where}"
