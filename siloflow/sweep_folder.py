"""The sweep folder ``OUT``: its record ``sweep.json`` (the sweep's definition and the SHA-256 of each
file siloflow wrote at its top), the variants' case files ``cases/<name>.yaml``, and what earlier
runs of the sweep left in ``runs/`` and ``logs/``. Nothing in a sweep folder is ever deleted; a file
is replaced only while it holds what siloflow wrote there, and a folder of another sweep is refused.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path
from typing import Optional

import yaml

from .atomic_files import read_json, write_json, write_text
from .errors import ReadError, SetupError
from .sweep_plan import StageProgress, Variant

#: the sweep's record in its folder: its definition and the files siloflow wrote there
RECORD_NAME = "sweep.json"
RECORD_KIND = "siloflow sweep"
#: the line a sweep appends to a run's log when the run ends by itself
EXIT_LINE = re.compile(r"# siloflow sweep: exit code (-?\d+)")
#: how much of a log's end is read for it
LOG_TAIL = 1 << 16


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
        data = read_json(path, "a sweep record", 1 << 24)
    except ReadError:
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


def save_record(out: Path, record: dict) -> None:
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
    save_record(out, record)
    for name, text in texts.items():
        path = out / name
        if not (path.is_file() and not path.is_symlink() and sha256(path) == new[name]):
            write_text(path, text)
    for name, digest in new.items():
        record["files"][name] = [digest]
    save_record(out, record)


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
    check_cases(out, variants)


def check_cases(out: Path, variants: list[Variant]) -> None:
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
        check_cases(Path(out), variants)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for done, v in enumerate(variants, 1):
        paths[v.name] = folder / f"{v.name}.yaml"
        if not paths[v.name].exists():
            write_text(paths[v.name], case_text(v))
        if progress is not None:
            progress("writing", done, len(variants))
    return paths



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

