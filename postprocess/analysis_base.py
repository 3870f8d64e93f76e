"""The one shape every frame analysis has (after MDAnalysis' AnalysisBase):

    analysis = Porosity(regions=...)
    analysis.run(frames, contacts=None)     # _prepare(); _single_frame(f, c) per frame; _conclude()
    analysis.table                          # tidy pandas DataFrame, one row per frame (and region/...)
    analysis.save(folder)                   # <name>.csv, <name>.parquet and <name>.png, atomically
    analysis.products()                     # the same files in memory, for a report layer: Products

``frames`` is any iterable of :class:`postprocess.dumps.Frame` (a dump path is read with
:func:`postprocess.dumps.read_frames`); ``contacts`` optionally gives the matching dump local
frames (paired by timestep), so the analyses run on any LIGGGHTS/LAMMPS output.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Iterator, NamedTuple

import pandas as pd

from siloflow.atomic_files import atomic_path, write_text
from siloflow.errors import ReadError

from .dumps import Frame, read_frames
from .figures import plt, save_figure


class Products(NamedTuple):
    """What an analysis hands a report layer (``postprocess.report``) to write, in writing order:
    ``tables`` {file name (``.csv``, ``.parquet``): pandas DataFrame, written without its index},
    ``figures`` {file name (``.png``): matplotlib Figure}."""
    tables: dict
    figures: dict

    def add(self, other: "Products") -> "Products":
        """Add ``other``'s files (a name already here is replaced); returns self."""
        self.tables.update(other.tables)
        self.figures.update(other.figures)
        return self

    def close(self) -> None:
        """Close the figures unwritten (a failed analysis' own, which pyplot would keep open)."""
        for fig in self.figures.values():
            plt.close(fig)

    def write(self, folder) -> list[Path]:
        """Write the tables (``.csv``, ``.parquet``; without the index) and the figures (PNG) into
        ``folder`` (made if missing), each atomically; the figures are closed, written or not.
        Returns the paths written."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        written = []
        try:
            for fname, table in self.tables.items():
                path = folder / fname
                if path.suffix == ".csv":
                    write_text(path, table.to_csv(index=False))
                elif path.suffix == ".parquet":
                    try:
                        with atomic_path(path) as tmp:
                            table.to_parquet(tmp, index=False)
                    except ImportError:  # pyarrow is a dependency; a missing one only loses the Parquet copy
                        continue
                else:
                    raise ValueError(f"{fname}: a table is written as .csv or .parquet")
                written.append(path)
            for fname, fig in self.figures.items():
                save_figure(fig, folder / fname)
                written.append(folder / fname)
        finally:
            self.close()
        return written


def _as_frames(source) -> Iterable[Frame] | None:
    if source is None:
        return None
    if isinstance(source, (str, Path)):
        return read_frames(source)
    return source


class StepCursor:
    """Walks a stream of frames in increasing timestep order and hands out the frame of a given
    step (None if the stream has none), never going back."""

    def __init__(self, frames: Iterable[Frame]):
        self._it = iter(frames)
        self._current = next(self._it, None)

    def at(self, step: int) -> Frame | None:
        while self._current is not None and self._current.timestep < step:
            self._current = next(self._it, None)
        c = self._current
        return c if c is not None and c.timestep == step else None


def paired(frames: Iterable[Frame], contacts: Iterable[Frame] | None) -> Iterator[tuple[Frame, Frame | None]]:
    """Pair atom frames with contact frames of the same timestep (both in increasing step order);
    atom frames with no contact frame get None when ``contacts`` is None, else are skipped."""
    if contacts is None:
        for f in frames:
            yield f, None
        return
    cursor = StepCursor(contacts)
    for f in frames:
        c = cursor.at(f.timestep)
        if c is not None:
            yield f, c


class FrameAnalysis:
    """Base class: subclasses set ``name`` and implement ``_single_frame`` (returning a list of
    row dicts or None); ``_prepare``/``_conclude`` are optional. ``needs_contacts`` analyses
    refuse to run without contact frames unless they can derive contacts themselves."""

    name = "analysis"
    needs_contacts = False

    def __init__(self):
        self.rows: list[dict] = []
        self.table = pd.DataFrame()
        self.n_frames = 0

    def run(self, frames, contacts=None, start: int = 0, stop: int | None = None, step: int = 1):
        frames = _as_frames(frames)
        contacts = _as_frames(contacts)
        if self.needs_contacts and contacts is None:
            raise ReadError(f"{self.name} needs contact (dump local) frames")
        self.rows = []
        self.n_frames = 0
        self._prepare()
        for k, (frame, cframe) in enumerate(paired(frames, contacts)):
            if k < start or (stop is not None and k >= stop) or (k - start) % step:
                continue
            out = self._single_frame(frame, cframe)
            self.n_frames += 1
            if out:
                for row in out:
                    self.rows.append({"step": frame.timestep, **row})
        if self.n_frames == 0:
            raise ReadError(f"{self.name}: no frames to analyse")
        self.table = pd.DataFrame(self.rows)
        self._conclude()
        return self

    def _prepare(self) -> None:
        pass

    def _single_frame(self, frame: Frame, contacts: Frame | None) -> list[dict] | None:
        raise NotImplementedError

    def _conclude(self) -> None:
        pass

    def plot(self):
        """The analysis' figure (a matplotlib Figure); None if it has none."""
        return None

    def products(self, figure: bool = True) -> Products:
        """What :meth:`save` writes, in memory, for a report layer to write: ``<name>.csv`` and
        ``<name>.parquet`` (:attr:`table`), ``<name>.png`` (:meth:`plot`; none without ``figure``,
        for an empty table or for an analysis without a figure)."""
        fig = self.plot() if figure and not self.table.empty else None
        return Products({f"{self.name}.csv": self.table, f"{self.name}.parquet": self.table},
                        {} if fig is None else {f"{self.name}.png": fig})

    def save(self, folder, figure: bool = True) -> list[Path]:
        """Write ``<name>.csv`` (and ``.parquet``) and the figure into ``folder`` (:meth:`products`)."""
        return self.products(figure).write(folder)
