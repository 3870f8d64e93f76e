"""A stage run in chunks follows the trajectory of one run (docs/engine_facts.md).

siloflow's LIGGGHTS decks run their stages in chunks: the fill one ``run`` per placed batch, the
settle stage one per check interval, the discharge one per chunk, and each stage a ``run`` of its own. LIGGGHTS sets a run up
anew at each ``run`` (neighbour lists, the walls' contact histories), so the chunks are only harmless
if every contact's history survives the set-up. It does at LIGGGHTS' default neighbour page; with
a page of 20000 the trajectory jumps at a run boundary, as if contact histories were dropped
there (which ones, pair or wall, is not isolated; pages of 5000-99999 gave the same jump, 100000
none), while one run at that page follows the default's. That page is also what each mesh wall's
contact history zeroes once a step (``FixContactHistoryMesh::markAllContacts``: 27 % of a step on
the accuracy case, measured with perf), so a smaller page would make the accuracy case's runs 30 %
faster, and siloflow leaves it alone: the tests check that the decks never set it, that chunks at
the default page keep the trajectory, and the engine fact that a smaller page breaks it.
"""
from __future__ import annotations

import re
import subprocess

import pytest
import yaml

from siloflow.engine import LiggghtsEngine
from siloflow.engine.liggghts.deck import before_stage_run

from conftest import ROOT, needs_liggghts, render_deck

CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"
#: steps compared after the boundary, the fill's end (its last batch's run: the bed lies on the plate
#: and against the walls, still settling)
AFTER = 34
NEIGH_MODIFY = re.compile(r"^neigh_modify.*$", re.M)


@pytest.fixture(scope="module")
def fill_deck(tmp_path_factory):
    """The accuracy case's rendered deck up to its last placed batch's ``run`` (left out), at pinned
    settings (dt = 0.1 t_c, 1/100 of the stiffness), its folder (meshes, fill batches, output
    folders), the step that batch is read at and the steps of its run (to the fill's end)."""
    tmp = tmp_path_factory.mktemp("chunks")
    data = yaml.safe_load(CASE.read_text())
    data.update(name="chunks", engine={"ranks": 2, "timestep_fraction": 0.1, "stiffness_scale": 0.01})
    folder = tmp / "deck"
    text = render_deck(data, folder)
    last = text.rindex("\nread_dump ")
    run = text.index("\nrun ", last)
    steps = int(text[run:].split()[1])
    return folder, text[:run + 1], int(text[last:].split()[2]), steps


def _state(folder, head: str, name: str, start: int, runs: list[int], page: int | None = None
           ) -> tuple[float, float]:
    """Kinetic energy (J) and deepest pair overlap (m) after ``runs`` (steps of each ``run``) from
    step ``start`` (the head's end), from the last thermo line (LIGGGHTS prints one at the end of
    every run). ``page`` sets the neighbour page for the whole deck."""
    if page is not None:
        head = NEIGH_MODIFY.sub(f"neigh_modify    delay 0 page {page}", head, count=1)
    (folder / f"{name}.in").write_text(head + "".join(f"run {n}\n" for n in runs))
    subprocess.run(LiggghtsEngine().command(2, deck=f"{name}.in", log=f"{name}.log"), cwd=folder, check=True,
                   capture_output=True)
    step = str(start + sum(runs))
    last = [line.split() for line in (folder / f"{name}.log").read_text().splitlines()
            if line.split()[:1] == [step]][-1]
    # thermo_style custom step time atoms c_ke c_pe c_mass_silo f_massflow[1] f_massflow[2]
    # c_guard_speed c_guard_overlap c_guard_out (templates/liggghts/in.liggghts.j2)
    return float(last[3]), float(last[9])


def test_decks_leave_the_neighbour_page_at_its_default(fill_deck):
    _, head, _, _ = fill_deck
    lines = NEIGH_MODIFY.findall(head)
    assert lines and not any(re.search(r"\b(page|one)\b", line) for line in lines)


@needs_liggghts
def test_chunks_follow_one_run_at_the_default_page_and_not_at_another(fill_deck):
    folder, head, start, fill = fill_deck
    ke_one, overlap_one = _state(folder, head, "one", start, [fill + AFTER])
    ke_chunks, overlap_chunks = _state(folder, head, "chunks", start, [fill, AFTER])
    assert overlap_one > 0.0 and ke_one > 0.0            # a bed in contact, still settling
    # the same trajectory, to what the set-up's new summation order leaves (1e-5, 1e-6 measured)
    assert ke_chunks == pytest.approx(ke_one, rel=1e-4)
    assert overlap_chunks == pytest.approx(overlap_one, rel=1e-4)
    # the engine fact: at a page of 20000 the trajectory jumps at a run boundary (0.6 % in kinetic
    # energy and 6 % in the deepest overlap 34 steps on, measured with an inserted fill)
    ke_small_page_one, _ = _state(folder, head, "one_page", start, [fill + AFTER], page=20000)
    ke_small_page, _ = _state(folder, head, "chunks_page", start, [fill, AFTER], page=20000)
    assert abs(ke_small_page / ke_small_page_one - 1.0) > 1e-3
