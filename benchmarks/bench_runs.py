"""What the engine benchmarks share: running one case (a dict) into a work folder through
``siloflow.run``, timed, in this process (no benchmark starts a ``siloflow`` command). A failed run
stops the benchmark."""
from __future__ import annotations

import re
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
#: LIGGGHTS' and LAMMPS' "Loop time of T on P procs for N steps with A atoms", one per ``run``
LOOP = re.compile(r"^Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms", re.M)
#: the sections of the engines' loop timing: LIGGGHTS 3.8 "Pair  time (%) = T (P)", LAMMPS' table
#: "Pair    | min | avg | max | %varavg | %total" (its Other row has the average alone)
SECTIONS = ("Pair", "Neigh", "Comm", "Output", "Modify", "Other")
_LIGGGHTS_SECTION = re.compile(r"^(\w+)\s+time \(%\) = (\S+) \(", re.M)
_LAMMPS_SECTION = re.compile(r"^(\w+)\s*\|\s*(?:(\S+)\s*\|\s*(\S+)|\s*\|\s*(\S+))", re.M)


def loop_split(log_text: str) -> dict[str, float]:
    """Seconds of each loop section (``pair_s`` ... ``other_s``: :data:`SECTIONS`) summed over a
    log's ``run`` commands, LIGGGHTS' or LAMMPS' (the average over ranks); 0 for a section the log
    never names (LIGGGHTS 3.8 has no Modify: its fixes are in Other)."""
    out = {f"{s.lower()}_s": 0.0 for s in SECTIONS}
    for name, seconds in _LIGGGHTS_SECTION.findall(log_text):
        name = "Output" if name == "Outpt" else name          # LIGGGHTS 3.8 spells it so
        if name in SECTIONS:
            out[f"{name.lower()}_s"] += float(seconds)
    for m in _LAMMPS_SECTION.finditer(log_text):
        name, avg = m.group(1), m.group(3) or m.group(4)
        if name in SECTIONS:
            try:
                out[f"{name.lower()}_s"] += float(avg)
            except ValueError:
                pass
    return out


def run_case(data: dict, work: Path, force: bool = False, cache: Path | None = None) -> tuple[Path, float]:
    """``siloflow.run`` of the case ``data`` (named by its ``name``) into ``work/runs/<name>``, its
    case file beside it in ``work`` (``force``: replace a folder siloflow made): (run folder, wall
    time s of the whole pipeline, render to first results); ``cache``: a fill cache folder. A refused or failed run stops the
    benchmark with siloflow's message."""
    from siloflow.errors import SiloflowError
    from siloflow.runs import run
    case_path = work / f"{data['name']}.yaml"
    case_path.write_text(yaml.safe_dump(data))
    folder = work / "runs" / data["name"]
    t0 = time.perf_counter()
    try:
        run(case_path, folder, force=force, cache=cache)
    except SiloflowError as exc:
        raise SystemExit(f"{data['name']} failed: {exc}") from None
    return folder, time.perf_counter() - t0


def clogged(folder: Path) -> bool:
    """Whether a finished run's discharge clogged, as its summary says (``summary.json``'s
    ``clogged``, ``postprocess.discharge.clog``). A summary written before clog detection is refused:
    ``siloflow post`` the folder again."""
    from siloflow.run_folder import RunFolder
    summary = RunFolder(folder).read_summary()
    if "clogged" not in summary:
        raise SystemExit(f"{folder}: its summary predates clog detection; run `siloflow post {folder}` again")
    return summary["clogged"] is not None
