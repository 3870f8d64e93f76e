"""Every shipped case renders, in each engine, exactly its committed goldens: plan, decks, meshes
(tests/golden.py; ``make golden`` regenerates them for a change that alters decks on purpose)."""
from __future__ import annotations

import pytest

from golden import CASES, ENGINES, GOLDEN, golden_files, golden_folder, golden_names


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("case_file", CASES, ids=[f"{c.parent.name}/{c.name}" for c in CASES])
def test_case_renders_its_golden_deck(case_file, engine):
    folder = golden_folder(case_file, engine)
    where = folder.relative_to(GOLDEN.parent)
    files = golden_files(case_file, engine)
    if isinstance(files, str):
        assert not folder.is_dir(), f"{engine} refuses {case_file.name}, yet {where} holds goldens: run 'make golden'"
        pytest.skip(f"{engine} refuses {case_file.name}: {files}")
    assert golden_names(folder) == sorted(files), (f"{where} holds {golden_names(folder)}, {case_file.name} renders "
                                                   f"{sorted(files)}: run 'make golden' and commit tests/golden/")
    for name, data in files.items():
        assert data == (folder / name).read_bytes(), (f"{case_file.name}: {name} differs from {where}/{name}; if the "
                                                      "change is meant, run 'make golden' and commit the new goldens")


def test_every_golden_belongs_to_a_shipped_case():
    assert sorted(p.name for p in GOLDEN.iterdir() if p.is_dir()) == sorted(golden_folder(c).name for c in CASES)
    for folder in GOLDEN.iterdir():
        assert sorted(p.name for p in folder.iterdir() if p.is_dir()) in ([], ["lammps"]), folder
