"""The report layer: writes what the analyses computed. Analyses return results (data:
numbers, arrays, DataFrames); this package alone writes files and draws figures.

- ``files``: tables (CSV, Parquet), frame analyses' results, NetCDF, atomically;
- ``figures``: matplotlib figures (Agg) from results, :func:`save_figure`;
- ``cg``: a coarse-graining's files and figures (``siloflow cg``);
- ``text``: the report's blocks, report.md and the console lines;
- ``html_page``: report.html, self-contained;
- ``run``: a run folder's results/ (:func:`post_process` = compute + :func:`write_run`);
- ``dumps``: ``siloflow post`` on any dump files.
"""
from __future__ import annotations

from .html_page import CONTENT_SECURITY_POLICY, HTML_TABLE_ROWS, html_blocks, report_html
from .run import REPORT_HTML, REPORT_MD, post_process, run_figures, write_report, write_run
from .text import (Items, Table, Text, Title, clog_line, console_lines, en_verdict_blocks, flow_rate_line,
                   janssen_lines, markdown, mobilisation_note, profile_line, report_blocks, report_text,
                   static_cell, steady_window_line, verdict_blocks)

__all__ = ["CONTENT_SECURITY_POLICY", "HTML_TABLE_ROWS", "REPORT_HTML", "REPORT_MD", "Items", "Table", "Text", "Title",
           "clog_line", "console_lines", "en_verdict_blocks", "flow_rate_line", "html_blocks", "janssen_lines",
           "markdown", "mobilisation_note", "post_process", "profile_line", "report_blocks", "report_html",
           "report_text", "run_figures", "static_cell", "steady_window_line", "verdict_blocks", "write_report",
           "write_run"]
