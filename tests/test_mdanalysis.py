"""``Run.to_universe``: a stored run's dumps (tests/data/tiny_run, no engine) as an MDAnalysis
Universe: the same positions, radii, types and velocities as siloflow's dump reader in every frame;
a fixed-N window refused when the particles change, or cut to the common ones; bodies as residues;
and MDAnalysis' own analyses (InterRDF, neighbour search) running on the silo."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import siloflow
from postprocess.dumps import Frame, read_frames
from postprocess.universe import universe_from_frames
from siloflow.errors import ReadError, SetupError

mda = pytest.importorskip("MDAnalysis")
from MDAnalysis.analysis.rdf import InterRDF  # noqa: E402
from MDAnalysis.lib.NeighborSearch import AtomNeighborSearch  # noqa: E402

STORED = Path(__file__).resolve().parent / "data" / "tiny_run"
FLOAT32 = 1e-8          # m: MDAnalysis keeps positions as float32 (a few 1e-9 m at these sizes)


@pytest.fixture(scope="module")
def run():
    return siloflow.open_run(STORED)


@pytest.fixture(scope="module")
def frames(run):
    return {f.timestep: f for f in read_frames(run.run_folder.dump_files("particles"))}


def _by_id(frame, ids):
    """The rows of ``frame`` of the particles ``ids``, in that order."""
    index = pd.Index(frame.column("id"))
    return index.get_indexer(ids)


def _same_as_dumps(u, frames):
    assert len(u.trajectory) == len(u.dump_steps)
    for ts, step in zip(u.trajectory, u.dump_steps):
        frame = frames[int(step)]
        rows = _by_id(frame, u.atoms.ids)
        assert (rows >= 0).all()
        np.testing.assert_allclose(u.atoms.positions, frame.positions()[rows], rtol=0, atol=FLOAT32)
        np.testing.assert_allclose(u.atoms.velocities, frame.velocities()[rows], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(u.atoms.radii, frame.radii()[rows])
        assert list(u.atoms.types) == [str(t) for t in frame.column("type")[rows]]
        np.testing.assert_allclose(u.atoms.masses, frame.column("mass")[rows])


def test_default_window_is_the_closed_silo_with_the_dumps_positions(run, frames):
    u = run.to_universe()
    stages = run.record.stage_steps
    expected = [s for s in frames if stages["settle"] <= s < stages["open"]]
    assert list(u.dump_steps) == expected and len(expected) >= 4
    assert u.atoms.n_atoms == 300 and list(u.atoms.ids) == sorted(frames[expected[0]].column("id"))
    _same_as_dumps(u, frames)
    assert set(u.atoms.names) == {"grain"} and np.all(u.atoms.radii == 0.00125)
    assert len(u.residues) == 300 and u.dimensions is None          # spheres: one body each; no cell
    np.testing.assert_allclose(u.dump_times, np.array(expected) * run.plan.dt)
    np.testing.assert_allclose(u.trajectory.dt, (expected[1] - expected[0]) * run.plan.dt)


def test_a_window_whose_count_changes(run, frames):
    with pytest.raises(ReadError, match=r"particles change in the window: 294 at step 10791, 291 at step 11772"):
        run.to_universe("discharge")
    u = run.to_universe("discharge", atoms="common")
    last = max(frames)
    assert u.atoms.n_atoms == frames[last].n == 188 and u.dump_steps[-1] == last
    assert u.dump_steps[0] >= run.record.stage_steps["discharge"]
    _same_as_dumps(u, frames)
    # by steps, every other frame
    u2 = run.to_universe(steps=(9000, None), every=2, atoms="common")
    assert list(u2.dump_steps) == [s for s in sorted(frames) if s >= 9000][::2]
    _same_as_dumps(u2, frames)
    # a changing count frame by frame: one Universe per frame
    for frame in run.frames():
        if frame.n:
            assert universe_from_frames([frame]).atoms.n_atoms == frame.n


def test_window_choices_refused(run):
    with pytest.raises(ReadError, match="no stage pour in this run; its stages are fill, settle, static, open, discharge"):
        run.to_universe("pour")
    with pytest.raises(ReadError, match="no particle is present in every frame"):
        run.to_universe("fill", atoms="common")                     # the first frame is empty
    with pytest.raises(ReadError, match="no particle dump between steps 1 and 5"):
        run.to_universe(steps=(1, 5))
    with pytest.raises(ReadError, match="atoms='any'"):
        run.to_universe(atoms="any")
    with pytest.raises(SetupError, match="stages or steps"):
        run.to_universe("settle", steps=(0, 10))


def test_clumps_are_residues():
    """Spheres of one clump (the same ``mol`` > 0) are one residue, with the clump's id; a loose
    sphere (``mol`` 0, dust) a residue of its own."""
    data = pd.DataFrame({"id": [5, 1, 2, 3, 4], "type": [2, 1, 1, 1, 1], "mol": [0, 7, 7, 9, 9],
                         "x": [0.0, 1, 2, 3, 4], "y": 0.0, "z": 0.0, "radius": [0.5, 1, 1, 1, 1]})
    frames = [Frame(s, np.zeros((3, 2)), data.assign(x=data.x + s)) for s in (0, 10)]
    u = universe_from_frames(frames, type_names={1: "wheat", 2: "dust"})
    assert list(u.atoms.ids) == [1, 2, 3, 4, 5]
    assert list(u.atoms.resids) == [7, 7, 9, 9, 14]                # dust: its id + the largest mol
    assert list(u.atoms.names) == ["wheat"] * 4 + ["dust"] and list(u.atoms.radii) == [1, 1, 1, 1, 0.5]
    assert len(u.residues) == 3
    u.trajectory[1]
    np.testing.assert_allclose(u.atoms.positions[:, 0], [11, 12, 13, 14, 10])


def test_mdanalysis_analyses_run_on_the_silo(run, frames):
    u = run.to_universe()
    # the radial distribution function peaks at contact (one grain diameter, 2.5 mm)
    rdf = InterRDF(u.atoms, u.atoms, nbins=60, range=(0.0, 0.0075), norm="density", exclusion_block=(1, 1)).run()
    assert abs(rdf.results.bins[np.argmax(rdf.results.rdf)] - 0.0025) < 0.0002
    assert rdf.results.rdf[rdf.results.bins < 0.002].sum() == 0              # no grain inside another
    # with a unit cell MDAnalysis normalises by its volume (a cell larger than the silo: no image is near)
    u_box = run.to_universe(dimensions=[0.1, 0.1, 0.2, 90, 90, 90])
    box = InterRDF(u_box.atoms, u_box.atoms, nbins=60, range=(0.0, 0.0075), exclusion_block=(1, 1)).run()
    np.testing.assert_array_equal(box.results.count, rdf.results.count)
    # neighbour search: grains within 1 % of contact, against a brute-force count on the dump
    u.trajectory[-1]
    search = AtomNeighborSearch(u.atoms)
    ours = np.array([len(search.search(a, 1.01 * 2 * a.radius)) - 1 for a in u.atoms])
    frame = frames[int(u.dump_steps[-1])]
    x = frame.positions()[_by_id(frame, u.atoms.ids)]
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    brute = (d <= 1.01 * 2 * 0.00125).sum(axis=1) - 1
    assert np.array_equal(ours, brute) and 4 < ours.mean() < 7
