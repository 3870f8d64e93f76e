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


# ----------------------------------------------------------------------------------------
# issue 13, item 3: every frame's rows and fields are checked against its header

ROW = 9          # fields per row of dump_text's default columns


def _rows(text):
    """Indices (0-based) of the data lines of ``text``."""
    return [k for k, line in enumerate(text.splitlines()) if len(line.split()) == ROW]


def _two_frames(tmp_path, rng, name="two.dump"):
    frames = [(0, random_frame(rng, 5)), (100, random_frame(rng, 6))]
    return frames, dump_text(frames)


def test_rows_with_one_field_more_than_the_header_are_refused_not_shifted(tmp_path):
    """pandas used to take the first of 10 fields as the index: z held y, mass held an id."""
    rng = np.random.default_rng(5)
    _, text = _two_frames(tmp_path, rng)
    lines = text.splitlines()
    every = [line + " 7" if k in _rows(text) else line for k, line in enumerate(lines)]
    path = tmp_path / "extra.dump"
    path.write_text("\n".join(every) + "\n")
    with pytest.raises(ReadError, match=r"extra\.dump: frame at step 0, line 10: 10 fields, but the header "
                                        r"names 9 columns"):
        read_dump(path)
    one = list(lines)
    k = _rows(text)[7]                       # third row of the second frame (file line k + 1)
    one[k] += " 7"
    path.write_text("\n".join(one) + "\n")
    with pytest.raises(ReadError, match=rf"extra\.dump: frame at step 100, line {k + 1}: 10 fields"):
        read_dump(path)


def test_rows_with_a_field_missing_are_refused_with_the_line(tmp_path):
    rng = np.random.default_rng(6)
    _, text = _two_frames(tmp_path, rng)
    lines = text.splitlines()
    k = _rows(text)[1]
    lines[k] = " ".join(lines[k].split()[:-1])
    path = tmp_path / "short.dump"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ReadError, match=rf"short\.dump: frame at step 0, line {k + 1}: 8 fields"):
        read_dump(path)


def test_a_last_number_cut_short_is_refused(tmp_path):
    rng = np.random.default_rng(7)
    _, text = _two_frames(tmp_path, rng)
    path = tmp_path / "cut.dump"
    path.write_text(text.rstrip()[:-3])      # the last radius loses its last digits, no newline
    with pytest.raises(ReadError, match=rf"cut\.dump: frame at step 100, line {len(text.splitlines())}: "
                                        "the file ends in the middle of this line"):
        read_dump(path)
    with gzip.open(tmp_path / "cut.dump.gz", "wt") as fh:
        fh.write(text.rstrip()[:-3])
    with pytest.raises(ReadError, match="cut.dump.gz: frame at step 100.*ends in the middle"):
        read_dump(tmp_path / "cut.dump.gz")


@pytest.mark.parametrize("announced, message", [
    (4, r"frame at step 0, line 14: expected 'ITEM: TIMESTEP' after the 4 rows the header announces"),
    (6, r"frame at step 0, line 15: the header announces 6 rows but has 5"),
    (-5, r"frame at step 0, line 4: the header announces a negative number of atoms \(-5\)"),
    ("5.0", r"frame at step 0, line 4: expected the number of atoms \(an integer\), found b'5.0'"),
    ("five", r"frame at step 0, line 4: expected the number of atoms"),
])
def test_a_header_count_that_lies_is_refused_before_the_frame_is_used(tmp_path, announced, message):
    rng = np.random.default_rng(8)
    _, text = _two_frames(tmp_path, rng)
    lines = text.splitlines()
    assert lines[3] == "5"
    lines[3] = str(announced)
    path = tmp_path / "lies.dump"
    path.write_text("\n".join(lines) + "\n")
    seen = []
    with pytest.raises(ReadError, match="lies.dump: " + message):
        for frame in read_frames(path):      # no frame of the wrong size reaches the caller
            seen.append(frame)
    assert seen == []
    with pytest.raises(ReadError, match="lies.dump: "):
        list(read_frames(path, steps=[100]))     # a skipped frame's row count is checked too


def test_non_integer_ids_and_nan_values(tmp_path):
    rng = np.random.default_rng(9)
    _, text = _two_frames(tmp_path, rng)
    lines = text.splitlines()
    k = _rows(text)[2]
    fields = lines[k].split()
    path = tmp_path / "ids.dump"
    path.write_text("\n".join(lines[:k] + [" ".join(["2.5"] + fields[1:])] + lines[k + 1:]) + "\n")
    with pytest.raises(ReadError, match=rf"ids\.dump: frame at step 0, line {k + 1}: column 'id' holds 2.5"):
        read_dump(path)
    # nan/inf as printf writes them are numbers (a run that blew up): read, not refused
    path.write_text("\n".join(lines[:k] + [" ".join(fields[:2] + ["nan", "-nan", "inf"] + fields[5:])]
                              + lines[k + 1:]) + "\n")
    frame = read_dump(path)[0]
    assert np.isnan(frame.positions()[2, :2]).all() and frame.positions()[2, 2] == np.inf
    assert frame.column("id").dtype == np.int64


def test_post_refuses_the_extra_field_dump_instead_of_reporting_shifted_values(tmp_path):
    """The reproduction of item 3 through the CLI: exit 1 and the message, not z_max 0.0 and exit 0."""
    from typer.testing import CliRunner

    from siloflow.cli import app

    rng = np.random.default_rng(10)
    _, text = _two_frames(tmp_path, rng)
    path = tmp_path / "extra.dump"
    path.write_text("\n".join(line + " 7" if k in _rows(text) else line
                              for k, line in enumerate(text.splitlines())) + "\n")
    result = CliRunner().invoke(app, ["post", str(path), "-o", str(tmp_path / "out")])
    flat = "".join(result.output.split())
    assert result.exit_code == 1, result.output
    assert "siloflow:ReadError" in flat and "extra.dump:frameatstep0,line10:10fields" in flat
    assert not (tmp_path / "out" / "summary.json").exists()


# ----------------------------------------------------------------------------------------
# issue 13, item 5: `post` on broken files ends in a message naming the file, never a traceback

def _vtk(tmp_path, name, lines):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


VTK_HEAD = ["# vtk DataFile Version 5.1", "Generated by LIGGGHTS", "ASCII", "DATASET POLYDATA"]


def _broken_inputs(tmp_path):
    """(path, expected message) of item 5's reproductions."""
    rng = np.random.default_rng(11)
    text = dump_text([(0, random_frame(rng, 5)), (100, random_frame(rng, 6))])
    neg = tmp_path / "neg.dump"
    neg.write_text(text.replace("NUMBER OF ATOMS\n5\n", "NUMBER OF ATOMS\n-5\n"))
    fake = tmp_path / "fake.dump.gz"
    fake.write_bytes(b"\x1f\x8bnot gzip at all")
    packed = gzip.compress(text.encode())
    trunc = tmp_path / "trunc.dump.gz"
    trunc.write_bytes(packed[:len(packed) // 2])
    corrupt = tmp_path / "corrupt.dump.gz"
    corrupt.write_bytes(packed[:20] + bytes(b ^ 0x5A for b in packed[20:40]) + packed[40:])
    few = _vtk(tmp_path, "few_1.vtk", VTK_HEAD + ["POINTS 3 float", "0 1 2 3"])
    word = _vtk(tmp_path, "word_1.vtk", VTK_HEAD + ["POINTS abc float", "0 1 2 3"])
    tuples = _vtk(tmp_path, "tuples_1.vtk", VTK_HEAD + ["POINTS 2 float", "0 0 0 1 1 1", "POINT_DATA 2",
                                                        "FIELD FieldData 1", "radius 1 3 double", "0.1 0.2"])
    fields = _vtk(tmp_path, "fields_1.vtk", VTK_HEAD + ["POINTS 2 float", "0 0 0 1 1 1", "POINT_DATA 2",
                                                        "FIELD FieldData 2", "radius 1 2 double", "0.1 0.2"])
    return [(neg, r"neg\.dump: frame at step 0, line 4: the header announces a negative number of atoms"),
            (fake, r"fake\.dump\.gz: .*gzip"),
            (trunc, r"trunc\.dump\.gz: frame at step \d+ \(from line \d+\): the gzip data is cut short"),
            (corrupt, r"corrupt\.dump\.gz: .*(gzip|line)"),
            (few, r"few_1\.vtk: POINTS \(line 5\): expected 9 numbers \(x y z of 3 points\), found only 4"),
            (word, r"word_1\.vtk: POINTS \(line 5\): expected the number of points"),
            (tuples, r"tuples_1\.vtk: radius \(line 9\): 3 tuples of 1 components; expected 2"),
            (fields, r"fields_1\.vtk: FIELD \(line 8\): announces 2 arrays, the file ends")]


def test_broken_dumps_raise_read_errors_naming_the_file(tmp_path):
    for path, message in _broken_inputs(tmp_path):
        with pytest.raises(ReadError, match=message):
            read_dump(path)


def test_post_on_broken_dumps_prints_a_message_not_a_traceback(tmp_path):
    from typer.testing import CliRunner

    from siloflow.cli import app

    for path, message in _broken_inputs(tmp_path):
        result = CliRunner().invoke(app, ["post", str(path), "-o", str(tmp_path / "out")])
        assert result.exit_code == 1 and isinstance(result.exception, SystemExit), (path, result.output)
        assert "siloflow: ReadError" in result.output, (path, result.output)
        assert path.name in "".join(result.output.split()), (path, result.output)
        assert "Traceback" not in result.output and "Aborted" not in result.output


def test_post_into_an_existing_file_is_a_setup_error_and_leaves_it_alone(tmp_path):
    from typer.testing import CliRunner

    from postprocess.report.dumps import analyse_any
    from siloflow.cli import app
    from siloflow.errors import SetupError

    rng = np.random.default_rng(12)
    good = tmp_path / "good.dump"
    good.write_text(dump_text([(0, random_frame(rng, 20))]))
    afile = tmp_path / "afile"
    afile.write_text("my notes\n")
    result = CliRunner().invoke(app, ["post", str(good), "-o", str(afile)])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert "siloflow: SetupError" in result.output and "afile" in result.output
    assert afile.read_text() == "my notes\n"
    with pytest.raises(SetupError, match="afile .*is a file, not a folder"):
        analyse_any(good, afile / "results")


def test_post_refuses_nan_positions_with_the_line_instead_of_a_traceback(tmp_path):
    """The reader reads printf's nan (above); the analyses of `post` need finite positions."""
    from typer.testing import CliRunner

    from siloflow.cli import app

    rng = np.random.default_rng(14)
    data = random_frame(rng, 30)
    data[3, 2] = np.nan
    path = tmp_path / "blown.dump"
    path.write_text(dump_text([(0, data)]))
    result = CliRunner().invoke(app, ["post", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert "blown.dump:frameatstep0,line13:x=nan" in "".join(result.output.split())


def test_wrapped_positions_are_put_back_in_a_periodic_box(tmp_path):
    """An engine wraps an atom that crossed a periodic boundary only at its next neighbour-list
    rebuild: a dump in between holds it outside the box. ``positions()`` gives what the dump holds
    (as MDAnalysis reads it); ``wrapped_positions()`` wraps along ``pp`` directions (here y, of
    -0.005..0.005 m) and leaves the fixed ones (x, z) as written."""
    text = ("ITEM: TIMESTEP\n10\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS ff pp ff\n-0.03 0.03\n-0.005 0.005\n0 0.08\n"
            "ITEM: ATOMS id type x y z\n"
            "1 1 0.031 0.0051 0.01\n"
            "2 1 0.0 -0.0052 0.02\n"
            "3 1 0.0 0.001 -0.001\n")
    (tmp_path / "d.txt").write_text(text)
    frame = read_dump(tmp_path / "d.txt")[0]
    np.testing.assert_allclose(frame.positions()[:, 1], [0.0051, -0.0052, 0.001])
    xyz = frame.wrapped_positions()
    np.testing.assert_allclose(xyz[:, 1], [-0.0049, 0.0048, 0.001], atol=1e-15)
    np.testing.assert_allclose(xyz[:, [0, 2]], [[0.031, 0.01], [0.0, 0.02], [0.0, -0.001]])   # fixed: as written
