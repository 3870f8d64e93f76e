"""Every shipped case renders exactly its committed golden deck (tests/golden.py; ``make golden``
regenerates them for a change that alters decks on purpose)."""
from __future__ import annotations

import pytest

from golden import CASES, golden_files, golden_folder


@pytest.mark.parametrize("case_file", CASES, ids=[f"{c.parent.name}/{c.name}" for c in CASES])
def test_case_renders_its_golden_deck(case_file):
    folder = golden_folder(case_file)
    assert folder.is_dir(), f"no golden for {case_file.name}: run 'make golden' and commit tests/golden/"
    for name, data in golden_files(case_file).items():
        expected = (folder / name).read_bytes()
        assert data == expected, (f"{case_file.name}: {name} differs from tests/golden/{folder.name}/{name}; "
                                  "if the change is meant, run 'make golden' and commit the new goldens")


def test_every_golden_belongs_to_a_shipped_case():
    from golden import GOLDEN
    assert sorted(p.name for p in GOLDEN.iterdir() if p.is_dir()) == sorted(golden_folder(c).name for c in CASES)
