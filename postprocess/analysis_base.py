"""The one shape every frame analysis has (after MDAnalysis' AnalysisBase):

    analysis = Porosity(regions=...)
    analysis.run(frames, contacts=None)     # _prepare(); _single_frame(f, c) per frame; _conclude()
    analysis.results.table                  # tidy pandas DataFrame, one row per frame (and region/...)

An analysis computes: its output is data in :attr:`FrameAnalysis.results` (numbers, arrays,
DataFrames), and it writes no file and draws no figure. The report layer (``postprocess.report``)
writes tables and figures from results: ``report.files.write_analysis(analysis, folder)``.

``frames`` is any iterable of :class:`postprocess.dumps.Frame` (a dump path is read with
:func:`postprocess.dumps.read_frames`); ``contacts`` optionally gives the matching dump local
frames (paired by timestep), so the analyses run on any LIGGGHTS/LAMMPS output.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Iterator

import pandas as pd

from siloflow.errors import ReadError

from .dumps import Frame, read_frames


class Results(dict):
    """An analysis' output (MDAnalysis' ``Results``): a dict whose keys are also attributes."""

    def __getattr__(self, key):
        try:
            return self[key]
        except KeyError:
            raise AttributeError(key) from None

    def __setattr__(self, key, value):
        self[key] = value


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
    row dicts or None); ``_prepare``/``_conclude`` are optional and put what they compute in
    :attr:`results`. ``needs_contacts`` analyses refuse to run without contact frames unless they
    can derive contacts themselves.

    After :meth:`run`: ``results.table`` (the rows as a DataFrame, a ``step`` column first) and
    ``n_frames`` (frames analysed)."""

    name = "analysis"
    needs_contacts = False

    def __init__(self):
        self.rows: list[dict] = []
        self.results = Results(table=pd.DataFrame())
        self.n_frames = 0

    @property
    def table(self) -> pd.DataFrame:
        """``results.table``."""
        return self.results.table

    def run(self, frames, contacts=None, start: int = 0, stop: int | None = None, step: int = 1):
        frames = _as_frames(frames)
        contacts = _as_frames(contacts)
        if self.needs_contacts and contacts is None:
            raise ReadError(f"{self.name} needs contact (dump local) frames")
        self.rows = []
        self.n_frames = 0
        self.results = Results(table=pd.DataFrame())
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
        self.results.table = pd.DataFrame(self.rows)
        self._conclude()
        return self

    def _prepare(self) -> None:
        pass

    def _single_frame(self, frame: Frame, contacts: Frame | None) -> list[dict] | None:
        raise NotImplementedError

    def _conclude(self) -> None:
        pass
