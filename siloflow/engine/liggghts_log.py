"""Reading LIGGGHTS screen/log output: stage markers, thermo rows, warnings and errors,
and turning a failure into a message with its likely cause and fix."""
from __future__ import annotations

import re
import signal
from dataclasses import dataclass, field
from typing import Optional

_STAGE = re.compile(r"^SILOFLOW_STAGE (\w+) (\d+)\s*$")
_MARK = re.compile(r"^SILOFLOW_(INSERTED|SETTLED|NOT_SETTLED|DONE)\s*(\S*)\s*$")
_THERMO = re.compile(r"^\s*(\d+)\s+([-+0-9.eE]+)\s+(\d+)(\s+[-+0-9.eEnaif]+)*\s*$")
#: an insertion fix's report of one batch (fix id, templates: a clump or a sphere each)
_INSERT_BATCH = re.compile(r"^INFO: Particle insertion (\S+): inserted (\d+) particle templates")
_ERROR = re.compile(r"^(ERROR( on proc \d+)?:.*)$")
_WARNING = re.compile(r"^(WARNING:.*)$")
#: check/timestep/gran's verdict that the time step is too large: a failure, not a warning
_TIMESTEP = re.compile(r"time-step is .* of (rayleigh|hertz) time", re.I)

STAGE_ORDER = ("fill", "settle", "shrink", "static", "open", "discharge")


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
    settled_ke_pe: Optional[float] = None
    not_settled_ke_pe: Optional[float] = None
    done: bool = False
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    fatal: bool = False             # the run must be stopped (an error the engine itself does not end on)

    def feed(self, line: str) -> bool:
        """Read one line; return True when the progress (step or stage) changed."""
        line = line.rstrip("\r\n")
        m = _THERMO.match(line)
        if m:
            self.step = int(m.group(1))
            self.atoms = int(m.group(3))
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
        m = _INSERT_BATCH.match(line)
        if m:
            self.templates[m.group(1)] = self.templates.get(m.group(1), 0) + int(m.group(2))
            return False
        m = _ERROR.match(line)
        if m:
            self.errors.append(m.group(1).strip())
            return False
        m = _WARNING.match(line)
        if m and _TIMESTEP.search(line) and not self.fatal:
            self.errors.append(m.group(1).strip())
            self.fatal = True
        elif m and m.group(1) not in self.warnings and len(self.warnings) < 50:
            self.warnings.append(m.group(1).strip())
        return False

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


def decode(raw: bytes) -> str:
    """Engine output as text: stray binary bytes after ERROR lines are replaced, not fatal."""
    return raw.decode("utf-8", errors="replace")


# ----------------------------------------------------------------- diagnosis
_KNOWN = [
    (_TIMESTEP,
     "the time step is too large for the contacts this run sees (LIGGGHTS' check/timestep/gran: faster "
     "impacts or smaller grains than siloflow's estimate); the run was stopped",
     "lower engine.timestep_fraction (or, with dust, raise particles.dust.density_scale)"),
    (re.compile(r"Cannot open mesh file|Cannot open STL|Can not open file", re.I),
     "a mesh file named in the deck is missing or unreadable",
     "re-render the deck with 'siloflow render' and do not move files out of the run folder"),
    (re.compile(r"youngsModulus <= 1e9", re.I),
     "a Young's modulus above 1e9 Pa without 'hard_particles yes'",
     "this is a siloflow bug (it writes hard_particles for such cases): report it with the case file"),
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
             extra: tuple[str, ...] = ()) -> tuple[str, str, str]:
    """(message, likely cause, fix) for a failed run; ``extra``: other output lines to search."""
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
            return message, cause, fix
    return message, "", "read the log lines below; the full log is log.liggghts in the run folder"
