"""Read LIGGGHTS/LAMMPS dump files: per-atom ``dump custom``, contact ``dump local`` and
LIGGGHTS' legacy-VTK ``dump custom/vtk``, plain or gzip-compressed, one or many frames per
file, with a particle count that may change from frame to frame (filling, discharge).

Frames are streamed one at a time (memory is one frame), each parsed by pandas' C parser.
Positions given as ``xs``/``xu``/``x`` are all returned as unwrapped-or-plain Cartesian
``x y z`` in the dump's length unit (SI for our decks).

    for frame in read_frames("output/dumps/particles_*.dump.gz"):
        frame.positions()       # (n, 3) m
        frame.data["radius"]    # any column by its name in the file
"""
from __future__ import annotations

import glob
import gzip
import io
import re
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np
import pandas as pd

from siloflow.engine_output import PAIR_LOCAL_LAYOUT, local_columns  # noqa: F401 (re-exported)
from siloflow.errors import ReadError

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
        """(n, 3) Cartesian positions, from x/xu or scaled xs/xsu columns."""
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

def _open(path: Path):
    with open(path, "rb") as probe:
        magic = probe.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb", buffering=1 << 20)


def _expect(f, prefix: bytes, path: Path) -> bytes:
    line = f.readline()
    if not line.startswith(prefix):
        raise ReadError(f"{path}: expected '{prefix.decode()}', found {line[:60]!r}")
    return line


def _parse_block(block: bytes, names: list[str], n: int, path: Path, step: int) -> pd.DataFrame:
    if n == 0:
        return pd.DataFrame({c: np.empty(0) for c in names})
    try:
        data = pd.read_csv(io.BytesIO(block), sep=r"\s+", header=None, names=names, engine="c",
                           dtype=np.float64, na_filter=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise ReadError(f"{path}: frame at step {step}: cannot parse the data lines ({exc})") from None
    if len(data) != n:
        raise ReadError(f"{path}: frame at step {step} announces {n} rows but has {len(data)} (truncated file?)")
    for col in ("id", "type", "mol", "id1", "id2", "periodic", "mesh", "triangle", "ix", "iy", "iz"):
        if col in data:
            data[col] = data[col].astype(np.int64)
    return data


def _text_frames(path: Path, columns: Sequence[str] | None, wanted: set | None = None) -> Iterator[Frame]:
    with _open(path) as f:
        while True:
            line = f.readline()
            if not line:
                return
            if not line.strip():
                continue
            if not line.startswith(b"ITEM: TIMESTEP"):
                raise ReadError(f"{path}: not a LAMMPS/LIGGGHTS text dump (expected 'ITEM: TIMESTEP', "
                                f"found {line[:60]!r})")
            try:
                step = int(f.readline().split()[0])
                count_item = f.readline()
                if not count_item.startswith((b"ITEM: NUMBER OF ATOMS", b"ITEM: NUMBER OF ENTRIES")):
                    raise ReadError(f"{path}: step {step}: expected 'ITEM: NUMBER OF ...', found {count_item[:60]!r}")
                kind = "atoms" if b"ATOMS" in count_item else "entries"
                n = int(f.readline().split()[0])
                box_line = _expect(f, b"ITEM: BOX BOUNDS", path).decode().split()[3:]
                triclinic = bool(box_line) and box_line[0] == "xy"
                bounds = [f.readline().split() for _ in range(3)]
                box = np.array([[float(b[0]), float(b[1])] for b in bounds])
                header = _expect(f, b"ITEM: ATOMS" if kind == "atoms" else b"ITEM: ENTRIES", path)
            except (IndexError, ValueError):
                raise ReadError(f"{path}: malformed frame header near byte {f.tell()}") from None
            names = header.decode().split()[2:]
            if columns is not None:
                if len(columns) != len(names):
                    raise ReadError(f"{path}: {len(columns)} column names given for {len(names)} columns "
                                    f"({' '.join(names)})")
                names = list(columns)
            if len(set(names)) != len(names):
                raise ReadError(f"{path}: repeated column names {names}; pass column names explicitly")
            if wanted is not None and step not in wanted:   # skip the rows unparsed
                for _ in islice(f, n):
                    pass
                continue
            block = b"".join(islice(f, n))
            data = _parse_block(block, names, n, path, step)
            boundary = tuple(box_line[3:] if triclinic else box_line)
            yield Frame(step, box, data, kind, boundary, str(path), {"triclinic": triclinic})


# ----------------------------------------------------------------------------------------
# LIGGGHTS legacy VTK (dump custom/vtk)

def _vtk_step(path: Path) -> int:
    """LIGGGHTS' VTK dumps carry their timestep in the file name only (last number)."""
    digits = re.findall(r"\d+", path.name)
    return int(digits[-1]) if digits else 0


def _vtk_frame(path: Path) -> Frame:
    with _open(path) as f:
        raw = f.read()
    head, _, body = raw.partition(b"\nPOINTS ")
    if not body or b"DATASET POLYDATA" not in head:
        raise ReadError(f"{path}: not a LIGGGHTS particle VTK file (no POLYDATA points)")
    lines = head.split(b"\n")
    if len(lines) > 2 and lines[2].strip() == b"BINARY":
        raise ReadError(f"{path}: binary VTK is not supported; write ASCII (dump_modify binary no)")
    tokens = body.split()
    n = int(tokens[0])
    pos = np.asarray(tokens[2:2 + 3 * n], dtype=float).reshape(n, 3)
    columns: dict[str, np.ndarray] = {"x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]}
    try:
        i = tokens.index(b"POINT_DATA", 2 + 3 * n)
    except ValueError:
        i = len(tokens)
    if i < len(tokens) and tokens[i + 2] == b"FIELD":
        nfields = int(tokens[i + 4])
        j = i + 5
        for _ in range(nfields):
            name, ncomp, ntup = tokens[j].decode(), int(tokens[j + 1]), int(tokens[j + 2])
            values = np.asarray(tokens[j + 4:j + 4 + ncomp * ntup], dtype=float).reshape(ntup, ncomp)
            j += 4 + ncomp * ntup
            if ncomp == 1:
                columns[name] = values[:, 0]
            else:
                names = _VTK_VECTORS.get(name, tuple(f"{name}{k + 1}" for k in range(ncomp)))
                for k, col in enumerate(names[:ncomp]):
                    columns[col] = values[:, k]
    data = pd.DataFrame(columns)
    for col in ("id", "type", "ix", "iy", "iz"):
        if col in data:
            data[col] = data[col].astype(np.int64)
    step = _vtk_step(path)
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
        raise ReadError(f"{source}: no frames")
    return frame
