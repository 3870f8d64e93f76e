"""A run folder's results/: the tables, the figures, summary.json, report.md and report.html,
written from what the analyses computed (``postprocess.run_results.RunResults``)."""
from __future__ import annotations

from pathlib import Path

from siloflow.atomic_files import write_json, write_text
from siloflow.run_folder import RESULT_TABLES, SUMMARY_NAME

from ..first_results import analyse_run
from ..run_results import RunResults
from .figures import analysis_figure, design_plot, first_results_plot, force_chain_plot, plt, sector_plot, wall_map_plot
from .files import write_figures, write_tables
from .html_page import report_html
from .text import markdown, report_blocks

#: the report files written beside the tables and figures
REPORT_MD, REPORT_HTML = "report.md", "report.html"


def run_figures(results: RunResults) -> dict:
    """The figures of a run's results, drawn, by file name in report order: wall_map.png (the wall
    unrolled, when it has sensor sectors), first_results.png,
    each frame analysis' (``<name>.png``), the force chains, sectors.png (an eccentric outlet's),
    design_loads.png."""
    figures: dict = {}
    try:
        sectors = results.tables.get(RESULT_TABLES["sectors"])
        if sectors is not None and len(sectors) and "arc_deg" in sectors:
            en = results.summary.get("design_loads") or {}
            figures["wall_map.png"] = wall_map_plot(sectors, en.get("bands") if en.get("computed") else None)
        figures["first_results.png"] = first_results_plot(results.bands, results.discharge, results.band_table,
                                                          results.t_open)
        for analysis in results.analyses:
            fig = analysis_figure(analysis)
            if fig is not None:
                figures[f"{analysis.name}.png"] = fig
        for name, chains in results.force_chains.items():
            figures[name] = force_chain_plot(chains)
        if results.summary.get("eccentric_discharge") and sectors is not None:
            figures["sectors.png"] = sector_plot(sectors)
        if results.design is not None:
            figures["design_loads.png"] = design_plot(results.design, results.band_table)
    except BaseException:
        for fig in figures.values():      # the figures drawn so far
            plt.close(fig)
        raise
    return figures


def write_report(out, name: str, summary: dict, tables: dict | None = None, figures: dict | None = None) -> None:
    """Write a run's results into the folder ``out`` (made if missing): ``tables`` ({file name:
    DataFrame}, ``.csv``/``.parquet``) and ``figures`` ({file name: Figure}, PNG, closed), then
    ``summary`` as summary.json (NaN as null), report.md and report.html (``text.report_blocks``;
    the figures' PNG as written, the CSV tables). ``name``: the run's."""
    out = Path(out)
    tables, figures = tables or {}, figures or {}
    try:
        write_tables(tables, out)
    except BaseException:
        for fig in figures.values():
            plt.close(fig)
        raise
    write_figures(figures, out)
    write_json(out / SUMMARY_NAME, summary)
    blocks = report_blocks(summary, name)
    write_text(out / REPORT_MD, markdown(blocks))
    pngs = {fname: (out / fname).read_bytes() for fname in figures}
    write_text(out / REPORT_HTML, report_html(blocks, name, tables, pngs))


def write_run(results: RunResults) -> dict:
    """Write a run's results (:func:`write_report` into ``results.out``, the figures drawn by
    :func:`run_figures`); returns the summary."""
    write_report(results.out, Path(results.folder).name, results.summary, results.tables, run_figures(results))
    return results.summary


def post_process(folder, measured_pressure=None) -> dict:
    """The results of a finished run folder, computed (``first_results.analyse_run``) and written
    to its results/ (:func:`write_run`); returns the summary."""
    return write_run(analyse_run(folder, measured_pressure))
