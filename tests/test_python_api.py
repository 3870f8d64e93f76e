"""The Python API of docs/python_api.md on the stored run folder tests/data/tiny_run (no engine):
cases from YAML or a dict, changed with ``Case.with_changes`` and validated again whole; ``Run``'s
summary, tables, frames and coarse-grained fields; and the example notebook examples/silo_api.py,
executed headless (jupytext + nbclient)."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import siloflow
from conftest import needs_liggghts
from postprocess.dumps import read_frames
from siloflow.case import Case
from siloflow.errors import CaseError, ReadError, SetupError

ROOT = Path(__file__).resolve().parents[1]
STORED = ROOT / "tests" / "data" / "tiny_run"
CASE = ROOT / "examples" / "tiny_silo.yaml"
NOTEBOOK = ROOT / "examples" / "silo_api.py"


# ------------------------------------------------------------------ cases
def test_case_from_yaml_and_dict_agree():
    case = Case.from_yaml(CASE)
    assert Case.model_validate(case.model_dump(mode="json")) == case
    assert case.fill.count == 300 and case.geometry.orifice_radius == 0.005


def test_with_changes_gives_a_new_validated_case():
    case = Case.from_yaml(CASE)
    changed = case.with_changes({"geometry.orifice_radius": 0.006, "fill.count": 400, "discharge.duration": 0.5})
    assert (changed.geometry.orifice_radius, changed.fill.count, changed.discharge.duration) == (0.006, 400, 0.5)
    assert (case.geometry.orifice_radius, case.fill.count) == (0.005, 300)       # the original is unchanged
    assert changed.with_changes({}) == changed
    assert changed.materials == case.materials and changed.seed == case.seed
    # a whole section, as a dict or as its model
    hopper = {"kind": "hopper", "radius": 0.008, "height": 0.06, "outlet_radius": 0.005, "half_angle_deg": 30.0}
    assert case.with_changes({"geometry": hopper}).geometry.kind == "hopper"
    assert case.with_changes({"materials.particle": case.materials.particle.model_copy(
        update={"density": 1500.0})}).materials.particle.density == 1500.0


@pytest.mark.parametrize("change, field, words", [
    ({"geometry.orifice_diameter": 0.02}, "geometry.orifice_diameter", "unknown key"),
    ({"geometry.orifice_radius": -0.001}, "geometry.orifice_radius", "greater than 0"),
    ({"fill.count": 2.5}, "fill.count", "whole number"),
    ({"geometry.orifice_radius": 0.02}, "geometry", "orifice_radius (0.02 m) must be smaller than radius"),
    # a check across sections: the grains no longer fit the silo
    ({"particles.radius": 0.004}, "(top level)", "particles.radius (0.004 m) is too large"),
    ({"seed.value": 1}, "seed", "not a section"),
    ({"geometry..radius": 1}, "geometry..radius", "dotted field path"),
])
def test_with_changes_refuses_an_invalid_change_naming_the_field(change, field, words):
    case = Case.from_yaml(CASE)
    with pytest.raises(CaseError) as info:
        case.with_changes(change)
    assert any(path == field and words in msg for path, msg in info.value.problems), info.value.problems


def test_with_changes_derives_the_defaults_again():
    data = Case.from_yaml(CASE).model_dump(mode="json", exclude_unset=True)
    del data["fill"]["settle"]["static_window"]
    case = Case.model_validate(data)                       # its static window is the default: 20 samples
    assert case.fill.settle.static_window == pytest.approx(0.1)
    assert case.with_changes({"outputs.sample_interval": 0.01}).fill.settle.static_window == pytest.approx(0.2)
    assert case.with_changes({"fill.count": 100}).fill.settle.static_window == pytest.approx(0.1)
    given = Case.from_yaml(CASE)                           # a window the case sets stays
    assert given.with_changes({"outputs.sample_interval": 0.01}).fill.settle.static_window == 0.02


def test_with_changes_reruns_the_validators_that_model_copy_skips():
    case = Case.from_yaml(CASE)
    unchecked = case.model_copy(update={"fill": case.fill.model_copy(update={"count": -5})})
    assert unchecked.fill.count == -5                       # pydantic's model_copy does not validate
    with pytest.raises(CaseError, match="fill.count"):
        case.with_changes({"fill.count": -5})


# ------------------------------------------------------------------ the stored run
@pytest.fixture(scope="module")
def run():
    return siloflow.open_run(STORED)


def test_open_run_reads_the_stored_results(run):
    assert isinstance(run, siloflow.Run) and run.state == "complete"
    assert run.summary["flow_rate"]["rate"] > 0
    for table, columns in ((run.flow, {"time", "outlet_mass", "particles"}),
                           (run.wall_pressure, {"band", "time", "pressure"}), (run.bands, {"band"})):
        assert isinstance(table, pd.DataFrame) and columns <= set(table.columns) and len(table)
    assert run.flow.particles.iloc[-1] < run.flow.particles.max()         # the discharge removed grains


def test_frames_are_the_dumps(run):
    frames = list(run.frames())
    assert [f.n for f in frames][:4] == [0, 162, 270, 300] and len(frames) == 19
    assert [f.timestep for f in run.frames(every=6)] == [f.timestep for f in frames[::6]]
    last = frames[-1]
    assert last.n == 188 and last.positions().shape == (188, 3) and np.all(last.radii() == 0.00125)


def test_cg_stored_fields_and_computed_ones_agree(run):
    stored = run.cg()
    assert isinstance(stored, xr.Dataset) and dict(stored.sizes)["r"] == 8 and dict(stored.sizes)["z"] == 24
    computed = run.cg(nr=8, nz=24)                         # the same settings as the stored fields.nc
    for name in ("rho", "velocity", "solid_fraction", "kinetic_pressure"):
        np.testing.assert_allclose(computed[name].values, stored[name].values, rtol=1e-9, atol=1e-12)
    coarse = run.cg(nr=4, nz=12, species=None)
    assert dict(coarse.sizes)["r"] == 4 and "rho_species" not in coarse


def test_cg_settings_and_a_folder_without_stored_fields(run, tmp_path):
    with pytest.raises(SetupError, match="unknown setting"):
        run.cg(cells=8)
    with pytest.raises(SetupError, match="give no settings"):
        run.cg(stored=True, nr=4)
    copy = tmp_path / "run"
    shutil.copytree(STORED, copy)
    shutil.rmtree(copy / "results" / "cg")
    bare = siloflow.open_run(copy)
    with pytest.raises(ReadError, match="siloflow cg"):
        bare.cg(stored=True)
    ds = bare.cg(nr=4, nz=12)                               # computed, and not written
    assert float(ds.rho.max()) > 0 and not (copy / "results" / "cg").exists()


def test_frames_of_the_run_match_the_dump_reader(run):
    files = run.run_folder.dump_files("particles")
    for ours, direct in zip(run.frames(), read_frames(files)):
        assert ours.timestep == direct.timestep
        pd.testing.assert_frame_equal(ours.data, direct.data)


# ------------------------------------------------------------------ the notebook
def test_example_notebook_runs_headless(tmp_path):
    jupytext = pytest.importorskip("jupytext", reason="the notebook extra: pip install -e '.[notebook]'")
    nbclient = pytest.importorskip("nbclient", reason="the notebook extra: pip install -e '.[notebook]'")
    notebook = jupytext.read(NOTEBOOK)
    client = nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(NOTEBOOK.parent)}})
    client.execute()
    text = "\n".join(out.get("text", "") for cell in notebook.cells if cell.cell_type == "code"
                     for out in cell.get("outputs", []) if out.get("output_type") == "stream")
    assert "flow rate" in text and "unknown key" in text
    peak = float(re.search(r"first peak at ([0-9.]+) mm", text).group(1))
    assert abs(peak - 2.5) < 0.2                            # the RDF's first peak: grains in contact
    assert "188 atoms" in text                              # the discharge window's common particles


# ------------------------------------------------------------------ with the engine
@needs_liggghts
def test_run_a_changed_case_and_read_it_back(tmp_path):
    """``siloflow.run`` of a case changed in Python (the tiny silo, fewer grains, a shorter
    discharge): a complete Run whose tables, frames, fields and Universe read as the stored one's."""
    case = Case.from_yaml(CASE).with_changes({"fill.count": 150, "discharge.duration": 0.15, "seed": 7})
    r = siloflow.run(case, tmp_path / "run")
    assert r.state == "complete" and r.summary["flow_rate"]["rate"] > 0
    assert siloflow.open_run(tmp_path / "run").flow.equals(r.flow)
    frames = list(r.frames())
    assert max(f.n for f in frames) == 150 and frames[-1].n < 150
    u = r.to_universe()
    assert u.atoms.n_atoms == 150 and len(u.trajectory) >= 2
    for ts, step in zip(u.trajectory, u.dump_steps):
        frame = next(f for f in frames if f.timestep == step)
        order = np.argsort(frame.column("id"))
        np.testing.assert_allclose(u.atoms.positions, frame.positions()[order], rtol=0, atol=1e-8)
    assert float(r.cg(nr=4, nz=12).rho.max()) > 0
