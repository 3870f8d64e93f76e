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
from siloflow.geometry import MeshError, read_user_mesh, rectangle
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
    assert "malformed ASCII STL file (it starts with 'solid'): line 4" in _refused(
        tmp_path, raw=b"solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0\n")
    assert "no triangles" in _refused(tmp_path, raw=b"solid x\nendsolid x\n")
    assert "outside the silo" in _refused(tmp_path, tris, scale=10.0)
    with pytest.raises(CaseError, match="cannot read") as info:
        derive(load_case(slab_case_with(tmp_path, "missing.stl")))
    assert [field for field, _ in info.value.problems] == ["inserts[0].file"]


GOOD_FACET = "  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n      vertex 1 0 0\n      vertex 0 1 0\n" \
             "    endloop\n  endfacet\n"


@pytest.mark.parametrize("bad, line, said", [
    ("      vertex 1 0 oops\n", 12, "'vertex 1 0 oops'"),          # a word for a number
    ("      vertex 1 0\n", 12, "'vertex 1 0'"),                    # two coordinates (read as 'File too large, got
    ("      vertx 1 0 0\n", 12, "'vertx 1 0 0'"),                  # 1869833326 triangles' before)
])
def test_a_malformed_ascii_stl_names_its_line_not_a_binary_size(tmp_path, bad, line, said):
    """An ASCII STL (text starting with 'solid') whose parse fails is reported as a malformed
    ASCII STL with the line, never re-read as a binary STL of billions of triangles."""
    second = GOOD_FACET.replace("      vertex 1 0 0\n", bad)
    path = tmp_path / "hand.stl"
    path.write_text("solid hand\n" + GOOD_FACET + second + "endsolid hand\n")
    with pytest.raises(MeshError) as info:
        read_user_mesh(path)
    message = str(info.value)
    assert str(path) in message and f"malformed ASCII STL file (it starts with 'solid'): line {line}:" in message
    assert said in message and "triangles" not in message
    # through a case: the insert's field and the same message
    assert f"line {line}:" in _refused(tmp_path, raw=path.read_bytes())
    # a truncated ASCII file says where it ends
    path.write_text("solid hand\n" + GOOD_FACET + "  facet normal 0 0 1\n")
    with pytest.raises(MeshError, match=r"malformed ASCII STL .* ends after line 9 where 'outer loop' was expected"):
        read_user_mesh(path)


def test_stl_kind_is_told_by_content(tmp_path):
    """A well-formed ASCII file is read as ASCII; a binary file whose header starts with 'solid'
    (as some exporters write) is read as binary; a binary file cut short is refused by its size."""
    path = tmp_path / "hand.stl"
    path.write_text("solid hand\n" + GOOD_FACET + GOOD_FACET.replace("vertex 0 1 0", "vertex 1 1 0") + "endsolid\n")
    np.testing.assert_array_equal(read_user_mesh(path)[1], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\n", b"\r\n"))     # a BOM, Windows lines
    np.testing.assert_array_equal(read_user_mesh(path)[1], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    tris = baffle()
    write_user_stl(path, tris, Mode.BINARY)
    raw = path.read_bytes()
    path.write_bytes(b"solid exported".ljust(80, b" ") + raw[80:])
    np.testing.assert_allclose(read_user_mesh(path), tris, atol=1e-9)
    path.write_bytes(raw[:-10])
    with pytest.raises(MeshError, match=rf"not an STL file: as a binary STL its header announces {len(tris)} "
                                        rf"triangles \({84 + 50 * len(tris)} bytes\), but the file has {len(raw) - 10}"):
        read_user_mesh(path)


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
