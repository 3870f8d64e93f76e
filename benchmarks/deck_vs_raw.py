"""siloflow's full-output deck against a raw deck of the same grains, silo and walls (issue 56, item 4).

What is measured. For each case (decks/demo.yaml, decks/quick.yaml, benchmarks/cases/raw_large.yaml: 6.8e3,
5e3 and 3e4 grains) and engine (LIGGGHTS 3.8; LAMMPS with the case's engine section switched to
``lammps`` and the LIGGGHTS-only ``side_walls`` removed), on 2 MPI ranks, one engine job at a time:

1. siloflow's deck, every output (what a user gets): ``siloflow.run`` of the case into
   ``benchmarks/work/raw/<case>_<engine>[_primitive]/`` through the fill cache ``benchmarks/work/raw/cache``.
   On LIGGGHTS twice: the side walls as primitives (``engine.side_walls: primitive``, the default since
   8 Dec 2026, deck ``siloflow_primitive``) and as sensor meshes (``meshes``, the old default,
   ``siloflow_meshes``; ``--decks`` leaves it out).
   Primitive side walls are in the fill's key (``LiggghtsEngine.fill_key_parts``), so the two LIGGGHTS
   decks settle their own beds: only the stages after the settled bed are timed and compared. On LAMMPS
   one deck (``siloflow``). A bed already in the cache (an earlier call, ``--smoke``) is reused: the run
   then starts from it (``Engine.start_from_fill``, siloflow's resume path), and its resume log is read.
2. The measure, over the stages after the settled bed (static, opening, discharge): particle-steps per
   second of the engine's own "Loop time of T on P procs for N steps with A atoms" lines of those stages
   (``loop_rate``), and over siloflow's wall time of those stages (``wall_rate``: from siloflow's progress
   report of the static stage to the engine's exit, which on LAMMPS holds the driver's work between
   chunks: counting and deleting at the outlet, wall sensors, guard; ``outside_loop_s`` = wall - loop).
   Particle-steps are the atoms integrated over the steps of each run from its thermo rows (the
   discharge deletes grains as it goes; a run without two rows counts N x A). The runs of those stages
   are told apart by the decks' ``SILOFLOW_STAGE <name>`` prints (LIGGGHTS' log, and the raw decks of both
   engines) or, in LAMMPS' log, where siloflow's driver prints none, by each run's first step against the
   stages' first steps in the run record (``stage_steps``, the driver's). The loop split of those stages:
   ``pair_s neigh_s comm_s output_s modify_s other_s`` (``bench_runs.loop_split``; LIGGGHTS 3.8 has no
   Modify, its fixes are in Other, hence ``modify_other_s``). siloflow's LAMMPS driver runs its chunks with
   ``post no``, which leaves the split out of the log: the bench's hook (``benchmarks/deck_vs_raw_hook``,
   on the ranks' PYTHONPATH) sends them as ``post yes``, nothing else changed.
3. The raw deck (``raw``), written by the bench from the siloflow run folder into its own folder
   ``benchmarks/work/raw/<case>_<engine>_raw/`` and run right after siloflow's deck, on the same ranks,
   timed the same way (from its ``SILOFLOW_STAGE static`` print on its screen to its exit): the same
   settled bed (a copy of the run's restart file), species, contact law and parameters, time step and
   neighbour settings, the same walls as engine primitives or regions, or the same meshes where the
   engine has no primitive (LIGGGHTS: the ``zcylinder`` side of the primitive deck, whose run folder it
   starts from, and the floor, plate and counting-disc meshes; LAMMPS: siloflow's regions), the same
   opening and the same numbers of static, opening and discharge steps as siloflow's run; no sensors, no
   wall-force sampling, no dumps, no guard, no time-step check, thermo every 1000 steps. Discharged
   grains are deleted as each engine does it plainly: LIGGGHTS keeps the deck's ``massflow/mesh ...
   delete_atoms yes`` on the counting disc (the grain count then follows siloflow's); LAMMPS ``fix
   evaporate`` of the region below the counting plane every ``count_every`` steps (the driver's longest
   chunk) from the opening on, which deletes what siloflow's driver deletes, as often (evaporate forces a
   neighbour-list build each time it looks; in the discharge the flowing bed rebuilds about as often).
   On the quick case LAMMPS also runs the raw deck with the classic ``gran/hertz/history`` (``raw_classic``:
   ``engine_throughput.classic_pair``'s coefficients; not the case's damping, a throughput row only) for
   the goal's "LAMMPS' classic style"; its contacts start afresh from the restart (another history fix).
4. Rows (``benchmarks/results/deck_vs_raw/runs.csv``), each appended when it is done: case, engine, deck,
   ranks, atoms at start and end, steps (per stage too), particle-steps, loop and wall seconds and rates,
   the loop split, ``fraction_of_raw`` (loop rate / the raw deck's of the same case and engine) and
   ``wall_fraction_of_raw``, the engine version, the date, the call (rows of one call share it) and
   ``other_cpu``, the cores' worth of CPU that processes other than this one and its engines used while the
   row ran (/proc/stat's busy time less this process's and its waited children's CPU time: about 0 on a
   quiet machine; 0.1 or more means something else ran and the row is not a clean sample).
   Resumable: a row already there is not run again; a raw deck whose siloflow run folder is gone runs
   that case again (from the cached bed) without adding a row. ``--table`` prints the fractions and the
   LAMMPS/LIGGGHTS rate ratios of the quick case, and writes ``fractions.csv``, ``engine_ratio.csv`` and
   ``fractions.png`` (each deck's fraction of raw, the goal 0.85 drawn).

Run it alone on a quiet machine (nothing else may run while it times: the fractions and the engine ratio
are ratios within one call, and each run is one sample)::

    make bench-raw                                  # = .venv/bin/python benchmarks/deck_vs_raw.py
    .venv/bin/python benchmarks/deck_vs_raw.py --cases quick --engines lammps
    .venv/bin/python benchmarks/deck_vs_raw.py --smoke      # every deck for about 600 steps after the bed
    .venv/bin/python benchmarks/deck_vs_raw.py --table
    .venv/bin/python benchmarks/deck_vs_raw.py --check      # no engine: the raw decks from siloflow's renderer

For ratios from one machine state, delete runs.csv first. ``--smoke`` is for checking the script (rows in
benchmarks/work/raw_smoke/, not a result): the static window two sample intervals (360-420 steps), the plate
at 20 m/s (30-50 steps), one sample interval of discharge (180-210 steps), none of which is in the fill's
key, so it shares the fill cache and the beds it settles are the ones the measuring call then starts from.
``--no-lammps-split`` runs siloflow's LAMMPS chunks untouched (no split; the wall time without LAMMPS'
per-chunk summary). How long (an estimate from make bench-engines' and make demo's rates, not
measured): on 2 quiet cores, about 7 min for the demo, 6 min for the quick case and 15-20 min for raw_large
(each full run of the LIGGGHTS sensor-mesh deck 2.5, 2 and 6-10 min of it), 30-45 min in all; a second call
with every bed cached about half of that; ``--smoke`` about the fills' share, 15-25 min the first time.
"""
from __future__ import annotations

import argparse
import copy
import datetime
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import deque
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_runs import LOOP, SECTIONS, loop_split  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "deck_vs_raw"
WORK = ROOT / "benchmarks" / "work" / "raw"
SMOKE_WORK = ROOT / "benchmarks" / "work" / "raw_smoke"
CACHE = WORK / "cache"
HOOK = ROOT / "benchmarks" / "deck_vs_raw_hook"
#: the thermo commands a raw deck writes in place of siloflow's (both engines)
THERMO_COMMANDS = ("thermo_style", "thermo", "thermo_modify")


def raw_thermo_line(command: str, thermo: int) -> str:
    """A raw deck's ``thermo_style``, ``thermo`` (every ``thermo`` steps) or ``thermo_modify`` line."""
    return {"thermo_style": "thermo_style    custom step atoms", "thermo": f"thermo          {int(thermo)}",
            "thermo_modify": "thermo_modify   lost ignore norm no"}[command]
CASES = {"demo": ROOT / "decks" / "demo.yaml", "quick": ROOT / "decks" / "quick.yaml",
         "raw_large": ROOT / "benchmarks" / "cases" / "raw_large.yaml"}
ENGINES = ("liggghts", "lammps")
RANKS = 2
#: the goals: siloflow's deck at 0.85 of the raw deck's rate; LAMMPS' classic style 1.5x LIGGGHTS' (quick case)
GOAL, ENGINE_GOAL = 0.85, 1.5
#: the raw decks' thermo interval, steps
RAW_THERMO = 1000
#: the cases whose LAMMPS raw deck also runs on the classic gran/hertz/history (one species, Hertz)
CLASSIC_CASES = ("quick",)
#: siloflow's decks on each engine: deck -> the case's engine.side_walls (LAMMPS: none)
SILOFLOW_DECKS = {"liggghts": {"siloflow_meshes": "meshes", "siloflow_primitive": "primitive"},
                  "lammps": {"siloflow": None}}
#: every deck name the bench knows
ALL_DECKS = tuple(dict.fromkeys([d for e in SILOFLOW_DECKS.values() for d in e] + ["raw", "raw_classic"]))
#: the siloflow deck each raw deck starts from (its run folder's settled bed and step counts)
RAW_SOURCE = {"liggghts": "siloflow_primitive", "lammps": "siloflow"}
#: the stages after the settled bed, in order
AFTER_BED = ("static", "open", "discharge")
#: every stage a run record may name, in order (ties of first step go to the later one)
STAGE_ORDER = ("fill", "settle", "shrink", "mobilise", "resettle") + AFTER_BED
RAW_RESTART = "settled.restart"
RAW_DECK = {"liggghts": "in.raw.liggghts", "lammps": "in.raw.lammps"}
RAW_LOG = {"liggghts": "log.raw.liggghts", "lammps": "log.raw.lammps"}
RAW_SCREEN = "screen.raw.txt"
#: smoke: the static window (in sample intervals), the discharge (in sample intervals) and the plate speed
SMOKE_STATIC, SMOKE_DISCHARGE, SMOKE_PLATE_SPEED = 2, 1, 20.0
#: s the bench looks at the machine before it starts, and the other processes' cores it warns above
QUIET_PROBE, QUIET_LIMIT = 3.0, 0.1
#: the hook's switch (benchmarks/deck_vs_raw_hook/sitecustomize.py)
HOOK_SWITCH = ("SILOFLOW_BENCH_RUN_POST", "yes")
SPLIT = tuple(f"{s.lower()}_s" for s in SECTIONS)
_STAGE = re.compile(r"SILOFLOW_STAGE (\w+)")
_INT = re.compile(r"-?\d+")
_REF = re.compile(r"\b([cvf])_([A-Za-z0-9_]+)")

#: when each engine launch began and ended in this process (Engine.launch, timed: _time_launches)
_LAUNCH: dict = {}
_VERSIONS: dict = {}


# ---------------------------------------------------------------------------------------------- cases
def case_name(case: str, engine: str, deck: str) -> str:
    """The run folder's (and case's) name: ``<case>_<engine>[_primitive]``, the raw decks' with their deck."""
    if deck.startswith("siloflow"):
        return f"{case}_{engine}" + ("_primitive" if deck == "siloflow_primitive" else "")
    return f"{case}_{engine}_{deck}"


def case_data(case: str, engine: str, deck: str, smoke: bool = False) -> dict:
    """The case's fields for siloflow's ``deck`` on ``engine`` at 2 ranks: the engine section switched
    (LIGGGHTS-only ``side_walls`` and ``particles.monte_carlo_tries`` removed on LAMMPS), the side walls
    the deck's; ``smoke``: the static window two sample intervals, the discharge one, the plate fast
    (none of which is in the fill's key: the beds are the measuring call's)."""
    data = copy.deepcopy(yaml.safe_load(CASES[case].read_text()))
    data["name"] = case_name(case, engine, deck)
    eng = {k: v for k, v in data.get("engine", {}).items() if k != "side_walls"}
    eng.update(name=engine, ranks=RANKS)
    walls = SILOFLOW_DECKS[engine][deck]
    if walls is not None:
        eng["side_walls"] = walls
    data["engine"] = eng
    if engine != "liggghts":
        data.get("particles", {}).pop("monte_carlo_tries", None)
    if smoke:
        si = float(data.get("outputs", {}).get("sample_interval", 0.005))
        data["fill"].setdefault("settle", {})["static_window"] = SMOKE_STATIC * si
        opening = data.get("discharge", {}).get("opening", {})
        data["discharge"] = {"duration": SMOKE_DISCHARGE * si, "opening": {**opening, "speed": SMOKE_PLATE_SPEED}}
    return data


# ---------------------------------------------------------------------------------------------- logs
def parse_runs(text: str, stage_steps: dict | None = None) -> list[dict]:
    """Each ``run`` of an engine log: its stage (the last ``SILOFLOW_STAGE`` print before it; with
    ``stage_steps``, the run record's stage first steps, the stage whose first step is the latest not after
    the run's first step), first step, steps, atoms at the end, loop seconds, thermo rows (step, atoms) and
    loop split (``bench_runs.loop_split`` of the lines from its "Loop time" to the next)."""
    lines = text.splitlines()
    runs, cols, rows, stage = [], None, [], None
    for i, line in enumerate(lines):
        m = _STAGE.search(line)
        if m:
            stage = m.group(1)
            continue
        words = line.split()
        if words[:1] == ["Step"]:
            cols, rows = words, []
            continue
        m = LOOP.match(line)
        if m:
            runs.append({"stage": stage, "loop_s": float(m.group(1)), "procs": int(m.group(2)),
                         "steps": int(m.group(3)), "atoms": int(m.group(4)), "rows": rows, "line": i})
            cols, rows = None, []
            continue
        if cols and "Atoms" in cols and len(words) == len(cols) and _INT.fullmatch(words[0]):
            try:
                rows.append((int(words[0]), int(float(words[cols.index("Atoms")]))))
            except ValueError:
                pass
    for k, run in enumerate(runs):
        end = runs[k + 1]["line"] if k + 1 < len(runs) else len(lines)
        run.update(loop_split("\n".join(lines[run["line"]:end])))
        run["start"] = run["rows"][0][0] if run["rows"] else None
    if stage_steps:
        order = sorted(((int(s), STAGE_ORDER.index(n) if n in STAGE_ORDER else -1, n) for n, s in stage_steps.items()
                        if isinstance(s, int)))
        for run in runs:
            if run["start"] is not None:
                run["stage"] = next((n for s, _, n in reversed(order) if s <= run["start"]), None)
    return runs


def particle_steps(run: dict) -> float:
    """The atoms integrated over the run's steps (trapezoids between its thermo rows), or N x A when its
    rows do not span it."""
    rows = run["rows"]
    if len(rows) >= 2 and rows[-1][0] - rows[0][0] == run["steps"]:
        return float(sum((s1 - s0) * (a0 + a1) / 2 for (s0, a0), (s1, a1) in zip(rows, rows[1:])))
    return float(run["steps"] * run["atoms"])


def measure(text: str, stage_steps: dict | None = None) -> dict:
    """What the runs of the stages after the settled bed (:data:`AFTER_BED`) of a log did: steps (and per
    stage), first step, atoms at start and end, particle-steps, loop seconds, the loop split, runs."""
    runs = [r for r in parse_runs(text, stage_steps) if r["stage"] in AFTER_BED]
    if not runs:
        raise SystemExit("no run of the static, opening or discharge stage in the log (no SILOFLOW_STAGE print "
                         "and no stage steps): did the run get past its settled bed?")
    first = runs[0]
    out = {"first_step": first["start"], "atoms_start": first["rows"][0][1] if first["rows"] else first["atoms"],
           "atoms_end": runs[-1]["atoms"], "steps": sum(r["steps"] for r in runs), "runs": len(runs),
           "particle_steps": sum(particle_steps(r) for r in runs), "loop_s": sum(r["loop_s"] for r in runs)}
    for stage in AFTER_BED:
        out[f"{stage}_steps"] = sum(r["steps"] for r in runs if r["stage"] == stage)
    for key in SPLIT:
        out[key] = sum(r[key] for r in runs)
    if not any(out[key] for key in SPLIT):        # LAMMPS' "post no" runs print no split
        out.update({key: math.nan for key in SPLIT})
    out["modify_other_s"] = out["modify_s"] + out["other_s"]
    return out


def run_log(folder: Path, engine: str) -> tuple[Path, object]:
    """The log of a siloflow run folder's stages after the settled bed (the resume log of a run started from
    the fill cache), and its run record."""
    from siloflow.engines import ENGINE_FILES
    from siloflow.run_folder import RunFolder
    record = RunFolder(folder).record
    names = ENGINE_FILES[engine].names
    hit = bool((record.fill_cache or {}).get("hit"))
    return Path(folder) / names["resume_log" if hit else "log"], record


def measure_folder(folder: Path, engine: str) -> dict:
    """:func:`measure` of a finished siloflow run folder's log (LAMMPS: by the record's stage steps)."""
    log, record = run_log(folder, engine)
    text = log.read_text(errors="replace")
    out = measure(text, record.stage_steps if engine == "lammps" else None)
    out["from_fill_cache"] = bool((record.fill_cache or {}).get("hit"))
    return out


# ---------------------------------------------------------------------------------------------- raw decks
def _references_defined(lines: list[str]) -> list[str]:
    """The ``c_``, ``v_`` and ``f_`` references of ``lines`` to no compute, variable or fix they define
    (empty: the deck is whole)."""
    defined = {"c": set(), "v": set(), "f": set()}
    for line in lines:
        w = line.split()
        if len(w) > 1 and w[0] in ("compute", "variable", "fix"):
            defined[w[0][0]].add(w[1])
    missing = []
    for line in lines:
        for kind, name in _REF.findall(line):
            base = name.split("[")[0]
            if base not in defined[kind] and not (kind == "f" and base.startswith("force_")
                                                   and base[len("force_"):] in defined["f"]):
                missing.append(f"{kind}_{name} in {line.strip()[:80]}")
    return missing


def check_whole(lines: list[str], what: str) -> None:
    missing = _references_defined(lines)
    if missing:
        raise SystemExit(f"{what}: refers to what it does not define: " + "; ".join(missing[:5]))


#: what of siloflow's LIGGGHTS resume deck a raw deck leaves out, by command: the binned wall pieces' regions
#: and computes, the monitored quantities and the guard (computes, variables), the dumps, the discharge loop
LIGGGHTS_DROPPED = ("region", "compute", "variable", "dump", "dump_modify", "label", "next", "jump", "if", "print",
                    "run", "unfix", "write_restart")
#: ... and by fix ID: the wall-force and flow samples, the time-step check (the opening is written anew)
LIGGGHTS_DROPPED_FIXES = ("wall_forces", "flow", "timestep_check", "open_plate")


def liggghts_raw_deck(resume_text: str, steps: dict, thermo: int = RAW_THERMO) -> tuple[str, list[str]]:
    """The raw LIGGGHTS deck from siloflow's resume deck (``render_deck_text(plan, resume=True)``: the
    settled bed's restart, then the stages from static): its set-up (restart, neighbours, materials, pair
    style, time step, gravity, the floor, plate and counting-disc meshes and their ``wall/gran``, the
    primitive side walls, ``nve/sphere``, the counting disc's ``massflow/mesh ... delete_atoms yes``) with
    the meshes' ``/stress`` and the primitives' ``store_force`` left out and thermo ``step atoms`` every
    ``thermo`` steps, then ``steps``' static, opening (the deck's own plate motion) and discharge steps,
    each one ``run`` after its ``SILOFLOW_STAGE`` print. Returns (text, the mesh files it reads)."""
    lines = resume_text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("print") and "SILOFLOW_STAGE static" in line)
    opening = [line for line in lines if line.split()[:2] == ["fix", "open_plate"]]
    if len(opening) != 1:
        raise SystemExit("siloflow's LIGGGHTS resume deck has no single 'fix open_plate' line to open the orifice with")
    head, meshes = [], []
    for line in lines[:start]:
        w = line.split()
        if not w or w[0].startswith("#") or w[0] in LIGGGHTS_DROPPED:
            continue
        if w[0] == "fix" and w[1] in LIGGGHTS_DROPPED_FIXES:
            continue
        if w[0] == "read_restart":
            line = f"read_restart    {RAW_RESTART}"
        elif w[0] == "fix" and len(w) > 3 and w[3] == "mesh/surface/stress":
            line = re.sub(r" mesh/surface/stress ", " mesh/surface ", line, count=1)
        elif w[0] == "fix" and "wall/gran" in w:
            line = line.replace(" store_force yes", "")
        elif w[0] in THERMO_COMMANDS:
            line = raw_thermo_line(w[0], thermo)
        if "file" in w and w.index("file") + 1 < len(w):
            meshes.append(w[w.index("file") + 1])
        head.append(line)
    s, o, d = (int(steps[f"{k}_steps"]) for k in AFTER_BED)
    tail = [f'print           "SILOFLOW_STAGE static {s}"', f"run             {s}",
            f'print           "SILOFLOW_STAGE open {o}"', opening[0], f"run             {o}",
            "unfix           open_plate",
            f'print           "SILOFLOW_STAGE discharge {d}"', f"run             {d}",
            'print           "SILOFLOW_DONE"']
    body = head + tail
    check_whole(body, "the raw LIGGGHTS deck")
    header = ["# raw LIGGGHTS deck (benchmarks/deck_vs_raw.py): siloflow's resume deck without sensors, wall-force",
              "# sampling, dumps, guard or time-step check; the same bed, walls, opening and steps", ""]
    return "\n".join(header + body) + "\n", meshes


def classic_pair_lines(plan) -> list[str]:
    """``pair_style gran/hertz/history`` and its ``pair_coeff`` for the plan (one species, Hertz), as
    make bench-engines writes them (``engine_throughput.classic_pair``: Kn = 4/3 Y*, Kt = 8 G*, the damping
    giving the restitution at a resting grain's overlap; not the case's damping, a throughput variant)."""
    import engine_throughput
    with tempfile.TemporaryDirectory(prefix="deck-vs-raw-") as scratch:
        deck = Path(scratch) / "in.lammps"
        deck.write_text("pair_style      granular\npair_coeff      1 1 -\n")
        engine_throughput.classic_pair(Path(scratch), plan)
        return [line for line in deck.read_text().splitlines() if line.strip()]


def lammps_raw_deck(deck_text: str, plan, steps: dict, first_step: int, classic: list[str] | None = None,
                    thermo: int = RAW_THERMO) -> str:
    """The raw LAMMPS deck from siloflow's ``in.lammps`` (its named sections, as the driver runs them on a
    resume: resume_box, model, (mobilised,) regroup, restore_friction): the same restart, neighbours, pair
    style and coefficients, time step, gravity, regions and wall fixes (without their per-atom ``contacts``),
    ``nve/sphere``; no dump, no lowest-atom compute, thermo ``step atoms`` every ``thermo`` steps; then
    ``steps``' static steps; from the opening on, the grains below the counting plane deleted by ``fix
    evaporate`` every ``count_every(plan)`` steps (the driver's longest chunk; it forces a neighbour-list
    build each time it looks, so not in the static stage, where nothing passes the plane and siloflow's
    driver rebuilds nothing); the opening (the open section after ``open_time``, the time of its first
    step, ``first_step`` + static steps) and its steps, the opened section and the discharge steps, each
    stage's ``run`` after its ``SILOFLOW_STAGE`` print. ``classic``: the pair lines
    (:func:`classic_pair_lines`) that replace ``pair_style granular`` and its coefficients."""
    from siloflow.engine.lammps.deck import LOWEST_Z, count_every, sections
    from siloflow.run_folder import RESTART_FILE
    sec = sections(deck_text)
    missing = [name for name in ("resume_box", "model", "regroup", "restore_friction", "open", "opened")
               if name not in sec]
    if missing:
        raise SystemExit(f"siloflow's LAMMPS deck has no section {', '.join(missing)}")
    body = [line.replace(RESTART_FILE, RAW_RESTART) for line in sec["resume_box"]]
    swapped = False
    for line in sec["model"]:
        w = line.split()
        if w[0] in ("dump", "dump_modify") or (w[0] == "compute" and w[1] == LOWEST_Z):
            continue
        if classic is not None and w[0] in ("pair_style", "pair_coeff"):
            if not swapped:
                body += classic
                swapped = True
            continue
        if w[0] == "fix" and "wall/gran/region" in w and w[-1] == "contacts":
            line = line[:line.rstrip().rfind(" contacts")].rstrip()
        elif w[0] in THERMO_COMMANDS:
            line = raw_thermo_line(w[0], thermo)
        body.append(line)
    if plan.fill.mobilise is not None:
        body += sec.get("mobilised", [])          # the bed lies on the lowered floor
    body += sec["regroup"]
    if classic is None:
        body += sec["restore_friction"]
    # fix evaporate re-neighbours every time it looks: from the opening on (nothing passes the plane before)
    evaporate = (f"fix             raw_outlet all evaporate {count_every(plan)} 1000000000 below_outlet "
                 f"{4242 + plan.seed % 100000}")
    s, o, d = (int(steps[f"{k}_steps"]) for k in AFTER_BED)
    open_time = (int(first_step) + s) * plan.dt
    body += [f'print           "SILOFLOW_STAGE static {s}"', f"run             {s}", evaporate,
             f'print           "SILOFLOW_STAGE open {o}"', f"variable        open_time string {open_time!r}",
             *sec["open"], f"run             {o}", *sec["opened"],
             f'print           "SILOFLOW_STAGE discharge {d}"', f"run             {d}",
             'print           "SILOFLOW_DONE"']
    check_whole(body, "the raw LAMMPS deck")
    header = ["# raw LAMMPS deck (benchmarks/deck_vs_raw.py): siloflow's sections without sensors, per-atom wall",
              "# contacts, dumps or the driver; the same bed, regions, opening and steps; fix evaporate at the outlet",
              ""]
    return "\n".join(header + body) + "\n"


# ---------------------------------------------------------------------------------------------- running
def _time_launches() -> None:
    """Time each engine launch of ``siloflow.run`` in this process (``_LAUNCH``: start and end)."""
    from siloflow.engine.lammps.engine import LammpsEngine
    from siloflow.engine.liggghts.engine import LiggghtsEngine
    for cls in (LiggghtsEngine, LammpsEngine):
        if getattr(cls.launch, "_timed", False):
            continue
        original = cls.launch

        def launch(self, *args, _original=original, **kwargs):
            _LAUNCH["start"] = time.perf_counter()
            try:
                return _original(self, *args, **kwargs)
            finally:
                _LAUNCH["end"] = time.perf_counter()
        launch._timed = True
        cls.launch = launch


def cpu_now() -> tuple[float, float, float]:
    """(the machine's busy CPU seconds, this process's and its waited children's CPU seconds, now)."""
    with open("/proc/stat") as fh:
        user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fh.readline().split()[1:9])
    t = os.times()
    return ((user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK"),
            t.user + t.system + t.children_user + t.children_system, time.perf_counter())


def other_cpu(before: tuple) -> float:
    """Cores' worth of CPU used by other processes since ``before`` (:func:`cpu_now`)."""
    after = cpu_now()
    return max(0.0, (after[0] - before[0]) - (after[1] - before[1])) / max(1e-9, after[2] - before[2])


def version(engine: str) -> str:
    if engine not in _VERSIONS:
        from siloflow.engine import get_engine
        _VERSIONS[engine] = get_engine(engine).version()
    return _VERSIONS[engine]


class _Hook:
    """The LAMMPS ranks' hook (``benchmarks/deck_vs_raw_hook``) on their PYTHONPATH, switched on, for the
    ``with`` block."""

    def __init__(self, on: bool):
        self.on, self.saved = on, {}

    def __enter__(self):
        if self.on:
            for key in ("PYTHONPATH", HOOK_SWITCH[0]):
                self.saved[key] = os.environ.get(key)
            old = os.environ.get("PYTHONPATH")
            os.environ["PYTHONPATH"] = str(HOOK) + (os.pathsep + old if old else "")
            os.environ[HOOK_SWITCH[0]] = HOOK_SWITCH[1]
        return self

    def __exit__(self, *exc):
        for key, value in self.saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def row_of(case: str, engine: str, deck: str, m: dict, wall: float, others: float, folder: Path, call: str) -> dict:
    return {"case": case, "engine": engine, "deck": deck, "ranks": RANKS, "atoms_start": m["atoms_start"],
            "atoms_end": m["atoms_end"], "steps": m["steps"], **{f"{k}_steps": m[f"{k}_steps"] for k in AFTER_BED},
            "first_step": m["first_step"], "runs": m["runs"], "particle_steps": m["particle_steps"],
            "loop_s": m["loop_s"], "wall_s": wall, "outside_loop_s": wall - m["loop_s"],
            "loop_rate": m["particle_steps"] / m["loop_s"], "wall_rate": m["particle_steps"] / wall,
            **{k: m[k] for k in SPLIT}, "modify_other_s": m["modify_other_s"],
            "fraction_of_raw": math.nan, "wall_fraction_of_raw": math.nan,
            "from_fill_cache": m.get("from_fill_cache", False), "other_cpu": others, "version": version(engine),
            "date": datetime.datetime.now().isoformat(timespec="seconds"), "call": call,
            "folder": str(folder.relative_to(ROOT)) if folder.is_relative_to(ROOT) else str(folder)}


def run_siloflow(case: str, engine: str, deck: str, work: Path, cache: Path, smoke: bool, call: str,
                 split: bool = True) -> dict:
    """siloflow's ``deck`` of the case on ``engine``, every output, through the fill cache; its row
    (``split``: LAMMPS' chunks with ``post yes``, through the hook, for their loop split)."""
    from siloflow.errors import SiloflowError
    from siloflow.runs import run
    data = case_data(case, engine, deck, smoke)
    folder = work / data["name"]
    marks: dict = {}

    def progress(stage: str, step: int, total: int) -> None:
        if stage in AFTER_BED and "static" not in marks:
            marks["static"] = time.perf_counter()
    _time_launches()
    _LAUNCH.clear()
    before = cpu_now()
    print(f"{data['name']}: siloflow's deck ({deck}), 2 ranks ...", flush=True)
    try:
        with _Hook(split and engine == "lammps"):
            run(data, folder, force=True, progress=progress, cache=cache, post=False)
        others = other_cpu(before)
    except SiloflowError as exc:
        raise SystemExit(f"{data['name']} failed: {exc}") from None
    if "static" not in marks or "end" not in _LAUNCH:
        raise SystemExit(f"{folder}: siloflow reported no static stage: the run did not get past its settled bed")
    m = measure_folder(folder, engine)
    if split and engine == "lammps" and math.isnan(m["pair_s"]):
        print(f"  warning: {folder}: LAMMPS printed no loop split (the hook {HOOK} did not reach the ranks?)")
    return row_of(case, engine, deck, m, _LAUNCH["end"] - marks["static"], others, folder, call)


def run_streamed(command: list[str], folder: Path, env: dict | None = None) -> tuple[float, float]:
    """Run ``command`` in ``folder``, its output into ``screen.raw.txt``: (when its screen printed
    ``SILOFLOW_STAGE static``, when it ended), perf_counter seconds. A failure stops the benchmark."""
    tail: deque = deque(maxlen=20)
    mark = None
    with open(folder / RAW_SCREEN, "wb") as screen:
        proc = subprocess.Popen(command, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=env, start_new_session=True)
        try:
            for raw in proc.stdout:
                screen.write(raw)
                line = raw.decode(errors="replace")
                tail.append(line.rstrip())
                if mark is None and "SILOFLOW_STAGE static" in line:
                    mark = time.perf_counter()
            code = proc.wait()
        except BaseException:
            os.killpg(proc.pid, 15)
            raise
    end = time.perf_counter()
    if code != 0 or mark is None:
        raise SystemExit(f"{folder}: {' '.join(command)} ended with code {code}"
                         + ("" if mark is not None else " before its static stage") + ":\n  " + "\n  ".join(tail))
    return mark, end


def run_raw(case: str, engine: str, deck: str, source: Path, work: Path, call: str) -> dict:
    """The raw ``deck`` (``raw``, ``raw_classic``) from siloflow's run folder ``source``; its row."""
    from siloflow.engine import get_engine
    from siloflow.run_folder import RESTART_FILE, RunFolder
    folder = work / case_name(case, engine, deck)
    shutil.rmtree(folder, ignore_errors=True)          # the benchmark's own scratch
    folder.mkdir(parents=True)
    plan = RunFolder(source).plan
    steps = measure_folder(source, engine)
    shutil.copyfile(source / RESTART_FILE, folder / RAW_RESTART)
    if engine == "liggghts":
        from siloflow.engine.liggghts.deck import render_deck_text
        text, meshes = liggghts_raw_deck(render_deck_text(plan, resume=True), steps)
        for mesh in meshes:
            (folder / mesh).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source / mesh, folder / mesh)
        command, env = get_engine("liggghts").command(RANKS, RAW_DECK[engine], RAW_LOG[engine]), None
    else:
        from siloflow.engine.lammps.module import mpi_environment
        classic = classic_pair_lines(plan) if deck == "raw_classic" else None
        text = lammps_raw_deck((source / "in.lammps").read_text(), plan, steps, steps["first_step"], classic)
        here = Path(sys.executable).parent
        stdbuf = shutil.which("stdbuf")
        command = [str(here / "mpirun"), "-np", str(RANKS), *([stdbuf, "-oL"] if stdbuf else []), str(here / "lmp"),
                   "-in", RAW_DECK[engine], "-log", RAW_LOG[engine], "-nocite"]
        env = {**os.environ, **mpi_environment()}
    (folder / RAW_DECK[engine]).write_text(text)
    before = cpu_now()
    print(f"{folder.name}: raw deck from {source.name}, 2 ranks ...", flush=True)
    mark, end = run_streamed(command, folder, env)
    others = other_cpu(before)
    m = measure((folder / RAW_LOG[engine]).read_text(errors="replace"))
    for stage in AFTER_BED:
        if m[f"{stage}_steps"] != steps[f"{stage}_steps"]:
            raise SystemExit(f"{folder}: the raw deck ran {m[f'{stage}_steps']} {stage} steps, siloflow's "
                             f"{steps[f'{stage}_steps']}")
    return row_of(case, engine, deck, m, end - mark, others, folder, call)


def finished(folder: Path) -> bool:
    """A siloflow run folder that finished and kept its settled bed (a raw deck can start from it)."""
    from siloflow.run_folder import RESTART_FILE, RunFolder
    try:
        return RunFolder(folder).state.get("state") == "complete" and (folder / RESTART_FILE).is_file()
    except Exception:
        return False


def decks_of(case: str, engine: str) -> list[str]:
    return list(SILOFLOW_DECKS[engine]) + ["raw"] + (["raw_classic"] if engine == "lammps" and case in CLASSIC_CASES
                                                     else [])


# ---------------------------------------------------------------------------------------------- tables
def with_fractions(table):
    """``table`` with each row's loop and wall rate over its case's and engine's raw deck's."""
    import numpy as np
    table = table.copy()
    for (case, engine), group in table.groupby(["case", "engine"]):
        raw = group[group.deck == "raw"]
        loop, wall = (float(raw[c].iloc[-1]) if len(raw) else np.nan for c in ("loop_rate", "wall_rate"))
        table.loc[group.index, "fraction_of_raw"] = group.loop_rate / loop
        table.loc[group.index, "wall_fraction_of_raw"] = group.wall_rate / wall
    return table


def engine_ratios(table):
    """LAMMPS' rate over LIGGGHTS' on the quick case, each LAMMPS deck against each LIGGGHTS deck."""
    import pandas as pd
    quick = table[table.case == "quick"]
    rows = []
    for lmp in quick[quick.engine == "lammps"].itertuples():
        for lig in quick[quick.engine == "liggghts"].itertuples():
            rows.append({"lammps_deck": lmp.deck, "liggghts_deck": lig.deck,
                         "loop_ratio": lmp.loop_rate / lig.loop_rate, "wall_ratio": lmp.wall_rate / lig.wall_rate,
                         "same_call": lmp.call == lig.call})
    return pd.DataFrame(rows)


def figure(table, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    shown = table[table.deck != "raw"]
    cases = [c for c in CASES if c in set(shown.case)]
    decks = [(e, d) for e in ENGINES for d in (list(SILOFLOW_DECKS[e]) + ["raw_classic"])
             if ((shown.engine == e) & (shown.deck == d)).any()]
    fig, ax = plt.subplots(figsize=(2.2 + 2.0 * len(cases), 4.2))
    width = 0.8 / max(1, len(decks))
    for k, (engine, deck) in enumerate(decks):
        xs, ys, ws = [], [], []
        for i, case in enumerate(cases):
            row = shown[(shown.case == case) & (shown.engine == engine) & (shown.deck == deck)]
            if len(row):
                xs.append(i - 0.4 + (k + 0.5) * width)
                ys.append(float(row.fraction_of_raw.iloc[-1]))
                ws.append(float(row.wall_fraction_of_raw.iloc[-1]))
        ax.bar(xs, ys, width=width * 0.9, label=f"{engine} {deck}")
        ax.plot(xs, ws, "k.", ms=6)
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.axhline(GOAL, color="r", ls="--", lw=1, label=f"goal {GOAL}")
    ax.plot([], [], "k.", label="over the wall time")
    ax.set_xticks(range(len(cases)), cases)
    ax.set_ylabel("particle-steps/s, fraction of the raw deck's\n(bars: engine loop)")
    ax.set_title("siloflow's deck against the raw deck, 2 ranks, after the settled bed", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(csv: Path, out: Path) -> None:
    """Print the fractions and the engine ratios; write fractions.csv, engine_ratio.csv, fractions.png."""
    import pandas as pd
    if not csv.is_file():
        raise SystemExit(f"{csv}: no rows yet")
    table = with_fractions(pd.read_csv(csv))
    table.to_csv(csv, index=False)
    cols = ["case", "engine", "deck", "atoms_start", "steps", "loop_rate", "wall_rate", "fraction_of_raw",
            "wall_fraction_of_raw", "outside_loop_s", "pair_s", "neigh_s", "comm_s", "output_s", "modify_other_s",
            "other_cpu", "call"]
    fractions = table[cols].copy()
    fractions["meets_goal"] = [(f >= GOAL) if d.startswith("siloflow") and f == f else None
                               for d, f in zip(fractions.deck, fractions.fraction_of_raw)]
    # where the time goes: each loop section and the time outside the loop, s per 1e9 particle-steps
    per = ["pair_s", "neigh_s", "comm_s", "output_s", "modify_other_s", "loop_s", "outside_loop_s"]
    for col in per:
        fractions[col.replace("_s", "_s_per_gps")] = table[col] / table.particle_steps * 1e9
    out.mkdir(parents=True, exist_ok=True)
    fractions.to_csv(out / "fractions.csv", index=False)
    with pd.option_context("display.width", 220, "display.max_columns", 30, "display.precision", 3):
        print(fractions[cols[:9] + ["meets_goal", "other_cpu"]].to_string(index=False))
        print("\nseconds per 1e9 particle-steps (the loop split, and the wall time outside the loop):")
        per_gps = [c.replace("_s", "_s_per_gps") for c in per]
        print(fractions[["case", "engine", "deck"] + per_gps].to_string(index=False))
    ratios = engine_ratios(table)
    ratios.to_csv(out / "engine_ratio.csv", index=False)
    if len(ratios):
        print(f"\nquick case, LAMMPS' rate over LIGGGHTS' (goal: LAMMPS' classic style >= {ENGINE_GOAL}x, same call):")
        print(ratios.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
        goal_rows = ratios[(ratios.lammps_deck == "raw_classic") & ratios.liggghts_deck.str.startswith("siloflow")]
        for r in goal_rows.itertuples():
            print(f"  LAMMPS classic (raw_classic) / LIGGGHTS {r.liggghts_deck}: {r.loop_ratio:.2f}x in the loop, "
                  f"{r.wall_ratio:.2f}x over the wall time: goal {'met' if r.loop_ratio >= ENGINE_GOAL else 'NOT met'}"
                  + ("" if r.same_call else " (rows from different calls)"))
    if len(table.call.unique()) > 1:
        print(f"\nnote: the rows come from {len(table.call.unique())} calls; ratios across calls are not one "
              "machine state (delete runs.csv and run again for one)")
    figure(table, out / "fractions.png")
    print(f"\nwrote {out / 'fractions.csv'}, {out / 'engine_ratio.csv'}, {out / 'fractions.png'}")


# ---------------------------------------------------------------------------------------------- checks
def _check(folders: list[Path]) -> None:
    """Without an engine: the raw decks of every case and engine from siloflow's own renderer (and from
    the finished run folders ``folders``), checked whole and written to a scratch folder; the smoke
    cases' fills have the measuring cases' keys; the log parsers on a LIGGGHTS and a LAMMPS log."""
    from siloflow.case_file import case_from_dict
    from siloflow.derived import derive
    from siloflow.engine import get_engine
    from siloflow.engine.lammps.deck import render_deck_text as lammps_text
    from siloflow.engine.liggghts.deck import render_deck_text as liggghts_text
    from siloflow.fill_cache import fill_key_inputs
    scratch = Path(tempfile.mkdtemp(prefix="deck-vs-raw-check-"))
    for case in CASES:
        for engine in ENGINES:
            deck = RAW_SOURCE[engine]
            plan = derive(case_from_dict(case_data(case, engine, deck)))
            steps = {"static_steps": plan.static_steps, "open_steps": plan.opening.steps,
                     "discharge_steps": plan.discharge.chunk_steps * plan.discharge.max_chunks}
            if engine == "liggghts":
                siloflow_text = liggghts_text(plan, resume=True)
                raw, meshes = liggghts_raw_deck(siloflow_text, steps)
                kept = [line for line in raw.splitlines() if line and not line.startswith("#")]
                assert any("primitive type" in line and "zcylinder" in line and "store_force" not in line
                           for line in kept)
                assert any("massflow/mesh" in line and "delete_atoms yes" in line for line in kept)
                assert not any(line.split()[0] in ("dump", "compute", "region", "variable") for line in kept)
                assert sorted(meshes) == ["meshes/bottom.stl", "meshes/outlet.stl", "meshes/plate.stl"], meshes
                for keep in ("pair_style", "timestep", "neighbor", "neigh_modify", "fix             gravity",
                             "fix             integrate", "fix             material"):
                    assert [x for x in siloflow_text.splitlines() if x.startswith(keep)] == \
                        [x for x in kept if x.startswith(keep)], keep
                variants = {"raw": raw}
            else:
                siloflow_text = lammps_text(plan)
                first = 40000
                raw = lammps_raw_deck(siloflow_text, plan, steps, first)
                kept = [line for line in raw.splitlines() if line and not line.startswith("#")]
                assert not any(line.split()[0] in ("dump", "compute") or line.endswith(" contacts") for line in kept)
                assert any(" evaporate " in line for line in kept)
                assert f"variable        open_time string {(first + steps['static_steps']) * plan.dt!r}" in kept
                variants = {"raw": raw}
                if case in CLASSIC_CASES:
                    classic = lammps_raw_deck(siloflow_text, plan, steps, first, classic_pair_lines(plan))
                    assert "pair_style      gran/hertz/history" in classic and "pair_style      granular" not in classic
                    assert "pair_coeff      * *" in classic and "pair_coeff      1 1" not in classic
                    variants["raw_classic"] = classic
            for name, text in variants.items():
                out = scratch / case_name(case, engine, name)
                out.mkdir()
                (out / RAW_DECK[engine]).write_text(text)
                (out / f"siloflow.{RAW_DECK[engine]}").write_text(siloflow_text)
            commands = sum(1 for x in siloflow_text.splitlines() if x.strip() and not x.lstrip().startswith("#"))
            print(f"{case} {engine}: {plan.expected_atoms} grains, dt {plan.dt:.4g} s; raw deck {len(kept)} commands "
                  f"against siloflow's {commands}")
            # the smoke case's fill is the measuring case's (its key, the engine's version aside)
            keys = []
            eng = get_engine(engine)
            cls = type(eng)
            saved = cls.version
            cls.version = lambda self: "(not asked)"
            try:
                for smoke in (False, True):
                    for d in SILOFLOW_DECKS[engine]:
                        smoke_plan = derive(case_from_dict(case_data(case, engine, d, smoke)))
                        keys.append((d, fill_key_inputs(smoke_plan, eng)))
            finally:
                cls.version = saved
            by_deck = {}
            for d, k in keys:
                by_deck.setdefault(d, []).append(k)
            for d, ks in by_deck.items():
                assert ks[0] == ks[1], f"{case} {engine} {d}: the smoke case's fill key differs"
            if engine == "liggghts":
                assert by_deck["siloflow_meshes"][0] != by_deck["siloflow_primitive"][0]
    # the log parsers: stages by print (LIGGGHTS, the raw decks) and by the record's steps (LAMMPS' driver)
    liggghts_log = "\n".join([
        'print "SILOFLOW_STAGE settle 100"', "SILOFLOW_STAGE settle 100", "Step Time Atoms", "0 0 10", "100 0.1 10",
        "Loop time of 1.0 on 2 procs for 100 steps with 10 atoms, finish time x", "Pair  time (%) = 0.5 (50)",
        "Other time (%) = 0.5 (50)", "SILOFLOW_STAGE static 100", "Step Time Atoms", "100 0.1 10", "200 0.2 10",
        "Loop time of 2.0 on 2 procs for 100 steps with 10 atoms", "Pair  time (%) = 1.5 (75)",
        "Neigh time (%) = 0.1 (5)", "Other time (%) = 0.4 (20)", "SILOFLOW_STAGE discharge 200", "Step Time Atoms",
        "200 0.2 10", "300 0.3 8", "400 0.4 6", "Loop time of 4.0 on 2 procs for 200 steps with 6 atoms",
        "Pair  time (%) = 3 (75)", "Outpt time (%) = 0.5 (12.5)", "Other time (%) = 0.5 (12.5)"])
    m = measure(liggghts_log)
    assert (m["static_steps"], m["discharge_steps"], m["atoms_start"], m["atoms_end"]) == (100, 200, 10, 6), m
    assert m["particle_steps"] == 1000 + 100 * 9 + 100 * 7 and m["loop_s"] == 6.0, m
    assert (m["pair_s"], m["neigh_s"], m["output_s"], m["other_s"]) == (4.5, 0.1, 0.5, 0.9), m
    lammps_log = "\n".join([
        "write_restart   output/restart/settled.restart", "run 40 pre yes post yes", "   Step        Atoms   ",
        "       500         194 ", "       540         194 ", "Loop time of 0.5 on 2 procs for 40 steps with 194 atoms",
        "", "Section |  min time  |  avg time  |  max time  |%varavg| %total", "---",
        "Pair    | 0.1        | 0.2        | 0.3        |   0.0 | 40.00",
        "Neigh   | 0.01       | 0.02       | 0.03       |   0.0 |  4.00",
        "Modify  | 0.1        | 0.1        | 0.1        |   0.0 | 20.00",
        "Other   |            | 0.05       |            |       | 10.00",
        "run 40 pre no post no", "   Step        Atoms   ", "       540         194 ", "       580         190 ",
        "Loop time of 0.4 on 2 procs for 40 steps with 190 atoms"])
    m = measure(lammps_log, {"fill": 0, "settle": 100, "static": 500, "open": 540, "discharge": 580})
    assert (m["static_steps"], m["open_steps"], m["discharge_steps"], m["first_step"]) == (40, 40, 0, 500), m
    assert (m["pair_s"], m["neigh_s"], m["modify_s"], m["other_s"]) == (0.2, 0.02, 0.1, 0.05), m
    no_split = "\n".join(line for line in lammps_log.splitlines() if "|" not in line)     # siloflow's "post no" runs
    m = measure(no_split, {"fill": 0, "settle": 100, "static": 500, "open": 540, "discharge": 580})
    assert all(math.isnan(m[k]) for k in SPLIT) and m["loop_s"] == 0.9 and m["particle_steps"] == 40 * 194 + 40 * 192, m
    # the LAMMPS ranks' hook (a Python of this venv with the ranks' environment) and the launch timer
    env = {**os.environ, "PYTHONPATH": str(HOOK), HOOK_SWITCH[0]: HOOK_SWITCH[1]}
    probe = ("import siloflow.engine.lammps.driver as d, sitecustomize as h\n"
             "class L:\n    def command(self, line): self.line = line\n"
             "p = h.RunPostProxy(L()); p.command('run 42 pre no post no')\n"
             "assert getattr(d.Driver.__init__, '_run_post', False) and p._lmp.line == 'run 42 pre no post yes'")
    subprocess.run([sys.executable, "-c", probe], env=env, check=True, cwd=scratch)
    _time_launches()
    from siloflow.engine.lammps.engine import LammpsEngine
    from siloflow.engine.liggghts.engine import LiggghtsEngine
    assert LammpsEngine.launch._timed and LiggghtsEngine.launch._timed
    # finished run folders: their after-bed measure, and their raw deck written beside the rendered ones
    for folder in folders:
        from siloflow.run_folder import RunFolder
        plan_engine = RunFolder(folder).plan.engine.name
        m = measure_folder(folder, plan_engine)
        print(f"{folder}: {plan_engine}, after the bed {m['steps']} steps in {m['runs']} runs (static "
              f"{m['static_steps']}, open {m['open_steps']}, discharge {m['discharge_steps']}), {m['atoms_start']} -> "
              f"{m['atoms_end']} atoms, "
              f"loop {m['loop_s']:.1f} s, {m['particle_steps'] / m['loop_s']:.3g} particle-steps/s in the loop; split "
              + ", ".join(f"{k} {m[k]:.1f}" for k in SPLIT))
        plan = RunFolder(folder).plan
        out = scratch / f"from_{folder.name}"
        out.mkdir()
        if plan_engine == "liggghts":
            from siloflow.engine.liggghts.deck import render_deck_text
            text, meshes = liggghts_raw_deck(render_deck_text(plan, resume=True), m)
            assert all((folder / mesh).is_file() for mesh in meshes), meshes
        else:
            text = lammps_raw_deck((folder / "in.lammps").read_text(), plan, m, m["first_step"])
        (out / RAW_DECK[plan_engine]).write_text(text)
    print(f"checks passed; the decks are in {scratch}")


# ---------------------------------------------------------------------------------------------- main
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--engines", nargs="+", choices=list(ENGINES), default=list(ENGINES))
    ap.add_argument("--smoke", action="store_true", help="every deck for a few hundred steps after the settled bed "
                    "(rows in benchmarks/work/raw_smoke/: checks the script, not a result)")
    ap.add_argument("--table", action="store_true", help="only print and write the fractions from the rows there")
    ap.add_argument("--cache", type=Path, default=CACHE, help=f"the fill cache (default {CACHE.relative_to(ROOT)})")
    ap.add_argument("--check", action="store_true", help="no engine: write and check the raw decks from siloflow's "
                    "renderer (and from --check-folder run folders), the smoke fill keys and the log parsers")
    ap.add_argument("--check-folder", type=Path, action="append", default=[], help="a finished run folder for --check")
    ap.add_argument("--decks", nargs="+", choices=ALL_DECKS, default=list(ALL_DECKS),
                    help="only these decks (default every one; a raw deck still runs the siloflow deck it starts from)")
    ap.add_argument("--no-lammps-split", action="store_true", help="siloflow's LAMMPS chunks as siloflow runs them "
                    "(post no): no loop split, and nothing of LAMMPS' summary in the time between chunks")
    args = ap.parse_args()
    work = SMOKE_WORK if args.smoke else WORK
    out = work / "results" if args.smoke else OUT
    csv = out / "runs.csv"
    if args.check:
        _check(args.check_folder)
        return
    if args.table:
        report(csv, out)
        return
    import pandas as pd
    work.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    table = pd.read_csv(csv) if csv.is_file() else pd.DataFrame()
    def have() -> set:
        return set(zip(table.case, table.engine, table.deck)) if len(table) else set()
    done = have()
    call = datetime.datetime.now().isoformat(timespec="seconds")
    before = cpu_now()
    time.sleep(QUIET_PROBE)
    busy = other_cpu(before)
    if busy > QUIET_LIMIT:
        print(f"warning: other processes use {busy:.1f} cores of this machine's {os.cpu_count()}: the rows will not "
              "be clean samples (each row's other_cpu says how busy it was)", flush=True)

    def add(row: dict) -> None:
        nonlocal table
        table = with_fractions(pd.concat([table, pd.DataFrame([row])], ignore_index=True))
        table.to_csv(csv, index=False)              # kept after every run: the benchmark resumes
        print(f"  {row['case']} {row['engine']} {row['deck']}: {row['particle_steps']:.3g} particle-steps, "
              f"{row['loop_rate']:.3g}/s in the loop, {row['wall_rate']:.3g}/s over the wall time "
              f"(other processes: {row['other_cpu']:.2f} cores)", flush=True)

    for case in args.cases:
        for engine in args.engines:
            for deck in decks_of(case, engine):
                if (case, engine, deck) in done or deck not in args.decks:
                    continue
                if deck in SILOFLOW_DECKS[engine]:
                    add(run_siloflow(case, engine, deck, work, args.cache, args.smoke, call, not args.no_lammps_split))
                    continue
                source_deck = RAW_SOURCE[engine]
                source = work / case_name(case, engine, source_deck)
                if not finished(source):               # its row is there but the folder is not: run it again
                    row = run_siloflow(case, engine, source_deck, work, args.cache, args.smoke, call,
                                       not args.no_lammps_split)
                    if (case, engine, source_deck) not in have():
                        add(row)
                add(run_raw(case, engine, deck, source, work, call))
    report(csv, out)


if __name__ == "__main__":
    main()
