"""Sweeps: one case over ``--set`` values and seeds, run here within a core budget or on Slurm.

A sweep is the cartesian product of the ``--set PATH=V1,V2,...`` values times ``seeds`` seeds
(:func:`expand`); each combination is a :class:`Variant`, a validated case named
``<case>-<index>``. Variants whose settled beds are the same (one
:func:`siloflow.fill_cache.fill_key`) form a fill group (:func:`group_by_fill`): its first
variant computes the fill and publishes it in the fill cache, the others start from it.

:func:`run_sweep` runs the variants here as ``siloflow run`` subprocesses: each group's first
before the rest of its group, in parallel while the engine ranks of the running ones add up to
at most the core budget; it writes the table of results ``sweep.csv`` (:func:`sweep_table`).
:func:`write_slurm` writes two Slurm job arrays instead (the fills, then the other runs after
them) and the script that submits them.

A sweep folder ``OUT`` holds ``cases/<name>.yaml`` (each variant's case), ``runs/<name>/`` (its
run folder), ``logs/`` (each run's terminal output) and ``sweep.csv``; for Slurm also
``fills.sbatch``, ``runs.sbatch``, ``fills.txt``, ``runs.txt`` (array task -> case file) and
``submit.sh``. Nothing in an existing folder is ever deleted or replaced.
"""
from __future__ import annotations

import copy
import itertools
import json
import math
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import yaml

from .atomic_files import write_text
from .case import Case
from .case_file import case_from_dict, load_case, parse_case_yaml, read_case_bytes
from .errors import CaseError, ReadError, SetupError

#: most values one ``--set`` may list
MAX_SET_VALUES = 1000
#: most variants one sweep may expand into (values x seeds)
MAX_VARIANTS = 10000
#: a segment of a ``--set`` field path
FIELD_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: a float as YAML 1.2 reads it; PyYAML (YAML 1.1) leaves ``1e-3`` and ``5.0e6`` strings
YAML12_FLOAT = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")
#: longest case name (``siloflow.case.SAFE_NAME_PATTERN``)
MAX_NAME_LENGTH = 64
#: s between two looks at the running runs
POLL_INTERVAL = 0.05
#: s a stopped run gets to stop its engine (siloflow run: 10 s SIGTERM + 5 s SIGKILL) before SIGKILL
STOP_GRACE = 30.0
#: progress(done, total, names of the running variants)
SweepProgress = Callable[[int, int, list], None]
#: columns of the sweep table before the ``--set`` paths, and after them
TABLE_HEAD = ("run", "name")
TABLE_TAIL = ("seed", "fill_key", "fill_from_cache", "status", "returncode", "wall_s", "flow_rate_kg_s",
              "flow_rate_stderr_kg_s", "force_balance_ratio", "bulk_solid_fraction", "log")


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: its position ``index`` (0..n-1), case ``name`` (``<case>-<index>``),
    the ``--set`` ``values`` ({field path: value}), ``seed``, the case mapping ``data`` (written
    to ``cases/<name>.yaml``) and its validated ``case``."""

    index: int
    name: str
    values: dict
    seed: int
    data: dict
    case: Case


# ------------------------------------------------------------------ --set and the variants
def _shown(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _scalar(item: str, spec: str):
    """One ``--set`` value as a YAML scalar (numbers in YAML 1.2's spelling too)."""
    text = item.strip()
    if not text:
        raise SetupError(f"--set {spec}: an empty value (two commas, or nothing after '=')")
    try:
        value = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError) as exc:
        problem = getattr(exc, "problem", None) or exc
        raise SetupError(f"--set {spec}: {_shown(text)!r} is not a YAML value ({problem})") from None
    if isinstance(value, str) and value == text and YAML12_FLOAT.fullmatch(text):
        value = float(text)
    if value is not None and not isinstance(value, (bool, int, float, str)):
        raise SetupError(f"--set {spec}: {_shown(text)!r} is a {type(value).__name__}; a value must be a number, "
                         "true/false, null or a string (quote it: '\"...\"')")
    return value


def parse_set(spec: str) -> tuple[str, list]:
    """``"geometry.orifice_radius=0.006,0.008"`` -> ``("geometry.orifice_radius", [0.006, 0.008])``.

    Each value is read as a YAML scalar: numbers (``1e-3`` too), ``true``/``false``, ``null``,
    strings. Raises ``SetupError`` naming the ``--set`` for an empty path or value, a path segment
    that is not a field name (``[A-Za-z_][A-Za-z0-9_]*``), a value given twice or more than
    ``MAX_SET_VALUES`` values.
    """
    shown = _shown(spec)
    path, sep, text = spec.partition("=")
    path = path.strip()
    if not sep:
        raise SetupError(f"--set {shown}: expected PATH=V1,V2,... (e.g. geometry.orifice_radius=0.006,0.008)")
    if not path:
        raise SetupError(f"--set {shown}: no field path before '='")
    for segment in path.split("."):
        if not FIELD_NAME.fullmatch(segment):
            raise SetupError(f"--set {shown}: {segment!r} in {_shown(path)!r} is not a field name (letters, "
                             "digits and _, not starting with a digit; sections joined by '.')")
    items = text.split(",")
    if len(items) > MAX_SET_VALUES:
        raise SetupError(f"--set {shown}: {len(items)} values; at most {MAX_SET_VALUES}")
    values = [_scalar(item, shown) for item in items]
    seen = set()
    for value in values:
        if (type(value), value) in seen:
            raise SetupError(f"--set {shown}: the value {value!r} is given twice")
        seen.add((type(value), value))
    return path, values


def _check_paths(sets: list[tuple[str, list]], seeds: int) -> None:
    paths = [path for path, _ in sets]
    for i, path in enumerate(paths):
        if path == "name":
            raise SetupError("--set name: a sweep names its variants itself (<case name>-<index>)")
        if path == "seed" and seeds > 1:
            raise SetupError("--set seed and --seeds: give the seeds one way (--set seed=1,2,3 or --seeds 3)")
        for other in paths[:i]:
            if other == path:
                raise SetupError(f"--set {path} is given twice: list all its values in one --set")
            if path.startswith(other + ".") or other.startswith(path + "."):
                raise SetupError(f"--set {other} and --set {path}: one is inside the other")


def _base_name(name) -> str:
    """The case name as the stem of variant names: ``siloflow.case.SAFE_NAME_PATTERN``'s alphabet, other
    characters as ``_``, no leading ``.`` or ``-`` ('sweep' if nothing is left)."""
    text = re.sub(r"[^A-Za-z0-9_.-]", "_", name if isinstance(name, str) else "")
    return text.lstrip(".-") or "sweep"


def variant_name(base: str, index: int) -> str:
    """``<base>-<index:03d>``, the base cut so that the name fits ``siloflow.case.SAFE_NAME_PATTERN`` (64 characters)."""
    suffix = f"-{index:03d}"
    return _base_name(base)[:MAX_NAME_LENGTH - len(suffix)] + suffix


def _set_field(data: dict, path: str, value, source: str) -> None:
    """Set ``value`` at the dotted ``path`` of ``data``, making missing sections."""
    node = data
    keys = path.split(".")
    for depth, key in enumerate(keys[:-1]):
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            where = ".".join(keys[:depth + 1])
            raise CaseError([(where, f"is a {type(node).__name__}, not a section: --set {path} cannot set a "
                                     "field inside it")], source)
    node[keys[-1]] = value


def _made_by(values: dict, seed) -> str:
    given = ", ".join(f"--set {path}={json.dumps(value)}" for path, value in values.items() if path != "seed")
    return (given + ", " if given else "") + f"seed {seed}"


def expand(case_data: dict, sets: list[tuple[str, list]], seeds: int = 1) -> list[Variant]:
    """The sweep's variants: every combination of the ``--set`` values (the last ``--set``
    varying fastest) times ``seeds`` seeds, seed k being the case's ``seed`` (or the ``--set
    seed`` value) + k. Each is a deep copy of ``case_data`` with the values at their dotted
    paths (missing sections made), named ``<case name>-<index:03d>`` and validated.

    Raises
    ------
    SetupError
        for ``seeds`` < 1, a path given twice or inside another, ``--set name``, ``--set seed``
        with ``seeds`` > 1, or more than ``MAX_VARIANTS`` variants.
    CaseError
        for the first variant that does not validate: each problem names the field and the
        ``--set`` values and seed that made it.
    """
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise SetupError(f"--seeds {seeds!r}: the number of seeds must be a whole number >= 1")
    if not isinstance(case_data, dict):
        raise CaseError([("(top level)", "the case file must be a YAML mapping of sections")], "sweep")
    _check_paths(sets, seeds)
    count = math.prod(len(values) for _, values in sets) * seeds
    if count > MAX_VARIANTS:
        raise SetupError(f"the sweep expands into {count} runs ({' x '.join(str(len(v)) for _, v in sets)} values "
                         f"x {seeds} seeds); at most {MAX_VARIANTS}")
    paths = [path for path, _ in sets]
    base = case_data.get("name")
    variants = []
    for combination in itertools.product(*(values for _, values in sets)):
        values = dict(zip(paths, combination))
        for k in range(seeds):
            index = len(variants)
            name = variant_name(base, index)
            source = f"sweep variant {name}"
            data = copy.deepcopy(case_data)
            for path, value in values.items():
                _set_field(data, path, value, source)
            seed = data.get("seed", Case.model_fields["seed"].default)
            if k:
                if isinstance(seed, bool) or not isinstance(seed, int):
                    raise CaseError([("seed", f"is {seed!r}: --seeds adds to it, so it must be a whole number")],
                                    source)
                seed += k
            data["seed"], data["name"] = seed, name
            try:
                case = case_from_dict(data, source)
            except CaseError as exc:
                raise _in_variant(exc, name, values, seed) from None
            variants.append(Variant(index, name, values, seed, data, case))
    return variants


def _in_variant(exc: CaseError, name: str, values: dict, seed) -> CaseError:
    """``exc`` with each problem saying which variant, ``--set`` values and seed made it."""
    made = _made_by(values, seed)
    return CaseError([(path, f"{message} (from {made})") for path, message in exc.problems],
                     f"sweep variant {name}")


def read_case_data(path) -> dict:
    """The mapping of case file ``path``, checked whole first (``load_case``: every problem of
    the case itself), with its inserts' files as absolute paths: the variants' case files are
    written elsewhere and must still find them. Raises ``CaseError``."""
    path = Path(path)
    case = load_case(path)
    data = parse_case_yaml(read_case_bytes(path), str(path))
    for insert, located in zip(data.get("inserts") or [], case.inserts):
        insert["file"] = located.file
    return data


# ------------------------------------------------------------------ fill groups
def sweep_engine(variants: list[Variant], need_binary: bool = True):
    """The engine the variants name (one for all), for their fill keys. Its version is asked
    once (``fill_key_parts`` asks for it per plan). Without the binary on this machine (a Slurm
    sweep written on a login node), ``need_binary=False`` keys with a stand-in version: the
    grouping is the same, since every variant has it. Raises ``SetupError``."""
    from .engine import get_engine
    names = sorted({v.case.engine.name for v in variants})
    if len(names) != 1:
        raise SetupError(f"one sweep runs one engine; its variants name {', '.join(names) or 'none'} (engine.name)")
    engine = get_engine(names[0])
    try:
        version = engine.version()
    except SetupError:
        if need_binary:
            raise
        version = "(not installed where the sweep was written)"
    engine.version = lambda: version        # the binary does not change during the sweep
    return engine


def group_by_fill(variants: list[Variant], engine) -> dict[str, list[Variant]]:
    """The variants by fill key (``siloflow.fill_cache.fill_key`` of each one's run plan on
    ``engine``), in order of first appearance, each group in variant order. Raises the
    ``CaseError`` of a variant whose plan cannot be made, naming its ``--set`` values."""
    from .derived import derive
    from .fill_cache import fill_key
    groups: dict[str, list[Variant]] = {}
    for v in variants:
        try:
            plan = derive(v.case)
        except CaseError as exc:
            raise _in_variant(exc, v.name, v.values, v.seed) from None
        groups.setdefault(fill_key(plan, engine), []).append(v)
    return groups


def check_engine(variants: list[Variant], engine) -> None:
    """Refuse, before anything runs, a variant the engine cannot run (``Engine.check``)."""
    from .engine.base import check_case
    for v in variants:
        try:
            check_case(v.case, engine)
        except CaseError as exc:
            raise _in_variant(exc, v.name, v.values, v.seed) from None


def _key_of(groups: dict[str, list[Variant]], variants: list[Variant]) -> dict[str, str]:
    """Variant name -> fill key; every variant in exactly one group (``SetupError`` otherwise)."""
    keys = {v.name: key for key, members in groups.items() for v in members}
    count = sum(len(members) for members in groups.values())
    if count != len(keys) or set(keys) != {v.name for v in variants}:
        raise SetupError("the fill groups do not hold each variant of the sweep exactly once")
    return keys


# ------------------------------------------------------------------ the sweep folder
def check_sweep_folder(out, variants: list[Variant], force: bool) -> None:
    """Refuse an existing non-empty sweep folder unless ``force``; even then refuse one whose
    ``runs/`` already holds a variant's run folder or whose ``cases/`` holds another case under
    a variant's name (nothing is ever deleted or replaced). Raises ``SetupError``."""
    out = Path(out)
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise SetupError(f"{out} exists and is not a folder (or is a symbolic link): choose another sweep folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not force:
        raise SetupError(f"{out} already exists and is not empty: choose another folder, or pass --force to "
                         "reuse it (nothing in it is deleted; existing run folders are refused)")
    taken = [v.name for v in variants if os.path.lexists(out / "runs" / v.name)]
    if taken:
        shown = ", ".join(taken[:5]) + (f" and {len(taken) - 5} more" if len(taken) > 5 else "")
        raise SetupError(f"{out / 'runs'} already holds {shown}: siloflow never replaces a run; move them "
                         "out, or choose another sweep folder")
    for v in variants:
        path = out / "cases" / f"{v.name}.yaml"
        if os.path.lexists(path) and (path.is_symlink() or not path.is_file()
                                      or path.read_text(errors="replace") != case_text(v)):
            raise SetupError(f"{path} holds another case: siloflow does not overwrite it; choose another "
                             "sweep folder")


def case_text(variant: Variant) -> str:
    """The variant's case file (YAML)."""
    return yaml.safe_dump(variant.data, sort_keys=False)


def write_cases(variants: list[Variant], out) -> dict[str, Path]:
    """Write each variant's case as ``out/cases/<name>.yaml`` (atomically); name -> path."""
    folder = Path(out) / "cases"
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for v in variants:
        paths[v.name] = folder / f"{v.name}.yaml"
        write_text(paths[v.name], case_text(v))
    return paths


def prepare_sweep(case_file, set_specs: list[str], seeds: int, out, force: bool = False,
                  need_binary: bool = True) -> tuple[list[Variant], dict[str, list[Variant]]]:
    """What ``siloflow sweep`` does before it runs or writes anything: read the case, expand the
    ``--set`` specs and seeds, check the sweep folder, the engine and every variant's plan.
    Returns the variants and their fill groups."""
    data = read_case_data(case_file)
    variants = expand(data, [parse_set(spec) for spec in set_specs], seeds)
    check_sweep_folder(out, variants, force)
    engine = sweep_engine(variants, need_binary)
    check_engine(variants, engine)
    return variants, group_by_fill(variants, engine)


# ------------------------------------------------------------------ running here
def default_command() -> list[str]:
    """``siloflow run`` with this Python (the variant's case, ``-o``, ``--cache`` follow)."""
    return [sys.executable, "-m", "siloflow.cli", "run"]


@dataclass
class _Job:
    variant: Variant
    process: subprocess.Popen
    log: object


class _FillOrder:
    """Which variants may start. Until a fill group has a finished run (its settled bed is then
    in the cache), one of its variants at a time runs, computing the fill; a failed one hands
    the fill to the next. Afterwards the rest of the group may start, from the cached bed."""

    def __init__(self, groups: dict[str, list[Variant]]):
        self.waiting = {key: list(members) for key, members in groups.items()}
        self.filling: dict[str, str] = {}       # key -> name of the run computing its fill
        self.filled: set[str] = set()

    def ready(self) -> list[tuple[str, Variant]]:
        """(key, variant) that may start: the fills first (group order), then the others (variant order)."""
        fills, others = [], []
        for key, members in self.waiting.items():
            if key in self.filled:
                others += [(key, v) for v in members]
            elif members and key not in self.filling:
                fills.append((key, members[0]))
        return fills + sorted(others, key=lambda kv: kv[1].index)

    def started(self, key: str, variant: Variant) -> None:
        self.waiting[key].remove(variant)
        if key not in self.filled:
            self.filling[key] = variant.name

    def finished(self, key: str, variant: Variant, ok: bool) -> None:
        if self.filling.get(key) == variant.name:
            del self.filling[key]
            if ok:
                self.filled.add(key)


def check_cores(variants: list[Variant], cores: int) -> None:
    """Refuse a core budget below 1 or below a variant's ``engine.ranks`` (``SetupError``)."""
    if isinstance(cores, bool) or not isinstance(cores, int) or cores < 1:
        raise SetupError(f"--cores {cores!r}: the core budget must be a whole number >= 1")
    wide = [v for v in variants if v.case.engine.ranks > cores]
    if wide:
        v = max(wide, key=lambda v: v.case.engine.ranks)
        raise SetupError(f"{v.name} needs engine.ranks = {v.case.engine.ranks} but --cores is {cores}: "
                         "raise --cores or lower engine.ranks")


def _start(variant: Variant, command: list[str], case_file: Path, out: Path, cache: Path) -> _Job:
    argv = [*command, str(case_file), "-o", str(out / "runs" / variant.name), "--cache", str(cache)]
    log_file = out / "logs" / f"{variant.name}.log"
    try:
        log = open(log_file, "a", encoding="utf-8")        # appended: an older log is never truncated
        log.write(f"# siloflow sweep, {time.strftime('%Y-%m-%d %H:%M:%S')}: {shlex.join(argv)}\n")
        log.flush()
    except OSError as exc:
        raise SetupError(f"cannot write the log {log_file}: {exc.strerror or exc}") from None
    try:
        process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                   env={**os.environ, "COLUMNS": "200"}, start_new_session=True)
    except OSError as exc:
        log.close()
        raise SetupError(f"cannot start {argv[0]} for {variant.name}: {exc.strerror or exc}") from None
    return _Job(variant, process, log)


def _stop(jobs: list[_Job], grace: float = STOP_GRACE) -> None:
    """SIGTERM every running job (siloflow run then stops its engine and marks the folder
    interrupted) and wait for it; SIGKILL its process group after ``grace`` s."""
    for job in jobs:
        if job.process.poll() is None:
            job.process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + grace
    for job in jobs:
        try:
            job.process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            try:
                os.killpg(job.process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            job.process.wait()


def run_sweep(variants: list[Variant], out: Path, cores: int, cache: Path, command: Optional[list[str]] = None,
              progress: Optional[SweepProgress] = None, groups: Optional[dict[str, list[Variant]]] = None):
    """Run the variants here and return their table (:func:`sweep_table`, also ``out/sweep.csv``).

    Each variant's case is written to ``out/cases/<name>.yaml`` and run as
    ``command + [case, "-o", out/runs/<name>, "--cache", cache]`` (default ``siloflow run`` with
    this Python), its output in ``out/logs/<name>.log``. A fill group's first variant runs
    before the rest of its group, which then starts from its cached bed; runs go in parallel
    while their ``engine.ranks`` add up to at most ``cores``. A failed run does not stop the
    others. ``groups`` are the fill groups (:func:`group_by_fill`; default: with the cases'
    engine). ``progress(done, total, running_names)`` is told of every change. Ctrl-C
    (``KeyboardInterrupt``) stops the running runs and is raised again.

    Raises
    ------
    SetupError
        for a run needing more ranks than ``cores``, or a command that cannot be started.
    """
    out = Path(out).absolute()
    cache = Path(cache).absolute()
    check_cores(variants, cores)
    if groups is None:
        groups = group_by_fill(variants, sweep_engine(variants))
    keys = _key_of(groups, variants)
    case_files = write_cases(variants, out)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    command = list(command or default_command())
    order = _FillOrder(groups)
    running: dict[str, _Job] = {}
    returncodes: dict[str, int] = {}
    changed = True
    try:
        while len(returncodes) < len(variants):
            for name, job in list(running.items()):
                code = job.process.poll()
                if code is not None:
                    job.log.close()
                    del running[name]
                    returncodes[name] = code
                    order.finished(keys[name], job.variant, code == 0)
                    changed = True
            free = cores - sum(job.variant.case.engine.ranks for job in running.values())
            for key, v in order.ready():
                if v.case.engine.ranks <= free:
                    running[v.name] = _start(v, command, case_files[v.name], out, cache)
                    order.started(key, v)
                    free -= v.case.engine.ranks
                    changed = True
            if changed and progress is not None:
                progress(len(returncodes), len(variants), sorted(running))
            changed = False
            if len(returncodes) < len(variants):
                time.sleep(POLL_INTERVAL)
    except BaseException:                      # Ctrl-C, or a run that could not start
        _stop(list(running.values()))
        raise
    finally:
        for job in running.values():
            job.log.close()
    table = sweep_table(variants, out, keys, returncodes)
    write_text(out / "sweep.csv", table.to_csv(index=False))
    return table


# ------------------------------------------------------------------ the table
def _number(value) -> float:
    """``value`` as a float if it is a finite-or-nan number (not a bool), else nan."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _results(folder: Path) -> dict:
    """What the table takes from a run folder (nan/None where it holds nothing readable)."""
    from .run_folder import RunFolder
    run = RunFolder(folder)
    row = {"fill_from_cache": None, "wall_s": math.nan, "flow_rate_kg_s": math.nan,
           "flow_rate_stderr_kg_s": math.nan, "force_balance_ratio": math.nan, "bulk_solid_fraction": math.nan}
    try:
        record = run.record
        row["wall_s"] = _number(record.wall_time)
        if isinstance(record.fill_cache, dict) and isinstance(record.fill_cache.get("hit"), bool):
            row["fill_from_cache"] = record.fill_cache["hit"]
    except ReadError:
        pass
    try:
        summary = run.read_summary()
    except ReadError:
        return row

    def section(name: str) -> dict:
        value = summary.get(name)
        return value if isinstance(value, dict) else {}

    row["flow_rate_kg_s"] = _number(section("flow_rate").get("rate"))
    row["flow_rate_stderr_kg_s"] = _number(section("flow_rate").get("stderr"))
    row["force_balance_ratio"] = _number(section("force_balance").get("ratio"))
    row["bulk_solid_fraction"] = _number(section("frame_analyses").get("bulk_solid_fraction"))
    return row


def sweep_table(variants: list[Variant], out: Path, keys: dict[str, str], returncodes: dict[str, int]):
    """One row per variant: ``run`` (its run folder), ``name``, each ``--set`` path, ``seed``,
    ``fill_key`` (first 12 hex digits), ``fill_from_cache`` (the run record's ``fill_cache``
    hit, None if unknown), ``status`` (complete: exit code 0, else failed), ``returncode``,
    ``wall_s`` (engine wall time, s), ``flow_rate_kg_s`` and ``flow_rate_stderr_kg_s`` (steady
    flow rate, kg/s), ``force_balance_ratio`` (settled bed's supports over its weight),
    ``bulk_solid_fraction`` and ``log``; nan where a run left no value. A pandas DataFrame."""
    import pandas as pd
    out = Path(out)
    paths = [path for path in (variants[0].values if variants else {}) if path != "seed"]
    rows = []
    for v in variants:
        folder = out / "runs" / v.name
        code = returncodes.get(v.name)
        row = {"run": str(folder), "name": v.name, **{path: v.values[path] for path in paths}, "seed": v.seed,
               "fill_key": keys[v.name][:12], "status": "complete" if code == 0 else "failed", "returncode": code,
               "log": str(out / "logs" / f"{v.name}.log")}
        rows.append({**row, **_results(folder)})
    return pd.DataFrame(rows, columns=[*TABLE_HEAD, *paths, *TABLE_TAIL])


def table_summary(table) -> dict:
    """Counts of a sweep table: runs ``complete`` and ``failed``, fills ``computed`` (runs that
    made their bed) and ``reused`` (runs that started from a cached one)."""
    fills = table["fill_from_cache"].map({True: "reused", False: "computed"})
    return {"complete": int((table["status"] == "complete").sum()), "failed": int((table["status"] != "complete").sum()),
            "computed": int((fills == "computed").sum()), "reused": int((fills == "reused").sum())}


# ------------------------------------------------------------------ Slurm
def _relative(path: Path, out: Path) -> str:
    """``path`` relative to the sweep folder when inside it (the folder can move to a cluster)."""
    path = Path(path).absolute()
    return path.relative_to(out).as_posix() if out in path.parents else str(path)


def _array_script(job_name: str, tasks: str, variants: list[Variant], what: str, siloflow: str, cache: str) -> str:
    """A job array with one task per line of ``tasks``, each running ``siloflow run`` on that case."""
    ranks = max(v.case.engine.ranks for v in variants)
    run = f"{shlex.quote(siloflow)} run \"$case_file\" -o \"runs/$name\" --cache {shlex.quote(cache)}"
    return f"""#!/bin/bash
# siloflow sweep: {what}
# One array task per line of {tasks} (task k runs the case file on line k + 1), in the sweep folder
# (submit.sh submits from there). siloflow starts the engine itself (mpirun -np <engine.ranks>)
# inside the task's allocation, so a task is one node with one Slurm task per MPI rank, one CPU
# each: --ntasks = --ntasks-per-node = the largest engine.ranks of these cases ({ranks}),
# --cpus-per-task=1. Open MPI's mpirun takes its slots from the allocation; srun is not used.
# The fill cache must be on a file system every node sees. Slurm's MaxArraySize (1001 by
# default) bounds the tasks of one array.
#SBATCH --job-name={job_name}
#SBATCH --array=0-{len(variants) - 1}
#SBATCH --nodes=1
#SBATCH --ntasks={ranks}
#SBATCH --ntasks-per-node={ranks}
#SBATCH --cpus-per-task=1
#SBATCH --output=logs/%x-%A_%a.out
set -euo pipefail
case_file=$(sed -n "$((SLURM_ARRAY_TASK_ID + 1))p" {tasks})
if [ -z "$case_file" ]; then
    echo "no case file on line $((SLURM_ARRAY_TASK_ID + 1)) of {tasks}" >&2
    exit 1
fi
name=$(basename "$case_file" .yaml)
export COLUMNS=200
exec {run}
"""


def _submit_script(fills: int, runs: int) -> str:
    lines = ["#!/bin/bash",
             "# Submit the sweep: the fills (one per distinct settled bed), then the other runs, which",
             "# start from the cached beds once every fill succeeded (afterok). If a fill fails, the runs",
             "# stay pending (DependencyNeverSatisfied): scancel them, fix the case, submit again.",
             "set -euo pipefail",
             'cd "$(dirname "$0")"',
             "fills=$(sbatch --parsable fills.sbatch)",
             "fills=${fills%%;*}                 # --parsable prints jobid[;cluster]",
             f'echo "fills: job $fills ({fills} tasks)"']
    if runs:
        lines += ['runs=$(sbatch --parsable --dependency=afterok:"$fills" runs.sbatch)',
                  "runs=${runs%%;*}",
                  f'echo "runs: job $runs ({runs} tasks, after job $fills)"']
    return "\n".join(lines) + "\n"


def write_slurm(variants: list[Variant], groups: dict[str, list[Variant]], out: Path, cache: Path,
                siloflow: str = "siloflow") -> Path:
    """Write the sweep as Slurm job arrays instead of running it; return ``out/submit.sh``.

    Writes ``out/cases/*.yaml``; ``fills.txt`` (the first variant of each fill group) and
    ``runs.txt`` (the others), one case file per line, array task k taking line k + 1;
    ``fills.sbatch`` and ``runs.sbatch``, their job arrays (each task ``siloflow run <case> -o
    runs/<name> --cache <cache>``); ``submit.sh``, which submits the fills and then the runs
    with ``--dependency=afterok:<fills job>`` (only the fills when every group has one variant);
    the empty ``logs/`` and ``runs/`` folders. Paths inside ``out`` are written relative to it.
    """
    out = Path(out).absolute()
    if not variants:
        raise SetupError("the sweep has no variants")
    _key_of(groups, variants)
    case_files = write_cases(variants, out)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    fills = [members[0] for members in groups.values()]
    runs = sorted((v for members in groups.values() for v in members[1:]), key=lambda v: v.index)
    base = variants[0].name.rsplit("-", 1)[0]
    cache_path = _relative(cache, out)
    arrays = [("fills", fills, f"the fills: one task per fill group ({len(fills)}), each computing a settled "
                               "bed and caching it for the group's other runs"),
              ("runs", runs, f"the other runs ({len(runs)}), each starting from its group's cached bed")]
    for kind, members, what in arrays:
        if not members:
            continue
        write_text(out / f"{kind}.txt", "".join(_relative(case_files[v.name], out) + "\n" for v in members))
        write_text(out / f"{kind}.sbatch", _array_script(f"{base}-{kind}", f"{kind}.txt", members, what, siloflow,
                                                         cache_path))
    submit = out / "submit.sh"
    write_text(submit, _submit_script(len(fills), len(runs)))
    submit.chmod(0o755)
    return submit
