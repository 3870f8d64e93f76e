"""Writing results: tables (CSV, Parquet), figures (PNG, ``report.figures.save_figure``), frame
analyses' results and NetCDF fields, each atomically (``siloflow.atomic_files``)."""
from __future__ import annotations

from pathlib import Path

from siloflow.atomic_files import atomic_path, write_text

from .figures import analysis_figure, plt, save_figure


def write_table(table, path) -> bool:
    """Write a DataFrame without its index as ``path``'s suffix says (``.csv`` or ``.parquet``);
    False when the Parquet copy cannot be written (pyarrow missing: a dependency, so only that
    copy is lost), else True. ValueError for another suffix."""
    path = Path(path)
    if path.suffix == ".csv":
        write_text(path, table.to_csv(index=False))
    elif path.suffix == ".parquet":
        try:
            with atomic_path(path) as tmp:
                table.to_parquet(tmp, index=False)
        except ImportError:
            return False
    else:
        raise ValueError(f"{path.name}: a table is written as .csv or .parquet")
    return True


def write_tables(tables: dict, folder) -> list[Path]:
    """Write ``tables`` ({file name: DataFrame}) into ``folder`` (made if missing), in order;
    returns the paths written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return [folder / name for name, table in tables.items() if write_table(table, folder / name)]


def write_figures(figures: dict, folder) -> list[Path]:
    """Write ``figures`` ({file name: matplotlib Figure}) into ``folder``, each closed, written or
    not; returns the paths written."""
    folder = Path(folder)
    written = []
    try:
        for name, fig in figures.items():
            save_figure(fig, folder / name)
            written.append(folder / name)
    finally:
        for fig in figures.values():
            plt.close(fig)
    return written


def write_analysis(analysis, folder, figure: bool = True) -> list[Path]:
    """Write a frame analysis' results into ``folder``: ``<name>.csv`` and ``<name>.parquet``
    (``results.table``) and, with ``figure``, ``<name>.png`` (``report.figures.analysis_figure``,
    none for an empty table). Returns the paths written."""
    table = analysis.results.table
    written = write_tables({f"{analysis.name}.csv": table, f"{analysis.name}.parquet": table}, folder)
    fig = analysis_figure(analysis) if figure else None
    if fig is not None:
        written += write_figures({f"{analysis.name}.png": fig}, folder)
    return written


def write_netcdf(dataset, path) -> Path:
    """Write an xarray Dataset as NetCDF to ``path``, atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    dataset.to_netcdf(tmp)
    tmp.replace(path)
    return path


def write_coarse_graining(cg, folder) -> list[Path]:
    """Write a :class:`postprocess.coarse_grain.CoarseGraining`'s results into ``folder``:
    ``coarse_graining.csv`` and ``.parquet`` (its table) and ``fields.nc`` (the time-averaged
    ``dataset()``, NetCDF). Returns the paths written."""
    return write_analysis(cg, folder, figure=False) + [write_netcdf(cg.dataset(), Path(folder) / "fields.nc")]
