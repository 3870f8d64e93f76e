"""Deck folders: complete, deterministic, atomic, and closed to injection."""
from __future__ import annotations

import math

import pytest

from siloflow.case_file import case_from_dict
from siloflow.deck import DeckError, _num, _safe_name
from siloflow.engine.liggghts.deck import check_deck
from siloflow.errors import CaseError, SetupError
from siloflow.run_folder import RunFolder

from conftest import render


def test_deck_folder_is_complete_and_deterministic(quick_dict, tmp_path):
    case = case_from_dict(quick_dict)
    a, b = render(case, tmp_path / "a"), render(case, tmp_path / "b")
    deck = (a / "in.liggghts").read_text()
    assert deck == (b / "in.liggghts").read_text()
    plan = RunFolder(a).plan
    assert plan.walls
    for w in plan.walls:
        assert (a / w.file).is_file()
        assert (a / w.file).read_bytes() == (b / w.file).read_bytes()
        if w.role != "outlet":
            assert f"meshes {w.name}" in deck or f" {w.name}" in deck.split("n_meshes")[1]
    # the placed fill: every grain in one of the batch files the deck reads, the same bytes each time
    batches = sorted((a / "fill").iterdir())
    assert [f"read_dump       fill/{p.name}" in deck for p in batches] == [True] * len(batches)
    assert sum(int(p.read_text().splitlines()[3]) for p in batches) == plan.fill.count
    assert all(p.read_bytes() == (b / "fill" / p.name).read_bytes() for p in batches)
    assert f"timestep        {plan.dt:.10g}" in deck
    assert "delete_atoms yes" in deck and "move/mesh mesh plate" in deck
    assert (a / "case.yaml").is_file()


def test_existing_folder_is_never_overwritten_silently(quick_dict, tmp_path):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    marker = folder / "keep.txt"
    marker.write_text("user data")
    with pytest.raises(SetupError, match="--force"):
        render(case, folder)
    assert marker.read_text() == "user data"
    with pytest.raises(SetupError, match="did not write"):      # --force never deletes a user's file
        render(case, folder, force=True)
    assert marker.read_text() == "user data"
    marker.unlink()
    render(case, folder, force=True)
    assert (folder / "in.liggghts").is_file()


def test_failed_render_leaves_nothing(quick_dict, tmp_path):
    quick_dict["fill"]["count"] = 60000        # valid on its own, but the bed would reach the top
    case = case_from_dict(quick_dict)
    with pytest.raises(CaseError, match="no room to insert"):
        render(case, tmp_path / "deck")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("line", ["shell rm -rf /", "include evil.in", "variable x python f",
                                  "fix 1 all print 1 'x' # shell ls", "python f input 1"])
def test_deck_check_refuses_foreign_commands(line):
    with pytest.raises(DeckError):
        check_deck(f"units si\n{line}\n")


def test_filters_refuse_unsafe_values():
    for bad in (math.nan, math.inf, "1", True, None):
        with pytest.raises(DeckError):
            _num(bad)
    for bad in ("a b", "x\nshell", "", "$(x)", "a;b"):
        with pytest.raises(DeckError):
            _safe_name(bad)
    assert _num(2.5e-5) == "2.5e-05" and _safe_name("band00_s01") == "band00_s01"


def test_injection_in_any_string_field_never_reaches_a_deck(quick_dict, tmp_path):
    """The only free-text field (description) is never rendered; names are alphabet-checked."""
    quick_dict["description"] = "x\nshell touch pwned\n"
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "deck")
    assert "pwned" not in (folder / "in.liggghts").read_text()
    check_deck((folder / "in.liggghts").read_text())
