"""Golden decks: what every shipped case renders, in each engine, committed under tests/golden/.

``golden_files(case_file, engine)`` renders a case the way ``siloflow render`` does with that engine
and returns the files a change must not alter by accident: the run plan ``plan.json``, the decks
(LIGGGHTS: ``in.liggghts`` and the resumed deck ``in.resume.liggghts``; LAMMPS: ``in.lammps`` and
its clumps' molecule files), the SHA-256 of every mesh and, for spheres in LIGGGHTS, of the placed
fill's batches. LIGGGHTS' goldens are in tests/golden/<folder>-<case>/, LAMMPS' in its ``lammps/``;
a case an engine refuses (``Engine.check``) has none there. ``tests/test_golden_decks.py`` compares
them with the committed copies; ``make golden`` (``python tests/golden.py``) rewrites the copies
through this same function, for a change that alters decks on purpose (commit the new goldens with
it, as LAMMPS' force-style tests do).
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path
from unittest import mock

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden"
#: every case the repository ships: the papers' decks and the test cases
CASES = sorted([*(ROOT / "decks").glob("*.yaml"), *(ROOT / "tests" / "data").glob("*.yaml")])
ENGINES = ("liggghts", "lammps")
#: what each engine's run folder holds that a golden keeps as it is (beside plan.json)
DECKS = {"liggghts": ["in.liggghts", "in.resume.liggghts"], "lammps": ["in.lammps", "*.mol"]}


def golden_files(case_file: Path, engine: str = "liggghts") -> dict[str, bytes] | str:
    """{file name: bytes} of what ``engine`` renders of ``case_file`` (the case with its
    ``engine.name`` set to it): the plan, the decks, the meshes' SHA-256 and, where written, the
    placed fill batches' SHA-256; or, for a case the engine refuses, the reason."""
    from siloflow.case_file import load_case
    from siloflow.derived import derive
    from siloflow.engine import get_engine
    from siloflow.engine.liggghts.deck import write_resume_deck
    from siloflow.run_folder import sha256

    case = load_case(case_file)
    case = case.model_copy(update={"engine": case.engine.model_copy(update={"name": engine})})
    plan = derive(case)
    renderer = get_engine(engine)
    # a golden is this repository's, not this machine's: as many cores as the case has ranks
    with mock.patch.object(os, "cpu_count", lambda: case.engine.ranks):
        problems = renderer.check(case, plan)
        if problems:
            return "; ".join(f"{field}: {message}" for field, message in problems)
        with tempfile.TemporaryDirectory(prefix="siloflow-golden-") as scratch:
            folder = renderer.prepare(case, Path(scratch) / "deck", plan=plan)
            if engine == "liggghts":
                write_resume_deck(plan, folder)
            out = {p.name: p.read_bytes() for pattern in ["plan.json", *DECKS[engine]] for p in sorted(folder.glob(pattern))}
            for name, sub, pattern in (("meshes.sha256", "meshes", "*.stl"), ("fill.sha256", "fill", "*.txt")):
                if (folder / sub).is_dir():      # fill/: spheres' placed batches (siloflow.fill_placement)
                    out[name] = "".join(f"{sha256(p)}  {p.name}\n" for p in sorted((folder / sub).glob(pattern))).encode()
            return out


def golden_folder(case_file: Path, engine: str = "liggghts") -> Path:
    """Where the goldens of ``case_file`` live: tests/golden/<folder>-<case name>/, LAMMPS' in its lammps/."""
    folder = GOLDEN / f"{case_file.parent.name}-{case_file.stem}"
    return folder if engine == "liggghts" else folder / engine


def golden_names(folder: Path) -> list[str]:
    """The files of a golden folder (not its engine subfolders)."""
    return sorted(p.name for p in folder.iterdir() if p.is_file()) if folder.is_dir() else []


def main() -> None:
    """Rewrite every golden (``make golden``): each engine's files, none for a case it refuses."""
    sys.path.insert(0, str(ROOT))
    for case_file in CASES:
        for engine in ENGINES:
            out, files = golden_folder(case_file, engine), golden_files(case_file, engine)
            if isinstance(files, str):
                if out.is_dir():
                    shutil.rmtree(out)
                print(f"golden: {engine} refuses {case_file.name}: {files}")
                continue
            out.mkdir(parents=True, exist_ok=True)
            for name in set(golden_names(out)) - set(files):
                (out / name).unlink()
            for name, data in files.items():
                (out / name).write_bytes(data)
            print(f"golden: {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
