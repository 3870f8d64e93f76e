"""``siloflow post`` on dump files of any LIGGGHTS/LAMMPS run: the results folder, written from
``postprocess.any_dump.DumpResults``: each analysis' tables and figure (frames, porosity,
coordination), force_chains_last.png, summary.json and README.txt."""
from __future__ import annotations

from pathlib import Path

from siloflow.atomic_files import write_json, write_text
from siloflow.errors import SetupError
from siloflow.run_folder import SUMMARY_NAME

from ..any_dump import DumpResults, analyse_dump_files
from ..dumps import dump_files
from .figures import force_chain_plot
from .files import write_analysis, write_figures


def _results_folder(out: Path, create: bool) -> None:
    """Check (and with ``create``, make) the results folder ``out``: SetupError if a file is in
    the way or it cannot be made."""
    for p in (out, *out.parents):
        if p.exists() and not p.is_dir():
            what = "is" if p == out else f"(in the results folder's path {out}) is"
            raise SetupError(f"{p} {what} a file, not a folder; give a results folder with -o")
        if p.exists():
            break
    if create:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SetupError(f"cannot create the results folder {out}: {exc.strerror or exc}") from None


def write_dump_results(results: DumpResults, out) -> dict:
    """Write :class:`DumpResults` into the folder ``out``; returns the summary."""
    out = Path(out)
    for analysis in results.analyses:
        write_analysis(analysis, out)
    if results.force_chains is not None:
        write_figures({"force_chains_last.png": force_chain_plot(results.force_chains)}, out)
    write_json(out / SUMMARY_NAME, results.summary)
    write_text(out / "README.txt", "siloflow post on dump files: frames.csv (counts, energy), porosity.csv "
               f"(exact overlap volumes in measurement spheres), coordination.csv, {SUMMARY_NAME}\n")
    return results.summary


def analyse_any(source, out, contacts=None, contact_columns=None, spheres=None, every: int = 1) -> dict:
    """Analyse the dumps ``source`` (file, glob or folder; ``any_dump.analyse_dump_files``) and
    write tables, figures and summary.json to ``out`` (checked before the long read, made after it)."""
    out = Path(out)
    files = dump_files(source)
    _results_folder(out, create=False)     # before the (long) read
    results = analyse_dump_files(files, contacts, contact_columns, spheres, every)
    _results_folder(out, create=True)
    return write_dump_results(results, out)
