"""Walls from the user's STL files (``inserts``): read as meshes, checked, written anew; never
pasted into the deck; a bad file is refused naming the insert."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
import yaml
from stl import Mode
from stl import mesh as stl_mesh

from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.errors import CaseError
from siloflow.geometry import rectangle
from siloflow.run_folder import RunFolder

from conftest import ROOT, render

SLAB = ROOT / "tests" / "data" / "slab_silo.yaml"


def write_user_stl(path, tris, mode=Mode.ASCII, name="baffle"):
    m = stl_mesh.Mesh(np.zeros(len(tris), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = tris
    m.update_normals()
    with open(path, "wb") as fh:
        m.save(name, fh=fh, mode=mode)
    return path


def baffle(scale: float = 1.0) -> np.ndarray:
    """A horizontal plate through the slab's thickness, 20 mm wide at z = 30 mm (in 1/scale units)."""
    return rectangle((-0.01, -0.00137, 0.03), (0.02, 0.0, 0.0), (0.0, 0.00274, 0.0), 2, 1) / scale


def slab_case_with(tmp_path, file: str, scale: float = 1.0):
    data = yaml.safe_load(SLAB.read_text())
    data["inserts"] = [{"name": "baffle", "file": file, "scale": scale}]
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("mode", [Mode.ASCII, Mode.BINARY])
def test_insert_is_read_checked_and_written_anew(tmp_path, mode):
    (tmp_path / "shapes").mkdir()
    # millimetres, a hostile solid name: neither may reach the deck as written
    write_user_stl(tmp_path / "shapes" / "b.stl", baffle(scale=1e-3), mode, name="shell rm -rf")
    case = load_case(slab_case_with(tmp_path, "shapes/b.stl", scale=1e-3))   # relative to the case file
    folder = render(case, tmp_path / "deck")
    deck = (folder / "in.liggghts").read_text()
    assert "file meshes/insert_baffle.stl" in deck and "insert_baffle" in deck.split("mesh n_meshes")[1]
    assert "rm -rf" not in deck and "shapes" not in deck
    written = stl_mesh.Mesh.from_file(str(folder / "meshes" / "insert_baffle.stl"))
    np.testing.assert_allclose(np.sort(written.vectors.reshape(-1, 3), axis=0),
                               np.sort(baffle().reshape(-1, 3), axis=0), atol=1e-9)
    assert b"rm -rf" not in (folder / "meshes" / "insert_baffle.stl").read_bytes()
    # the run folder is self-contained: its case names the copy, in metres
    stored = load_case(folder / "case.yaml")
    assert stored.inserts[0].file == str((folder / "meshes" / "insert_baffle.stl").resolve())
    assert stored.inserts[0].scale == 1.0
    walls = RunFolder(folder).plan.walls
    assert any(w.name == "insert_baffle" and w.role == "insert" for w in walls)


def _refused(tmp_path, tris=None, raw: bytes | None = None, scale: float = 1.0) -> str:
    path = tmp_path / "bad.stl"
    if raw is not None:
        path.write_bytes(raw)
    else:
        write_user_stl(path, tris)
    case = load_case(slab_case_with(tmp_path, str(path), scale))     # the file is read when the walls are made
    with pytest.raises(CaseError) as info:
        derive(case)
    (field, message), = info.value.problems
    assert field == "inserts[0].file"
    return message


def test_bad_insert_files_are_refused_naming_the_insert(tmp_path):
    tris = baffle()
    nan = tris.copy()
    nan[0, 0, 0] = np.nan
    assert "non-finite" in _refused(tmp_path, nan)
    flat = tris.copy()
    flat[1, 2] = flat[1, 1]                                  # two equal vertices: zero area
    assert "degenerate" in _refused(tmp_path, flat)
    assert "not an STL file" in _refused(tmp_path, raw=np.random.default_rng(1).bytes(5000))
    assert "no triangles" in _refused(tmp_path, raw=b"solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0\n")
    assert "outside the silo" in _refused(tmp_path, tris, scale=10.0)
    with pytest.raises(CaseError, match="cannot read") as info:
        derive(load_case(slab_case_with(tmp_path, "missing.stl")))
    assert [field for field, _ in info.value.problems] == ["inserts[0].file"]


def test_an_insert_that_is_a_fifo_is_refused_not_read(tmp_path):
    """A FIFO named as an insert hung siloflow validate (it waited for a writer)."""
    import os
    os.mkfifo(tmp_path / "pipe.stl")
    with pytest.raises(CaseError, match="FIFO") as info:
        derive(load_case(slab_case_with(tmp_path, "pipe.stl")))
    assert [field for field, _ in info.value.problems] == ["inserts[0].file"]
    from typer.testing import CliRunner

    from siloflow.cli import app
    result = CliRunner().invoke(app, ["validate", str(tmp_path / "case.yaml")])
    assert result.exit_code == 1
    assert "inserts[0].file" in result.output and "FIFO" in result.output


@pytest.mark.engine
@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed (make install-engine); "
                    "CI installs it, so CI never skips this")
def test_insert_carries_load_in_a_real_run(tmp_path):
    from postprocess.report import post_process as analyse
    from siloflow.engine import LiggghtsEngine

    write_user_stl(tmp_path / "b.stl", baffle(), Mode.BINARY)
    case = load_case(slab_case_with(tmp_path, "b.stl"))
    folder = tmp_path / "run"
    record = LiggghtsEngine().run(case, folder)
    summary = analyse(folder)
    forces = RunFolder(folder).wall_forces()              # the force the grains exert on each wall
    on_baffle = forces[forces.wall == "insert_baffle"]
    still = on_baffle[(on_baffle.step > record.stage_steps["static"]) & (on_baffle.step <= record.stage_steps["open"])]
    assert len(still) and (still.fz < 0).all()            # grains rest on the baffle (force on it: down)
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.01)   # the baffle counted in the balance
