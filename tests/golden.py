"""Golden decks: what every shipped case renders, committed under tests/golden/.

``golden_files(case_file)`` renders a case the way ``siloflow render`` does and returns the
files a change must not alter by accident: ``in.liggghts``, the resumed deck
``in.resume.liggghts`` and the SHA-256 of every mesh. ``tests/test_golden_decks.py`` compares
them with the committed copies; ``make golden`` (``python tests/golden.py``) rewrites the
copies through this same function, for a change that alters decks on purpose (commit the new
goldens with it, as LAMMPS' force-style tests do).
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden"
#: every case the repository ships: the papers' decks and the test cases
CASES = sorted([*(ROOT / "decks").glob("*.yaml"), *(ROOT / "tests" / "data").glob("*.yaml")])


def golden_files(case_file: Path) -> dict[str, bytes]:
    """{file name: bytes} of what ``case_file`` renders: both decks, the meshes' SHA-256
    and, for spheres, the placed fill batches' SHA-256."""
    from siloflow.case_file import load_case
    from siloflow.derived import derive
    from siloflow.engine import get_engine
    from siloflow.engine.liggghts.deck import write_resume_deck
    from siloflow.run_folder import sha256

    with tempfile.TemporaryDirectory(prefix="siloflow-golden-") as scratch:
        case = load_case(case_file)
        plan = derive(case)
        folder = get_engine(case.engine.name).prepare(case, Path(scratch) / "deck", plan=plan)
        write_resume_deck(plan, case, folder)
        meshes = "".join(f"{sha256(p)}  {p.name}\n" for p in sorted((folder / "meshes").glob("*.stl")))
        out = {"in.liggghts": (folder / "in.liggghts").read_bytes(),
               "in.resume.liggghts": (folder / "in.resume.liggghts").read_bytes(),
               "meshes.sha256": meshes.encode()}
        if (folder / "fill").is_dir():          # spheres: the placed fill's batches (siloflow.fill_placement)
            out["fill.sha256"] = "".join(f"{sha256(p)}  {p.name}\n"
                                         for p in sorted((folder / "fill").glob("*.txt"))).encode()
        return out


def golden_folder(case_file: Path) -> Path:
    """Where the goldens of ``case_file`` live: tests/golden/<folder>-<case name>/."""
    return GOLDEN / f"{case_file.parent.name}-{case_file.stem}"


def main() -> None:
    """Rewrite every golden (``make golden``)."""
    sys.path.insert(0, str(ROOT))
    for case_file in CASES:
        out = golden_folder(case_file)
        out.mkdir(parents=True, exist_ok=True)
        for name, data in golden_files(case_file).items():
            (out / name).write_bytes(data)
        print(f"golden: {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
