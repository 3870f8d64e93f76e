"""Read LIGGGHTS/LAMMPS dump files: per-atom ``dump custom``, contact ``dump local`` and
LIGGGHTS' legacy-VTK ``dump custom/vtk``, plain or gzip-compressed, one or many frames per
file, with a particle count that may change from frame to frame (filling, discharge).

Frames are streamed one at a time (memory is one frame), each parsed by pandas' C parser.
Each frame is checked against its header (row count, one number per named column): a malformed
or truncated file raises ReadError naming the file, frame and line, before the frame is yielded.
Positions given as ``xs``/``xu``/``x`` are all returned as unwrapped-or-plain Cartesian
``x y z`` in the dump's length unit (SI for our decks).

    for frame in read_frames("output/dumps/particles_*.dump.gz"):
        frame.positions()       # (n, 3) m
        frame.data["radius"]    # any column by its name in the file
"""
from __future__ import annotations

import csv
import glob
import gzip
import io
import re
import sys
import zlib
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np
import pandas as pd

from siloflow.errors import ReadError

#: column names a LIGGGHTS ``compute pair/gran/local`` writes, per keyword, in LIGGGHTS' fixed
#: output order (which does not depend on the order the keywords were given in)
PAIR_LOCAL_LAYOUT = {
    "pos": ["x1", "y1", "z1", "x2", "y2", "z2"],
    "vel": ["vx1", "vy1", "vz1", "vx2", "vy2", "vz2"],
    "id": ["id1", "id2", "periodic"],
    "force": ["fx", "fy", "fz"],
    "force_normal": ["fnx", "fny", "fnz"],
    "force_tangential": ["ftx", "fty", "ftz"],
    "torque": ["tx", "ty", "tz"],
    "history": ["h1", "h2", "h3"],
    "contactArea": ["area"],
    "delta": ["delta"],
}
#: ``compute wall/gran/local`` uses the same order, but ``id`` is (mesh id, triangle id, particle id)
#: and ``pos`` is (contact point on the wall, particle centre): seen in LIGGGHTS 3.8 output, where
#: the first point lies on the cylinder (r = R) and the second at r = R - radius
WALL_LOCAL_ID = ["mesh", "triangle", "id1"]
WALL_LOCAL_POS = ["xw", "yw", "zw", "x1", "y1", "z1"]


def local_columns(keywords: Sequence[str], wall: bool = False) -> list[str]:
    """Column names of a LIGGGHTS pair/gran/local (or wall/gran/local) compute with these keywords."""
    unknown = [k for k in keywords if k not in PAIR_LOCAL_LAYOUT]
    if unknown:
        raise ReadError(f"unknown pair/gran/local keyword(s) {unknown}; known: {list(PAIR_LOCAL_LAYOUT)}")
    names: list[str] = []
    for key, cols in PAIR_LOCAL_LAYOUT.items():
        if key in keywords:
            if wall and key == "id":
                cols = WALL_LOCAL_ID
            elif wall and key == "pos":
                cols = WALL_LOCAL_POS
            names += cols
    return names


_VTK_VECTORS = {"v": ("vx", "vy", "vz"), "f": ("fx", "fy", "fz"), "omega": ("omegax", "omegay", "omegaz"),
                "i": ("ix", "iy", "iz"), "x": ("x", "y", "z")}


@dataclass
class Frame:
    """One dump frame. ``box`` is [[xlo, xhi], [ylo, yhi], [zlo, zhi]] (m); ``data`` has one row
    per atom (``kind == "atoms"``) or per contact (``kind == "entries"``)."""

    timestep: int
    box: np.ndarray
    data: pd.DataFrame
    kind: str = "atoms"
    boundary: tuple[str, ...] = ()
    source: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.data)

    def column(self, name: str) -> np.ndarray:
        if name not in self.data:
            raise ReadError(f"{self.source}: frame at step {self.timestep} has no column {name!r} "
                            f"(columns: {', '.join(self.data.columns)})")
        return self.data[name].to_numpy()

    def positions(self) -> np.ndarray:
        """(n, 3) Cartesian positions, from x/xu or scaled xs/xsu columns, as written (an engine wraps an
        atom that crossed a periodic boundary only at its next neighbour-list rebuild, so a dump between
        two rebuilds can hold it a little outside the box: :meth:`wrapped_positions` puts it back)."""
        for names in (("x", "y", "z"), ("xu", "yu", "zu")):
            if all(c in self.data for c in names):
                return self.data[list(names)].to_numpy(dtype=float)
        for names in (("xs", "ys", "zs"), ("xsu", "ysu", "zsu")):
            if all(c in self.data for c in names):
                if self.meta.get("triclinic"):
                    raise ReadError(f"{self.source}: scaled coordinates of a triclinic box are not supported")
                lo, hi = self.box[:, 0], self.box[:, 1]
                return lo + self.data[list(names)].to_numpy(dtype=float) * (hi - lo)
        raise ReadError(f"{self.source}: frame at step {self.timestep} has no position columns "
                        f"(columns: {', '.join(self.data.columns)})")

    def wrapped_positions(self) -> np.ndarray:
        """:meth:`positions` with each periodic direction (``pp`` bounds) of an orthogonal box wrapped
        into [lo, hi) (a copy; a triclinic box's as written)."""
        xyz = np.array(self.positions(), dtype=float)
        if self.meta.get("triclinic") or len(self.boundary) != 3:
            return xyz
        for k, flags in enumerate(self.boundary):
            if flags == "pp":
                lo, length = self.box[k, 0], self.box[k, 1] - self.box[k, 0]
                if length > 0:
                    xyz[:, k] = lo + np.mod(xyz[:, k] - lo, length)
        return xyz

    def velocities(self) -> np.ndarray:
        return self.data[["vx", "vy", "vz"]].to_numpy(dtype=float) if "vx" in self.data else self._missing("vx vy vz")

    def radii(self) -> np.ndarray:
        if "radius" in self.data:
            return self.column("radius").astype(float)
        if "diameter" in self.data:
            return 0.5 * self.column("diameter").astype(float)
        return self._missing("radius")

    def _missing(self, what: str):
        raise ReadError(f"{self.source}: frame at step {self.timestep} has no {what} column(s) "
                        f"(columns: {', '.join(self.data.columns)})")


# ----------------------------------------------------------------------------------------
# file lists

def _natural_key(path: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path)]


def dump_files(source) -> list[Path]:
    """Files named by ``source``: a file, a glob pattern, a folder (all dump-like files in it),
    or a list of any of these, in natural order (``dump_9`` before ``dump_10``)."""
    if isinstance(source, (list, tuple)):
        return [p for s in source for p in dump_files(s)]
    text = str(source)
    path = Path(text)
    if path.is_dir():
        names = [str(p) for p in path.iterdir() if p.is_file() and _dump_like(p.name)]
    elif any(ch in text for ch in "*?["):
        names = glob.glob(text)
    elif path.is_file():
        return [path]
    else:
        raise ReadError(f"no dump file or folder at {text}")
    if not names:
        raise ReadError(f"no dump files match {text}")
    return [Path(p) for p in sorted(names, key=_natural_key)]


def _dump_like(name: str) -> bool:
    base = name[:-3] if name.endswith(".gz") else name
    return "dump" in base or base.endswith((".vtk", ".lammpstrj", ".liggghts"))


# ----------------------------------------------------------------------------------------
# text dumps
#
# Every frame is checked against its header: the rows until the next 'ITEM: TIMESTEP' must be
# exactly the announced count, each with exactly one field per column name, each a number.
# The happy path costs a few C-level checks on the joined block and the parsed array's shape;
# only a block that fails them is walked line by line, to name the first bad line.

_INT_COLUMNS = ("id", "type", "mol", "id1", "id2", "periodic", "mesh", "triangle", "ix", "iy", "iz")
_NUMBER = re.compile(rb"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf(?:inity)?)", re.I)
_INTEGER = re.compile(rb"\s*[+-]?\d+\s*")
# what a broken or truncated gzip stream (or an unreadable file) raises while reading
_STREAM_ERRORS = (EOFError, OSError, zlib.error)


def _open(path: Path):
    with open(path, "rb") as probe:
        magic = probe.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb", buffering=1 << 20)


def _stream_problem(exc: BaseException, path: Path, where: str = "") -> ReadError:
    """A ReadError for an exception raised while reading ``path`` (gzip or I/O)."""
    if isinstance(exc, EOFError):
        what = "the gzip data is cut short (truncated .gz file?)"
    elif isinstance(exc, gzip.BadGzipFile):
        what = f"not a valid gzip file ({exc})"
    elif isinstance(exc, zlib.error):
        what = f"corrupt gzip data ({exc})"
    else:
        what = f"cannot read the file ({getattr(exc, 'strerror', None) or exc})"
    return ReadError(f"{path}: {where}{': ' if where else ''}{what}")


class _Lines:
    """Binary line reader that counts lines, for messages."""

    def __init__(self, f):
        self.f = f
        self.lineno = 0
        self.frame = None    # (timestep, line of its 'ITEM: TIMESTEP') of the frame being read

    def where(self) -> str:
        if self.frame is None:
            return f"line {self.lineno + 1}" if self.lineno else ""
        step, line = self.frame
        return f"frame {'' if step is None else f'at step {step} '}(from line {line})"

    def readline(self) -> bytes:
        line = self.f.readline()
        if line:
            self.lineno += 1
        return line

    def nonblank(self) -> bytes:
        line = self.readline()
        while line and not line.strip():
            line = self.readline()
        return line

    def take(self, n: int) -> tuple[bytes, int]:
        lines = list(islice(self.f, n))
        self.lineno += len(lines)
        return b"".join(lines), len(lines)


def _show(line: bytes) -> str:
    return repr(line.rstrip(b"\r\n")[:60])


def _header(r: _Lines, path: Path, columns):
    """Parse the rest of a frame header (after its 'ITEM: TIMESTEP' line), checking every line."""
    step = None

    def fail(what: str):
        frame = f"frame at step {step}, " if step is not None else ""
        return ReadError(f"{path}: {frame}line {r.lineno}: {what}")

    def whole_line() -> bytes:
        line = r.readline()
        if line and not line.endswith(b"\n"):
            raise fail("the file ends in the middle of this line (truncated file?)")
        return line

    def integer(what: str) -> int:
        line = whole_line()
        if not _INTEGER.fullmatch(line):
            raise fail(f"expected the {what} (an integer), found {_show(line) if line else 'the end of the file'}")
        digits = line.strip().lstrip(b"+-").lstrip(b"0")
        value = int(line) if len(digits) <= 19 else None     # (Python refuses to convert 4300 digits or more)
        if value is None or not -2 ** 63 <= value < 2 ** 63:   # the engines count in 64 bits, and so do the tables
            raise fail(f"the {what} {_show(line)} does not fit a 64-bit integer: no LAMMPS or LIGGGHTS dump holds it")
        return value

    def item(prefixes: tuple[bytes, ...]) -> bytes:
        line = whole_line()
        if not line.startswith(prefixes):
            want = " or ".join(repr(p.decode()) for p in prefixes)
            raise fail(f"expected {want}, found {_show(line) if line else 'the end of the file'}")
        text = line.decode("ascii", "replace").rstrip("\r\n")
        if not text.replace("\t", " ").isprintable():
            raise fail(f"the header line {_show(line)} is not plain text")
        return text

    step = integer("timestep")
    count_item = item((b"ITEM: NUMBER OF ATOMS", b"ITEM: NUMBER OF ENTRIES"))
    kind = "atoms" if "ATOMS" in count_item else "entries"
    n = integer(f"number of {kind}")
    if n < 0:
        raise fail(f"the header announces a negative number of {kind} ({n})")
    if n > sys.maxsize:
        raise fail(f"the header announces an impossible number of {kind} ({n})")
    box_line = item((b"ITEM: BOX BOUNDS",)).split()[3:]
    triclinic = bool(box_line) and box_line[0] == "xy"
    box = np.zeros((3, 2))
    for k in range(3):
        fields = whole_line().split()
        if len(fields) != (3 if triclinic else 2) or not all(_NUMBER.fullmatch(v) for v in fields):
            raise fail(f"expected box bounds ({'lo hi tilt' if triclinic else 'lo hi'}), "
                       f"found {_show(b' '.join(fields))}")
        box[k] = float(fields[0]), float(fields[1])
    names = item((b"ITEM: ATOMS",) if kind == "atoms" else (b"ITEM: ENTRIES",)).split()[2:]
    if columns is not None:
        if len(columns) != len(names):
            raise ReadError(f"{path}: {len(columns)} column names given for {len(names)} columns "
                            f"({' '.join(names)})")
        names = list(columns)
    if len(set(names)) != len(names):
        raise ReadError(f"{path}: repeated column names {names}; pass column names explicitly")
    boundary = tuple(box_line[3:] if triclinic else box_line)
    return step, kind, n, box, boundary, triclinic, names


def _strict_rows(block: bytes, names: list[str], n: int, path: Path, step: int, first: int) -> np.ndarray:
    """Slow path: walk the rows, raise a ReadError naming the first bad line, else return them."""
    rows = []
    for k, line in enumerate(io.BytesIO(block)):
        where = f"{path}: frame at step {step}, line {first + k}"
        if line.startswith(b"ITEM:"):
            raise ReadError(f"{where}: the header announces {n} rows but has {k}; "
                            f"{_show(line)} follows row {k} (wrong count in the header?)")
        if not line.endswith(b"\n"):
            raise ReadError(f"{where}: the file ends in the middle of this line (truncated file?)")
        tokens = line.split()
        if not tokens:
            raise ReadError(f"{where}: blank line among the {n} rows the header announces")
        if len(tokens) != len(names):
            shown = " ".join(names) if len(names) <= 20 else " ".join(names[:20]) + " ..."
            raise ReadError(f"{where}: {len(tokens)} fields, but the header names {len(names)} columns ({shown})")
        for t in tokens:
            if not _NUMBER.fullmatch(t):
                raise ReadError(f"{where}: {_show(t)} is not a number")
        rows.append(tokens)
    if len(rows) != n:
        raise ReadError(f"{path}: frame at step {step}, line {first + len(rows)}: announces {n} rows but has "
                        f"{len(rows)} (truncated file?)")
    return np.array(rows, dtype=np.float64).reshape(n, len(names))


_NAN = ["nan", "-nan", "+nan", "NaN", "-NaN", "+NaN", "NAN", "-NAN", "+NAN"]


def _read_csv(block: bytes, **na) -> pd.DataFrame | None:
    """pandas' C parser on a block of rows, or None if it fails. No names and no index column:
    pandas cannot move a column into the index when rows have more fields than names."""
    try:
        return pd.read_csv(io.BytesIO(block), sep=r"\s+", header=None, engine="c", dtype=np.float64,
                           index_col=False, quoting=csv.QUOTE_NONE, **na)
    except (ValueError, OverflowError):
        return None


def _parse_block(block: bytes, nlines: int, names: list[str], n: int, path: Path, step: int,
                 first: int) -> pd.DataFrame:
    """The ``n`` rows of one frame (``block``, from line ``first``) as a DataFrame, checked."""
    if n == 0:
        return pd.DataFrame({c: np.empty(0) for c in names})
    data = None
    if nlines == n and block.endswith(b"\n"):     # (an 'ITEM:' line among the rows fails to parse)
        data = _read_csv(block, na_filter=False)
        if data is None and b"nan" in block.lower():    # printf's nan (a run that blew up)
            data = _read_csv(block, na_filter=True, keep_default_na=False, na_values=_NAN)
        if data is not None and data.shape != (n, len(names)):
            data = None
    if data is None:   # something is off (or nan/inf values): find it, or parse strictly
        data = pd.DataFrame(_strict_rows(block, names, n, path, step, first), columns=names)
    else:
        data.columns = names
    _to_int_columns(data, path, step, first)
    return data


def _to_int_columns(data: pd.DataFrame, path, step, first: int | None) -> None:
    """Integer columns (ids, types, image flags) to int64; refuses non-integer values."""
    for col in _INT_COLUMNS:
        if col in data:
            values = data[col].to_numpy()
            with np.errstate(invalid="ignore"):
                ints = values.astype(np.int64)
                bad = np.flatnonzero(ints != values)
            if bad.size:
                where = f"line {first + bad[0]}" if first is not None else f"point {bad[0]}"
                raise ReadError(f"{path}: frame at step {step}, {where}: column {col!r} holds "
                                f"{float(values[bad[0]]):.17g}, not an integer")
            data[col] = ints


def _text_frames(path: Path, columns: Sequence[str] | None, wanted: set | None = None) -> Iterator[Frame]:
    r = None
    try:
        with _open(path) as f:
            r = _Lines(f)
            yield from _frames_of(r, path, columns, wanted)
    except _STREAM_ERRORS as exc:
        raise _stream_problem(exc, path, r.where() if r else "") from None


def _frames_of(r: _Lines, path: Path, columns, wanted) -> Iterator[Frame]:
    line = r.nonblank()
    if line and not line.startswith(b"ITEM: TIMESTEP"):
        raise ReadError(f"{path}: not a LAMMPS/LIGGGHTS text dump (line {r.lineno}: expected 'ITEM: TIMESTEP', "
                        f"found {_show(line)})")
    while line:
        r.frame = (None, r.lineno)
        step, kind, n, box, boundary, triclinic, names = _header(r, path, columns)
        r.frame = (step, r.frame[1])
        first = r.lineno + 1
        block, nlines = r.take(n)
        if wanted is not None and step not in wanted:   # skipped unparsed; its row count is checked
            data = None
            if nlines != n or (n and not block.endswith(b"\n")) or b"ITEM:" in block:
                _strict_rows(block, names, n, path, step, first)
        else:
            data = _parse_block(block, nlines, names, n, path, step, first)
        line = r.nonblank()
        if line and not line.startswith(b"ITEM: TIMESTEP"):
            raise ReadError(f"{path}: frame at step {step}, line {r.lineno}: expected 'ITEM: TIMESTEP' after "
                            f"the {n} rows the header announces, found {_show(line)} "
                            f"(more rows than the header says?)")
        if data is not None:
            yield Frame(step, box, data, kind, boundary, str(path), {"triclinic": triclinic, "line": first})


# ----------------------------------------------------------------------------------------
# LIGGGHTS legacy VTK (dump custom/vtk)

def _vtk_step(path: Path) -> int:
    """LIGGGHTS' VTK dumps carry their timestep in the file name only (last number)."""
    digits = re.findall(r"\d+", path.name)
    return int(digits[-1]) if digits else 0


def _read_all(path: Path) -> bytes:
    try:
        with _open(path) as f:
            return f.read()
    except _STREAM_ERRORS as exc:
        raise _stream_problem(exc, path) from None


def _vtk_frame(path: Path) -> Frame:
    """One LIGGGHTS legacy-VTK particle file; every count is checked against the data."""
    raw = _read_all(path)
    head, sep, body = raw.partition(b"\nPOINTS ")
    if not sep or b"DATASET POLYDATA" not in head:
        raise ReadError(f"{path}: not a LIGGGHTS particle VTK file (no POLYDATA points)")
    lines = head.split(b"\n")
    if len(lines) > 2 and lines[2].strip() == b"BINARY":
        raise ReadError(f"{path}: binary VTK is not supported; write ASCII (dump_modify binary no)")
    if not raw.endswith(b"\n"):
        last = raw.count(b"\n") + 1
        raise ReadError(f"{path}: line {last}: the file ends in the middle of this line "
                        "(truncated file?)")
    tokens = body.split()

    def line_of(needle: bytes) -> int:
        at = raw.find(needle)
        return raw.count(b"\n", 0, at) + 1 + (needle.startswith(b"\n")) if at >= 0 else 0

    def fail(section: bytes, what: str):
        name = section.strip().decode("ascii", "replace")
        name = name if name.isprintable() else repr(section.strip())
        return ReadError(f"{path}: {name} (line {line_of(section)}): {what}")

    def count(i: int, section: bytes, what: str) -> int:
        t = tokens[i] if i < len(tokens) else b""
        if not re.fullmatch(rb"\d+", t):
            raise fail(section, f"expected the {what} (a count), found {_show(t) if t else 'the end of the file'}")
        return int(t)

    def numbers(i: int, size: int, section: bytes, what: str) -> np.ndarray:
        chunk = tokens[i:i + size]
        try:
            if len(chunk) < size or b"_" in b"".join(chunk):
                raise ValueError
            return np.asarray(chunk, dtype=np.float64)
        except ValueError:
            bad = next((t for t in chunk if not _NUMBER.fullmatch(t)), None)
            found = f"{_show(bad)} among them" if bad is not None else f"only {len(chunk)}"
            raise fail(section, f"expected {size} numbers ({what}), found {found}") from None

    points = b"\nPOINTS "
    n = count(0, points, "number of points")
    pos = numbers(2, 3 * n, points, f"x y z of {n} points").reshape(n, 3)
    if 2 + 3 * n < len(tokens) and _NUMBER.fullmatch(tokens[2 + 3 * n]):
        raise fail(points, f"announces {n} points, but more numbers follow their x y z")
    columns: dict[str, np.ndarray] = {"x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]}
    try:
        i = tokens.index(b"POINT_DATA", 2 + 3 * n)
    except ValueError:
        i = len(tokens)
    if i < len(tokens):
        pdata = b"\nPOINT_DATA "
        if count(i + 1, pdata, "number of points") != n:
            raise fail(pdata, f"announces {int(tokens[i + 1])} points, POINTS has {n}")
    if i + 2 < len(tokens) and tokens[i + 2] == b"FIELD":
        fdata = b"\nFIELD "
        nfields = count(i + 4, fdata, "number of arrays")
        j = i + 5
        for _ in range(nfields):
            if j + 4 > len(tokens):
                raise fail(fdata, f"announces {nfields} arrays, the file ends before all of them")
            name = tokens[j].decode("ascii", "replace")
            if not name.isprintable() or "\ufffd" in name:
                raise fail(fdata, f"array name {_show(tokens[j])} is not plain text")
            section = b"\n" + tokens[j] + b" "
            ncomp = count(j + 1, section, "number of components")
            ntup = count(j + 2, section, "number of tuples")
            if ntup != n or ncomp < 1:
                raise fail(section, f"{ntup} tuples of {ncomp} components; expected {n} tuples (one per point)")
            values = numbers(j + 4, ncomp * ntup, section, f"{ntup} x {ncomp} values").reshape(ntup, ncomp)
            j += 4 + ncomp * ntup
            if ncomp == 1:
                columns[name] = values[:, 0]
            else:
                names = _VTK_VECTORS.get(name, tuple(f"{name}{k + 1}" for k in range(ncomp)))
                for k, col in enumerate(names[:ncomp]):
                    columns[col] = values[:, k]
        if j < len(tokens) and tokens[j] not in (b"CELL_DATA", b"POINT_DATA", b"FIELD"):
            raise fail(fdata, f"announces {nfields} arrays, but more follow ({_show(tokens[j])} ...)")
    data = pd.DataFrame(columns)
    step = _vtk_step(path)
    _to_int_columns(data, path, step, None)
    box = np.column_stack([pos.min(axis=0), pos.max(axis=0)]) if n else np.zeros((3, 2))
    return Frame(step, box, data, "atoms", (), str(path), {"box_from_points": True})


# ----------------------------------------------------------------------------------------

def read_frames(source, columns: Sequence[str] | None = None, every: int = 1,
                steps: Iterable[int] | None = None) -> Iterator[Frame]:
    """Yield the frames of ``source`` (file, glob, folder or list) in file order.

    ``columns`` renames the data columns (needed for dump local files whose header says only
    ``c_pl[1] c_pl[2] ...``; see :func:`local_columns`). ``every`` keeps every n-th frame;
    ``steps`` keeps only the listed timesteps.
    """
    if every < 1:
        raise ValueError("every must be >= 1")
    wanted = None if steps is None else set(int(s) for s in steps)
    k = 0
    for path in dump_files(source):
        name = path.name[:-3] if path.name.endswith(".gz") else path.name
        if name.endswith(".vtk"):
            frames = [_vtk_frame(path)] if wanted is None or _vtk_step(path) in wanted else []
        else:
            frames = _text_frames(path, columns, wanted)   # unwanted frames are skipped unparsed
        for frame in frames:
            if k % every == 0:
                yield frame
            k += 1


def read_dump(source, columns: Sequence[str] | None = None) -> list[Frame]:
    """All frames of ``source`` as a list (small files; use :func:`read_frames` to stream)."""
    return list(read_frames(source, columns))


def last_frame(source, columns: Sequence[str] | None = None) -> Frame:
    frame = None
    for frame in read_frames(source, columns):
        pass
    if frame is None:
        names = [str(p) for p in dump_files(source)]
        raise ReadError(f"{', '.join(names[:3])}{', ...' if len(names) > 3 else ''}: no frames (empty file?)")
    return frame


#: the per-atom columns of a LIGGGHTS primitive wall's contact dump (siloflow.engine.liggghts.side_walls):
#: the touching grain, then its stored wall force (``f_force_<fix>[1..3]``, the force on the grain, N)
PRIMITIVE_CONTACT_COLUMNS = ["id", "x", "y", "z", "radius", "fx", "fy", "fz"]


def primitive_wall_contacts(frame: Frame, style: str, args: Sequence[float]) -> Frame:
    """A primitive wall's contact dump frame (one row per touching grain: :data:`PRIMITIVE_CONTACT_COLUMNS`)
    as a wall/gran/local frame: the contact point on the wall (``xw yw zw``: the grain centre's
    projection on a ``zcylinder`` of radius, axis x, y = ``args``, or on the plane ``xplane``/``yplane``
    at ``args[0]``), the grain's centre (``x1 y1 z1``), ``mesh``/``triangle`` -1, ``id1`` and the force on
    the grain (``fx fy fz``). A grain touches a primitive at most once, at its own height."""
    d = frame.data
    missing = [c for c in PRIMITIVE_CONTACT_COLUMNS if c not in d]
    if missing:
        raise ReadError(f"{frame.source}: a primitive wall's contact dump needs the columns {missing}")
    x, y, z = (d[c].to_numpy(float) for c in ("x", "y", "z"))
    if style == "zcylinder":
        radius, cx, cy = (float(a) for a in args)
        rx, ry = x - cx, y - cy
        rho = np.hypot(rx, ry)
        scale = np.divide(radius, rho, out=np.ones_like(rho), where=rho > 0)
        xw, yw = cx + rx * scale, cy + ry * scale
    elif style == "xplane":
        xw, yw = np.full_like(x, float(args[0])), y
    elif style == "yplane":
        xw, yw = x, np.full_like(y, float(args[0]))
    else:
        raise ReadError(f"{frame.source}: no contact point for a primitive wall of style {style!r}")
    n = len(d)
    data = pd.DataFrame({"xw": xw, "yw": yw, "zw": z, "x1": x, "y1": y, "z1": z,
                         "mesh": np.full(n, -1, np.int64), "triangle": np.full(n, -1, np.int64),
                         "id1": d["id"].to_numpy(np.int64),
                         "fx": d["fx"].to_numpy(float), "fy": d["fy"].to_numpy(float), "fz": d["fz"].to_numpy(float)})
    return Frame(frame.timestep, frame.box, data, kind="entries", boundary=frame.boundary, source=frame.source)


def frames_by_step(*streams: Iterable[Frame]) -> Iterator[Frame]:
    """The frames of several contact streams (e.g. mesh walls' and primitive walls') joined per
    timestep, in step order: one frame of each step holding every stream's rows there."""
    steps: dict[int, list[Frame]] = {}
    for stream in streams:
        for f in stream:
            steps.setdefault(f.timestep, []).append(f)
    for step in sorted(steps):
        parts = steps[step]
        data = pd.concat([p.data for p in parts], ignore_index=True) if len(parts) > 1 else parts[0].data
        first = parts[0]
        yield Frame(step, first.box, data, kind="entries", boundary=first.boundary,
                    source=", ".join(p.source for p in parts))
