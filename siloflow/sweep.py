"""Sweeps: one case over ``--set`` values and seeds, run here within a core budget or on Slurm.

A sweep is the cartesian product of the ``--set PATH=V1,V2,...`` values times ``seeds`` seeds
(:func:`expand`); each combination is a :class:`Variant`, a validated case named
``<case>-<index>``. Variants whose settled beds are the same (one
:func:`siloflow.fill_cache.fill_key`) form a fill group (:func:`group_by_fill`): its first
variant computes the fill and publishes it in the fill cache, the others start from it.

:func:`run_sweep` runs the variants here as ``siloflow run`` subprocesses: each group's first
before the rest of its group, in parallel while the engine ranks of the running ones add up to
at most the core budget; it writes the table of results ``sweep.csv`` (:func:`sweep_table`).
Run again on the same folder, it resumes the sweep: finished runs are kept (their results read
into the table), interrupted ones resumed (``siloflow run --resume``), missing ones run.
:func:`write_slurm` writes Slurm job arrays instead (the fills, then the other runs after
them; arrays of at most ``max_array_size`` tasks) and the script that submits them.

A sweep folder ``OUT`` holds ``sweep.json`` (the sweep's definition, :func:`sweep_definition`,
and the SHA-256 of each file siloflow wrote at its top), ``cases/<name>.yaml`` (each variant's
case), ``runs/<name>/`` (its run folder), ``logs/`` (each run's terminal output) and
``sweep.csv``; for Slurm also ``fills.sbatch``, ``runs.sbatch``, ``fills.txt``, ``runs.txt``
(array task -> case file) and ``submit.sh``. Nothing in a sweep folder is ever deleted; a file
is replaced only while it holds what siloflow wrote there, and a folder of another sweep is
refused.
"""
from __future__ import annotations

import copy
import hashlib
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
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import yaml

from .atomic_files import read_regular_bytes, write_json, write_text
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
#: progress(stage, done, total) while a sweep is prepared or written: "planning", "writing"
StageProgress = Callable[[str, int, int], None]
#: the sweep's record in its folder: its definition and the files siloflow wrote there
RECORD_NAME = "sweep.json"
RECORD_KIND = "siloflow sweep"
#: the table of results
TABLE_NAME = "sweep.csv"
#: most tasks of one Slurm job array by default (Slurm's MaxArraySize is 1001 unless raised)
DEFAULT_MAX_ARRAY_SIZE = 1000
#: the case sections that shape the walls' meshes (with the counting disc, siloflow.geometry.silo_meshes)
MESH_SECTIONS = {"geometry", "sensors", "inserts", "particles"}
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


@contextmanager
def _shared_meshes():
    """Within the block, ``derive`` computes the walls of each distinct silo once: it takes
    ``siloflow.geometry.silo_meshes`` when called, here memoised by what shapes the walls (the
    case's :data:`MESH_SECTIONS`, the counting disc and whether the side walls are sensors).
    Most of a plan's time is its meshes, the same for every variant of a silo."""
    from . import geometry as meshes
    original = meshes.silo_meshes
    memo: dict[str, list] = {}

    def shared(case, outlet_z, outlet_radius, sensors=True):
        key = json.dumps([case.model_dump(mode="json", include=MESH_SECTIONS), outlet_z, outlet_radius, sensors],
                         sort_keys=True, default=str)
        if key not in memo:
            memo[key] = original(case, outlet_z, outlet_radius, sensors)
        return list(memo[key])

    meshes.silo_meshes = shared
    try:
        yield
    finally:
        meshes.silo_meshes = original


def _but_name_and_seed(v: Variant) -> str:
    """The variant's case fields without ``name`` and ``seed``, as text: variants that agree on
    it have one plan but for those two (``derive`` only copies them into the plan)."""
    return json.dumps({k: x for k, x in v.data.items() if k not in ("name", "seed")}, sort_keys=True, default=str)


def group_by_fill(variants: list[Variant], engine, progress: Optional[StageProgress] = None) -> dict[str, list[Variant]]:
    """The variants by fill key (``siloflow.fill_cache.fill_key`` of each one's run plan on
    ``engine``), in order of first appearance, each group in variant order. A plan is derived
    once per distinct case but its name and seed (the seeds' plans are copies with theirs), and
    the walls once per distinct silo (:func:`_shared_meshes`). ``progress("planning", done,
    total)`` is told of each variant. Raises the ``CaseError`` of a variant whose plan cannot be
    made, naming its ``--set`` values."""
    from .derived import derive
    from .fill_cache import fill_key
    groups: dict[str, list[Variant]] = {}
    plans: dict[str, object] = {}
    with _shared_meshes():
        for done, v in enumerate(variants, 1):
            same = _but_name_and_seed(v)
            plan = plans.get(same)
            try:
                if plan is None:
                    plan = plans[same] = derive(v.case)
            except CaseError as exc:
                raise _in_variant(exc, v.name, v.values, v.seed) from None
            if (plan.name, plan.seed) != (v.case.name, v.case.seed):
                plan = plan.model_copy(update={"name": v.case.name, "seed": v.case.seed})
            groups.setdefault(fill_key(plan, engine), []).append(v)
            if progress is not None:
                progress("planning", done, len(variants))
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
def _file_digest(path, seen: dict) -> str:
    """``sha256:<hex>`` of a file's bytes (``missing`` when unreadable), once per path."""
    if path not in seen:
        try:
            seen[path] = "sha256:" + hashlib.sha256(Path(str(path)).read_bytes()).hexdigest()
        except (OSError, ValueError):
            seen[path] = "missing"
    return seen[path]


def sweep_definition(variants: list[Variant]) -> str:
    """SHA-256 (hex) of what a sweep runs: each variant's case fields, in order, an insert's
    file by its bytes (a moved case folder is the same sweep, an edited mesh another)."""
    digest, seen = hashlib.sha256(), {}
    for v in variants:
        data = v.data
        if isinstance(data.get("inserts"), list):
            data = {**data, "inserts": [{**ins, "file": _file_digest(ins["file"], seen)}
                                        if isinstance(ins, dict) and "file" in ins else ins for ins in data["inserts"]]}
        digest.update(json.dumps(data, sort_keys=True, default=str).encode() + b"\n")
    return digest.hexdigest()


def _sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _other_sweep(out: Path) -> SetupError:
    return SetupError(f"{out} holds another sweep (its {RECORD_NAME} records other runs: another case, other --set "
                      "values or --seeds): siloflow does not mix two sweeps in one folder; choose another sweep "
                      "folder (-o), or re-run the command that made this one to resume it")


def read_record(out) -> Optional[dict]:
    """The sweep record ``out/sweep.json`` (None if there is none): ``definition``
    (:func:`sweep_definition`), ``runs`` and ``files`` (name -> SHA-256s of what siloflow wrote
    there). ``SetupError`` for a file that is not such a record."""
    path = Path(out) / RECORD_NAME
    if not os.path.lexists(path):
        return None
    try:
        data = json.loads(read_regular_bytes(path, 1 << 24, "a sweep record"))
    except ValueError:
        data = None
    files = data.get("files") if isinstance(data, dict) else None
    if not (isinstance(data, dict) and data.get("kind") == RECORD_KIND and isinstance(data.get("definition"), str)
            and isinstance(files, dict) and all(isinstance(h, list) and all(isinstance(x, str) for x in h)
                                                for h in files.values())):
        raise SetupError(f"{path} is not a sweep record siloflow wrote: move it out of {out}, or choose another "
                         "sweep folder")
    return data


def open_record(out, variants: list[Variant], definition: Optional[str] = None) -> dict:
    """The record of the sweep in ``out``, new (not yet written) if it has none. Raises
    ``SetupError`` for a folder of another sweep."""
    out = Path(out)
    definition = definition or sweep_definition(variants)
    record = read_record(out)
    if record is None:
        return {"kind": RECORD_KIND, "definition": definition, "runs": len(variants), "files": {}}
    if record["definition"] != definition:
        raise _other_sweep(out)
    return record


def _save_record(out: Path, record: dict) -> None:
    write_json(out / RECORD_NAME, {**record, "files": dict(sorted(record["files"].items()))})


def check_owned(out, record: dict, texts: dict[str, Optional[str]]) -> None:
    """Refuse, naming them all, the files of ``texts`` (name in ``out`` -> the text siloflow
    would write, None if not known yet) that exist and hold neither what siloflow last wrote
    there (``record``) nor that text: a file the user edited, or siloflow did not write.
    Raises ``SetupError``."""
    from .run_folder import sha256
    out = Path(out)
    foreign = []
    for name, text in texts.items():
        path = out / name
        if not os.path.lexists(path):
            continue
        if path.is_symlink() or not path.is_file():
            foreign.append(f"{name} (not a regular file)")
            continue
        digest = sha256(path)
        if digest in record["files"].get(name, []) or (text is not None and digest == _sha256_text(text)):
            continue
        foreign.append(f"{name} (edited since siloflow wrote it)" if name in record["files"]
                       else f"{name} (not written by siloflow)")
    if foreign:
        raise SetupError(f"{out} holds {', '.join(foreign)}: siloflow does not overwrite a file it did not write or "
                         "that changed since; nothing was written. Move the file(s) out of the folder (keep your "
                         "changes elsewhere, e.g. an #SBATCH line to add again) and run the sweep again, or choose "
                         "another sweep folder")


def write_owned(out, record: dict, texts: dict[str, str]) -> None:
    """Write ``texts`` (name in ``out`` -> text) atomically after :func:`check_owned` (all
    checked before any is written), recording their SHA-256 in ``record`` (``out/sweep.json``).
    While they are written the record holds the old and the new digest of each, so a write cut
    short leaves files siloflow still knows as its own. An unchanged file is not rewritten."""
    from .run_folder import sha256
    out = Path(out)
    check_owned(out, record, texts)
    new = {name: _sha256_text(text) for name, text in texts.items()}
    for name, digest in new.items():
        record["files"][name] = sorted(set(record["files"].get(name, [])) | {digest})
    _save_record(out, record)
    for name, text in texts.items():
        path = out / name
        if not (path.is_file() and not path.is_symlink() and sha256(path) == new[name]):
            write_text(path, text)
    for name, digest in new.items():
        record["files"][name] = [digest]
    _save_record(out, record)


def check_sweep_folder(out, variants: list[Variant], force: bool, definition: Optional[str] = None) -> None:
    """Refuse a sweep folder that cannot hold this sweep. A folder holding this sweep (its
    ``sweep.json`` records the same :func:`sweep_definition`) is resumed, with or without
    ``force``; one of another sweep is refused. A non-empty folder without a sweep is refused
    unless ``force``, and even then when its ``runs/`` holds a variant's run folder. A case file
    under a variant's name must hold that variant's case. Raises ``SetupError``."""
    out = Path(out)
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise SetupError(f"{out} exists and is not a folder (or is a symbolic link): choose another sweep folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    record = read_record(out)
    if record is not None:
        if record["definition"] != (definition or sweep_definition(variants)):
            raise _other_sweep(out)
    else:
        if not force:
            raise SetupError(f"{out} already exists, is not empty and holds no sweep (no {RECORD_NAME}): choose "
                             "another folder, or pass --force to use it (nothing in it is deleted; existing run "
                             "folders are refused)")
        taken = [v.name for v in variants if os.path.lexists(out / "runs" / v.name)]
        if taken:
            shown = ", ".join(taken[:5]) + (f" and {len(taken) - 5} more" if len(taken) > 5 else "")
            raise SetupError(f"{out / 'runs'} already holds {shown}, made by no sweep siloflow recorded there: "
                             "siloflow never replaces a run; move them out, or choose another sweep folder")
    _check_cases(out, variants)


def _check_cases(out: Path, variants: list[Variant]) -> None:
    """Refuse a ``cases/<name>.yaml`` that holds another case than the variant's (``SetupError``)."""
    for v in variants:
        path = Path(out) / "cases" / f"{v.name}.yaml"
        if os.path.lexists(path) and (path.is_symlink() or not path.is_file()
                                      or path.read_text(errors="replace") != case_text(v)):
            raise SetupError(f"{path} holds another case: siloflow does not overwrite it; move it out, or choose "
                             "another sweep folder")


def case_text(variant: Variant) -> str:
    """The variant's case file (YAML; libyaml's emitter where PyYAML has it: the same text, faster)."""
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(variant.data, Dumper=dumper, sort_keys=False)


def write_cases(variants: list[Variant], out, progress: Optional[StageProgress] = None,
                checked: bool = False) -> dict[str, Path]:
    """Write each variant's case as ``out/cases/<name>.yaml`` (atomically; one already holding
    it is left alone, one holding another case refused before any is written, unless the caller
    ``checked`` them); name -> path. ``progress("writing", done, total)`` is told of each."""
    folder = Path(out) / "cases"
    if not checked:
        _check_cases(Path(out), variants)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for done, v in enumerate(variants, 1):
        paths[v.name] = folder / f"{v.name}.yaml"
        if not paths[v.name].exists():
            write_text(paths[v.name], case_text(v))
        if progress is not None:
            progress("writing", done, len(variants))
    return paths


def prepare_sweep(case_file, set_specs: list[str], seeds: int, out, force: bool = False, need_binary: bool = True,
                  progress: Optional[StageProgress] = None) -> tuple[list[Variant], dict[str, list[Variant]]]:
    """What ``siloflow sweep`` does before it runs or writes anything: read the case, expand the
    ``--set`` specs and seeds, check the sweep folder, the engine and every variant's plan
    (``progress`` as :func:`group_by_fill`). Returns the variants and their fill groups."""
    data = read_case_data(case_file)
    variants = expand(data, [parse_set(spec) for spec in set_specs], seeds)
    check_sweep_folder(out, variants, force)
    engine = sweep_engine(variants, need_binary)
    check_engine(variants, engine)
    return variants, group_by_fill(variants, engine, progress)


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
    the fill to the next. Afterwards the rest of the group may start, from the cached bed.
    A resumed sweep leaves out the ``finished`` runs (name -> exit code; a group with a complete
    one is filled) and lets the ``resuming`` ones (interrupted runs, resumed from their own
    folders) start at once, first."""

    def __init__(self, groups: dict[str, list[Variant]], finished: Optional[dict] = None,
                 resuming: Optional[set] = None):
        finished, resuming = finished or {}, resuming or set()
        self.waiting = {key: [v for v in members if v.name not in finished and v.name not in resuming]
                        for key, members in groups.items()}
        self.resuming = sorted(((key, v) for key, members in groups.items() for v in members if v.name in resuming),
                               key=lambda kv: kv[1].index)
        self.filling: dict[str, str] = {}       # key -> name of the run computing its fill
        self.filled = {key for key, members in groups.items() if any(finished.get(v.name) == 0 for v in members)}

    def ready(self) -> list[tuple[str, Variant]]:
        """(key, variant) that may start: the resumed runs, the fills (group order), then the
        others (variant order)."""
        fills, others = [], []
        for key, members in self.waiting.items():
            if key in self.filled:
                others += [(key, v) for v in members]
            elif members and key not in self.filling:
                fills.append((key, members[0]))
        return list(self.resuming) + fills + sorted(others, key=lambda kv: kv[1].index)

    def started(self, key: str, variant: Variant) -> None:
        for k, (_, v) in enumerate(self.resuming):
            if v.name == variant.name:
                del self.resuming[k]
                return
        self.waiting[key] = [v for v in self.waiting[key] if v.name != variant.name]
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


#: the line a sweep appends to a run's log when the run ends by itself
EXIT_LINE = re.compile(r"# siloflow sweep: exit code (-?\d+)")
#: how much of a log's end is read for it
LOG_TAIL = 1 << 16


def _start(variant: Variant, argv: list[str], out: Path) -> _Job:
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


def logged_exit(log_file: Path) -> Optional[int]:
    """The exit code a sweep logged for the last start of a run (None if that run did not end
    by itself, or there is no log)."""
    try:
        with open(log_file, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - LOG_TAIL))
            tail = fh.read().decode("utf-8", errors="replace")
    except OSError:
        return None
    marks = [line for line in tail.splitlines() if line.startswith("# siloflow sweep")]
    last = EXIT_LINE.fullmatch(marks[-1].strip()) if marks else None
    return int(last.group(1)) if last else None


def previous_runs(out, variants: list[Variant]) -> tuple[dict[str, Optional[int]], set[str]]:
    """What earlier runs of this sweep left in ``out/runs``: the finished runs (name -> exit
    code: the logged one, else 0 for a complete run and None for a failed one) and the names of
    the interrupted ones to resume (interrupted, abandoned, or rendered and never started).
    Raises ``SetupError``, naming them, for run folders still running or not made by siloflow."""
    from .run_folder import run_state
    out = Path(out)
    finished, resuming, problems = {}, set(), []
    for v in variants:
        folder = out / "runs" / v.name
        if not os.path.lexists(folder):
            continue
        if folder.is_symlink() or not folder.is_dir():
            problems.append(f"{v.name} (not a folder)")
            continue
        try:
            state = run_state(folder)
        except ReadError:
            problems.append(f"{v.name} (no siloflow run: no readable status)")
            continue
        if state["state"] == "running":
            problems.append(f"{v.name} (still running{': ' + state['reason'] if state.get('reason') else ''})")
        elif state["state"] in ("complete", "failed"):
            code = logged_exit(out / "logs" / f"{v.name}.log")
            finished[v.name] = code if code is not None else (0 if state["state"] == "complete" else None)
        else:
            resuming.add(v.name)
    if problems:
        shown = ", ".join(problems[:5]) + (f" and {len(problems) - 5} more" if len(problems) > 5 else "")
        raise SetupError(f"{out / 'runs'} holds run folders this sweep cannot resume: {shown}. Stop a run still "
                         "running (another sweep?) first; move the others out of the folder; then run the sweep "
                         "again")
    return finished, resuming


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
    this Python), its output appended to ``out/logs/<name>.log``. A fill group's first variant
    runs before the rest of its group, which then starts from its cached bed; runs go in
    parallel while their ``engine.ranks`` add up to at most ``cores``. A failed run does not
    stop the others. ``groups`` are the fill groups (:func:`group_by_fill`; default: with the
    cases' engine). ``progress(done, total, running_names)`` is told of every change.

    Resuming: on a folder of this sweep (``sweep.json``) the runs already finished are kept and
    read into the table, interrupted ones are resumed as ``command + ["--resume", run folder]``
    and the others run. Ctrl-C (``KeyboardInterrupt``) stops the running runs (each marks its
    folder interrupted), writes ``sweep.csv`` of the runs finished so far (the others
    ``unfinished``) and is raised again: calling this again resumes the sweep.

    Raises
    ------
    SetupError
        before anything runs: for a folder of another sweep, a run needing more ranks than
        ``cores``, run folders that are running or not siloflow's, a ``sweep.csv`` siloflow did
        not write; or a command that cannot be started.
    """
    out = Path(out).absolute()
    cache = Path(cache).absolute()
    check_cores(variants, cores)
    if groups is None:
        groups = group_by_fill(variants, sweep_engine(variants))
    keys = _key_of(groups, variants)
    record = open_record(out, variants)
    check_owned(out, record, {TABLE_NAME: None})
    finished, resuming = previous_runs(out, variants)
    _check_cases(out, variants)
    out.mkdir(parents=True, exist_ok=True)
    _save_record(out, record)
    case_files = write_cases(variants, out, checked=True)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    command = list(command or default_command())
    order = _FillOrder(groups, finished, resuming)
    running: dict[str, _Job] = {}
    returncodes: dict[str, Optional[int]] = dict(finished)
    changed = True
    try:
        while len(returncodes) < len(variants):
            for name, job in list(running.items()):
                code = job.process.poll()
                if code is not None:
                    job.log.write(f"# siloflow sweep: exit code {code}\n")
                    job.log.close()
                    del running[name]
                    returncodes[name] = code
                    order.finished(keys[name], job.variant, code == 0)
                    changed = True
            free = cores - sum(job.variant.case.engine.ranks for job in running.values())
            for key, v in order.ready():
                if v.case.engine.ranks <= free:
                    folder = out / "runs" / v.name
                    argv = ([*command, "--resume", str(folder)] if v.name in resuming else
                            [*command, str(case_files[v.name]), "-o", str(folder), "--cache", str(cache)])
                    running[v.name] = _start(v, argv, out)
                    order.started(key, v)
                    free -= v.case.engine.ranks
                    changed = True
            if changed and progress is not None:
                progress(len(returncodes), len(variants), sorted(running))
            changed = False
            if len(returncodes) < len(variants):
                time.sleep(POLL_INTERVAL)
    except BaseException as exc:               # Ctrl-C, or a run that could not start
        _stop(list(running.values()))
        if isinstance(exc, KeyboardInterrupt):
            try:                               # the runs finished so far; the sweep resumes from its folders
                write_owned(out, record, {TABLE_NAME: sweep_table(variants, out, keys, returncodes).to_csv(index=False)})
            except (OSError, SetupError, ReadError):
                pass
        raise
    finally:
        for job in running.values():
            job.log.close()
    table = sweep_table(variants, out, keys, returncodes)
    write_owned(out, record, {TABLE_NAME: table.to_csv(index=False)})
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


def sweep_table(variants: list[Variant], out: Path, keys: dict[str, str], returncodes: dict[str, Optional[int]]):
    """One row per variant: ``run`` (its run folder), ``name``, each ``--set`` path, ``seed``,
    ``fill_key`` (first 12 hex digits), ``fill_from_cache`` (the run record's ``fill_cache``
    hit, None if unknown), ``status`` (complete: exit code 0; failed: another or an unknown
    one; unfinished: not in ``returncodes``, the sweep was stopped first), ``returncode``,
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
               "fill_key": keys[v.name][:12], "returncode": code,
               "status": "complete" if code == 0 else "failed" if v.name in returncodes else "unfinished",
               "log": str(out / "logs" / f"{v.name}.log")}
        rows.append({**row, **_results(folder)})
    return pd.DataFrame(rows, columns=[*TABLE_HEAD, *paths, *TABLE_TAIL])


def table_summary(table) -> dict:
    """Counts of a sweep table: runs ``complete``, ``failed`` and ``unfinished``, fills
    ``computed`` (runs that made their bed) and ``reused`` (runs that started from a cached one)."""
    fills = table["fill_from_cache"].map({True: "reused", False: "computed"})
    return {**{status: int((table["status"] == status).sum()) for status in ("complete", "failed", "unfinished")},
            "computed": int((fills == "computed").sum()), "reused": int((fills == "reused").sum())}


# ------------------------------------------------------------------ Slurm
def _relative(path: Path, out: Path) -> str:
    """``path`` relative to the sweep folder when inside it (the folder can move to a cluster)."""
    path = Path(path).absolute()
    return path.relative_to(out).as_posix() if out in path.parents else str(path)


def _array_script(job_name: str, tasks: str, variants: list[Variant], what: str, siloflow: str, cache: str,
                  max_array_size: int) -> str:
    """A job array script: task k of an array submitted with offset o (the script's argument,
    default 0) runs ``siloflow run`` on the case file on line o + k + 1 of ``tasks``."""
    ranks = max(v.case.engine.ranks for v in variants)
    arrays = math.ceil(len(variants) / max_array_size)
    run = f"{shlex.quote(siloflow)} run \"$case_file\" -o \"runs/$name\" --cache {shlex.quote(cache)}"
    return f"""#!/bin/bash
# siloflow sweep: {what}
# One array task per line of {tasks}: task k of an array submitted with offset o (this script's
# argument, default 0) runs the case file on line o + k + 1, in the sweep folder (submit.sh
# submits from there). Slurm's MaxArraySize (1001 by default) bounds an array's task indices, so
# submit.sh submits {len(variants)} tasks as {arrays} array(s) of at most {max_array_size} tasks
# (siloflow sweep --max-array-size); #SBATCH --array below is the first.
# siloflow starts the engine itself (mpirun -np <engine.ranks>) inside the task's allocation, so a
# task is one node with one Slurm task per MPI rank, one CPU each: --ntasks = --ntasks-per-node =
# the largest engine.ranks of these cases ({ranks}), --cpus-per-task=1. Open MPI's mpirun takes its
# slots from the allocation; srun is not used. The fill cache must be on a file system every node sees.
#SBATCH --job-name={job_name}
#SBATCH --array=0-{min(len(variants), max_array_size) - 1}
#SBATCH --nodes=1
#SBATCH --ntasks={ranks}
#SBATCH --ntasks-per-node={ranks}
#SBATCH --cpus-per-task=1
#SBATCH --output=logs/%x-%A_%a.out
set -euo pipefail
offset=${{1:-0}}
case $offset in
    ''|*[!0-9]*) echo "the offset into {tasks} must be a whole number, not '$offset'" >&2; exit 1 ;;
esac
line=$((offset + SLURM_ARRAY_TASK_ID + 1))
case_file=$(sed -n "${{line}}p" {tasks})
if [ -z "$case_file" ]; then
    echo "no case file on line $line of {tasks}" >&2
    exit 1
fi
name=$(basename "$case_file" .yaml)
export COLUMNS=200
exec {run}
"""


def _arrays(count: int, size: int) -> list[tuple[int, int]]:
    """(offset, tasks) of the arrays that cover ``count`` lines, at most ``size`` tasks each."""
    return [(start, min(size, count - start)) for start in range(0, count, size)]


def _submit_script(fills: list[tuple[int, int]], runs: list[tuple[int, int, list[int]]]) -> str:
    """``fills``: (offset, tasks) of each fills array; ``runs``: (offset, tasks, the fills
    arrays holding its runs' fills) of each runs array."""
    lines = ["#!/bin/bash",
             "# Submit the sweep: the fills (one per distinct settled bed), then the other runs, each array",
             "# of them once every fills array holding their fills succeeded (afterok), so they start from",
             "# the cached beds. Each array is at most --max-array-size tasks; its argument is its offset",
             "# into fills.txt or runs.txt. If a fill fails, the runs after it stay pending",
             "# (DependencyNeverSatisfied): scancel them, fix the case, submit again.",
             "set -euo pipefail",
             'cd "$(dirname "$0")"']

    def submit(kind: str, k: int, total: int, offset: int, tasks: int, options: str, after: str) -> list[str]:
        var = f"{kind}_{k}"
        return [f"{var}=$(sbatch --parsable --array=0-{tasks - 1}{options} {kind}.sbatch {offset})",
                f"{var}=${{{var}%%;*}}                 # --parsable prints jobid[;cluster]",
                f'echo "{kind} {k + 1}/{total}: job ${var} ({tasks} task{"s" if tasks != 1 else ""}, lines '
                f'{offset + 1}-{offset + tasks} of {kind}.txt{after})"']

    for k, (offset, tasks) in enumerate(fills):
        lines += submit("fills", k, len(fills), offset, tasks, "", "")
    for k, (offset, tasks, needs) in enumerate(runs):
        jobs = ":".join(f'"$fills_{j}"' for j in needs)
        shown = ", ".join(f"$fills_{j}" for j in needs)
        lines += submit("runs", k, len(runs), offset, tasks, f" --dependency=afterok:{jobs}", f", after job(s) {shown}")
    return "\n".join(lines) + "\n"


def write_slurm(variants: list[Variant], groups: dict[str, list[Variant]], out: Path, cache: Path,
                siloflow: str = "siloflow", max_array_size: int = DEFAULT_MAX_ARRAY_SIZE,
                progress: Optional[StageProgress] = None) -> Path:
    """Write the sweep as Slurm job arrays instead of running it; return ``out/submit.sh``.

    Writes ``out/cases/*.yaml`` (``progress`` as :func:`write_cases`); ``fills.txt`` (the first
    variant of each fill group) and ``runs.txt`` (the others), one case file per line;
    ``fills.sbatch`` and ``runs.sbatch``, their job array scripts (each task ``siloflow run
    <case> -o runs/<name> --cache <cache>``); ``submit.sh``, which submits the fills as arrays of
    at most ``max_array_size`` tasks, each with its offset into ``fills.txt``, then the runs
    likewise, each runs array with ``--dependency=afterok:`` the fills arrays holding its runs'
    fills (only the fills when every group has one variant); the empty ``logs/`` and ``runs/``
    folders. Paths inside ``out`` are written relative to it. A file siloflow wrote is replaced
    only while unchanged (:func:`write_owned`); ``SetupError`` for a folder of another sweep, a
    file edited or not siloflow's (before anything is written), or ``max_array_size`` < 1.
    """
    out = Path(out).absolute()
    if not variants:
        raise SetupError("the sweep has no variants")
    if isinstance(max_array_size, bool) or not isinstance(max_array_size, int) or max_array_size < 1:
        raise SetupError(f"--max-array-size {max_array_size!r}: the tasks of one job array must be a whole number >= 1")
    keys = _key_of(groups, variants)
    record = open_record(out, variants)
    fills = [members[0] for members in groups.values()]
    runs = sorted((v for members in groups.values() for v in members[1:]), key=lambda v: v.index)
    fill_line = {v.name: k for k, v in enumerate(fills)}
    first_of = {key: members[0].name for key, members in groups.items()}
    base = variants[0].name.rsplit("-", 1)[0]
    cache_path = _relative(cache, out)
    texts = {}
    for kind, members, what in [
            ("fills", fills, f"the fills: one task per fill group ({len(fills)}), each computing a settled bed and "
                             "caching it for the group's other runs"),
            ("runs", runs, f"the other runs ({len(runs)}), each starting from its group's cached bed")]:
        if members:
            texts[f"{kind}.txt"] = "".join(f"cases/{v.name}.yaml\n" for v in members)
            texts[f"{kind}.sbatch"] = _array_script(f"{base}-{kind}", f"{kind}.txt", members, what, siloflow,
                                                    cache_path, max_array_size)
    run_arrays = [(offset, tasks, sorted({fill_line[first_of[keys[v.name]]] // max_array_size
                                          for v in runs[offset:offset + tasks]}))
                  for offset, tasks in _arrays(len(runs), max_array_size)]
    texts["submit.sh"] = _submit_script(_arrays(len(fills), max_array_size), run_arrays)
    check_owned(out, record, texts)             # everything checked before anything is written
    _check_cases(out, variants)
    out.mkdir(parents=True, exist_ok=True)
    _save_record(out, record)
    write_cases(variants, out, progress, checked=True)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_owned(out, record, texts)
    submit = out / "submit.sh"
    submit.chmod(0o755)
    return submit
