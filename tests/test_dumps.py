"""The dump reader: text dump custom/local, gzip, many frames, varying particle count, VTK;
cross-checked against MDAnalysis on a fixed-N dump."""
from __future__ import annotations

import gzip
import warnings

import numpy as np
import pytest

from postprocess.dumps import dump_files, local_columns, read_dump, read_frames
from siloflow.errors import ReadError


def dump_text(frames, columns=("id", "type", "x", "y", "z", "vx", "vy", "vz", "radius"), box=((0, 1),) * 3):
    """LAMMPS-style text of ``frames`` = [(step, array (n, len(columns)))]."""
    out = []
    for step, data in frames:
        out += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(len(data)),
                "ITEM: BOX BOUNDS ff ff ff"] + [f"{lo} {hi}" for lo, hi in box]
        out.append("ITEM: ATOMS " + " ".join(columns) + " ")
        out += [" ".join(f"{int(v)}" if c in ("id", "type") else f"{v:.10g}" for c, v in zip(columns, row)) + " "
                for row in data]
    return "\n".join(out) + "\n"


def random_frame(rng, n, start_id=1):
    ids = np.arange(start_id, start_id + n)
    rng.shuffle(ids)
    return np.column_stack([ids, rng.integers(1, 3, n), rng.random((n, 3)), rng.normal(size=(n, 3)),
                            rng.uniform(1e-3, 2e-3, n)])


def test_varying_particle_count_many_frames_and_gzip(tmp_path):
    rng = np.random.default_rng(0)
    frames = [(0, random_frame(rng, 5)), (100, random_frame(rng, 120)), (200, random_frame(rng, 0)),
              (300, random_frame(rng, 37))]
    text = dump_text(frames)
    (tmp_path / "a.dump").write_text(text)
    with gzip.open(tmp_path / "b.dump.gz", "wt") as fh:
        fh.write(text)
    for name in ("a.dump", "b.dump.gz"):
        got = read_dump(tmp_path / name)
        assert [f.timestep for f in got] == [0, 100, 200, 300]
        assert [f.n for f in got] == [5, 120, 0, 37]
        for (step, data), frame in zip(frames, got):
            if len(data):
                np.testing.assert_allclose(frame.positions(), data[:, 2:5], rtol=1e-9)
                np.testing.assert_array_equal(frame.column("id"), data[:, 0].astype(int))
                np.testing.assert_allclose(frame.velocities(), data[:, 5:8], rtol=1e-9)
                assert frame.column("id").dtype == np.int64


def test_any_column_order_and_scaled_coordinates(tmp_path):
    rng = np.random.default_rng(1)
    data = random_frame(rng, 50)
    cols = ("radius", "vz", "xs", "id", "zs", "ys", "type", "vx", "vy")
    order = [8, 7, 2, 0, 4, 3, 1, 5, 6]
    path = tmp_path / "dump.scaled"
    box = ((-1.0, 1.0), (0.0, 2.0), (5.0, 6.0))
    scaled = data.copy()
    path.write_text(dump_text([(7, scaled[:, order])], cols, box))
    frame = read_dump(path)[0]
    lo = np.array([b[0] for b in box])
    span = np.array([b[1] - b[0] for b in box])
    np.testing.assert_allclose(frame.positions(), lo + data[:, 2:5] * span, rtol=0, atol=1e-9)
    np.testing.assert_allclose(frame.radii(), data[:, 8], rtol=1e-9)


def test_one_file_per_frame_in_natural_order_and_every(tmp_path):
    rng = np.random.default_rng(2)
    for step in (0, 5, 10, 100, 1000):
        (tmp_path / f"dump.{step}.txt").write_text(dump_text([(step, random_frame(rng, 3))]))
    assert [p.name for p in dump_files(str(tmp_path / "dump.*.txt"))] == [
        "dump.0.txt", "dump.5.txt", "dump.10.txt", "dump.100.txt", "dump.1000.txt"]
    assert [f.timestep for f in read_frames(tmp_path)] == [0, 5, 10, 100, 1000]
    assert [f.timestep for f in read_frames(tmp_path, every=2)] == [0, 10, 1000]
    assert [f.timestep for f in read_frames(tmp_path, steps=[10, 1000])] == [10, 1000]


def test_dump_local_contacts_with_liggghts_column_layout(tmp_path):
    cols = local_columns(["force", "id", "pos"])          # order given does not matter
    assert cols[:9] == ["x1", "y1", "z1", "x2", "y2", "z2", "id1", "id2", "periodic"]
    assert cols[9:] == ["fx", "fy", "fz"]
    text = ("ITEM: TIMESTEP\n50\nITEM: NUMBER OF ENTRIES\n2\nITEM: BOX BOUNDS mm mm mm\n0 1\n0 1\n0 1\n"
            "ITEM: ENTRIES " + " ".join(f"c_pl[{k + 1}]" for k in range(12)) + "\n"
            "0 0 0 1 0 0 1 2 0 0.1 0 0\n0 0 0 0 1 0 1 3 0 0 0.2 0\n")
    (tmp_path / "contacts.txt").write_text(text)
    frame = read_dump(tmp_path / "contacts.txt", columns=cols)[0]
    assert frame.kind == "entries" and frame.n == 2
    assert list(frame.column("id2")) == [2, 3]
    with pytest.raises(ReadError, match="12 columns"):
        read_dump(tmp_path / "contacts.txt", columns=cols[:5])
    with pytest.raises(ReadError, match="unknown pair/gran/local keyword"):
        local_columns(["pos", "bogus"])


def test_truncated_and_foreign_files_are_refused_with_the_file_named(tmp_path):
    rng = np.random.default_rng(3)
    text = dump_text([(0, random_frame(rng, 10))])
    cut = tmp_path / "cut.dump"
    cut.write_text("\n".join(text.splitlines()[:-3]) + "\n")
    with pytest.raises(ReadError, match="cut.dump.*announces 10 rows but has 7"):
        read_dump(cut)
    other = tmp_path / "notes.dump"
    other.write_text("hello\n")
    with pytest.raises(ReadError, match="notes.dump: not a LAMMPS/LIGGGHTS text dump"):
        read_dump(other)
    with pytest.raises(ReadError, match="no dump files match"):
        read_dump(str(tmp_path / "nothing*.dump"))
    frame = read_dump(_ok(tmp_path, rng))[0]
    with pytest.raises(ReadError, match="no column 'omegax'"):
        frame.column("omegax")


def _ok(tmp_path, rng):
    path = tmp_path / "ok.dump"
    path.write_text(dump_text([(0, random_frame(rng, 4))]))
    return path


def test_liggghts_legacy_vtk_particles(tmp_path):
    """The layout LIGGGHTS' dump custom/vtk writes (POLYDATA points + FIELD arrays)."""
    pts = np.array([[0.0, 0.1, 0.2], [1.0, 1.1, 1.2], [2.0, 2.1, 2.2]])
    text = ["# vtk DataFile Version 5.1", "Generated by LIGGGHTS", "ASCII", "DATASET POLYDATA",
            "POINTS 3 float", " ".join(f"{v}" for v in pts.ravel()),
            "VERTICES 4 3", "OFFSETS vtktypeint64", "0 1 2 3", "CONNECTIVITY vtktypeint64", "0 1 2",
            "POINT_DATA 3", "FIELD FieldData 3", "id 1 3 int", "7 8 9", "v 3 3 double",
            "1 2 3 4 5 6 7 8 9", "radius 1 3 double", "0.001 0.002 0.003"]
    path = tmp_path / "particles_4200.vtk"
    path.write_text("\n".join(text) + "\n")
    frame = read_dump(path)[0]
    assert frame.timestep == 4200 and frame.n == 3
    np.testing.assert_allclose(frame.positions(), pts)
    np.testing.assert_allclose(frame.velocities()[1], [4, 5, 6])
    np.testing.assert_allclose(frame.radii(), [0.001, 0.002, 0.003])
    assert list(frame.column("id")) == [7, 8, 9]


def mdanalysis_frames(path):
    import MDAnalysis  # a test dependency: pip install -e .[test]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u = MDAnalysis.Universe(str(path), format="LAMMPSDUMP", topology_format="LAMMPSDUMP",
                                lammps_coordinate_convention="unscaled")
        return [(ts.frame, u.atoms.ids.copy(), ts.positions.copy(), ts.velocities.copy()) for ts in u.trajectory]


def compare_with_mdanalysis(path):
    ours = read_dump(path)
    theirs = mdanalysis_frames(path)
    assert len(ours) == len(theirs)
    for frame, (_, ids, pos, vel) in zip(ours, theirs):
        order = np.argsort(frame.column("id"))
        np.testing.assert_array_equal(frame.column("id")[order], ids)
        # MDAnalysis stores float32
        np.testing.assert_allclose(frame.positions()[order], pos, rtol=2e-7, atol=1e-12)
        np.testing.assert_allclose(frame.velocities()[order], vel, rtol=2e-7, atol=1e-12)
    return len(ours)


def test_reader_agrees_with_mdanalysis_on_a_fixed_n_dump(tmp_path):
    rng = np.random.default_rng(4)
    frames = [(k * 10, random_frame(rng, 200)) for k in range(6)]
    path = tmp_path / "fixed.lammpstrj"
    path.write_text(dump_text(frames))
    assert compare_with_mdanalysis(path) == 6
