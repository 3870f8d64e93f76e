"""A paper's claims report (issue 38; papers A and B): the rows of
:class:`postprocess.claims.ClaimRow` as one table, in report.md and report.html, with the
figures as PNG beside them (and embedded in the HTML) and the result tables the report was made
from. Generic: the paper's own text and figures come as blocks and Matplotlib figures."""
from __future__ import annotations

from pathlib import Path

from siloflow.atomic_files import write_text

from ..claims import FAILS, HOLDS, NOT_RESOLVED, SHOWN, ClaimRow
from .files import write_figures, write_tables
from .html_page import report_html
from .text import Items, Table, Text, Title, markdown

REPORT_MD, REPORT_HTML = "report.md", "report.html"
#: the claims table's columns
CLAIM_HEADER = ["Claim", "Paper", "Ours", "Uncertainty", "Verdict", "Note"]
def _cell(text) -> str:
    """A table cell on one line; a ``|`` (which would split a Markdown cell) written as ``/``."""
    return " ".join(str(text).replace("|", "/").split())


def claims_table(rows: list[ClaimRow]) -> Table:
    """The claims as one table block (every cell on one line)."""
    return Table(list(CLAIM_HEADER), [[_cell(v) for v in (r.claim, r.paper, r.ours, r.uncertainty, r.verdict, r.note)]
                                      for r in rows])


def verdict_line(rows: list[ClaimRow]) -> Text:
    """'11 claims tested: 6 hold, 2 fail, 3 not resolved; 2 rows shown (figures).'"""
    n = {v: sum(r.verdict == v for r in rows) for v in (HOLDS, FAILS, NOT_RESOLVED, SHOWN)}
    tested = n[HOLDS] + n[FAILS] + n[NOT_RESOLVED]
    return Text(f"{tested} claims tested: {n[HOLDS]} hold, {n[FAILS]} fail, {n[NOT_RESOLVED]} not resolved; "
                f"{n[SHOWN]} rows shown without a test.")


VERDICT_LEGEND = Items([
    f"- {HOLDS}: the claim is true over the whole 95 % interval of our number (Student's t; claims "
    "made at several points or apertures at once held to 95 % jointly, Bonferroni);",
    f"- {FAILS}: it is false over the whole interval;",
    f"- {NOT_RESOLVED}: the interval holds values for which it is true and values for which it is false;",
    f"- {SHOWN}: a number or figure the paper states no testable claim about.",
], lead="Verdicts (computed by postprocess/claims.py from the numbers, never typed):")


def claims_blocks(title: str, intro: list, rows: list[ClaimRow], after: list | None = None,
                  figures: list | None = None) -> list:
    """The report's blocks: the title, ``intro`` blocks, the verdict count and legend, the claims
    table, ``after`` blocks and a Markdown image line per figure file name in ``figures``."""
    blocks = [Title(title), *intro, verdict_line(rows), VERDICT_LEGEND, claims_table(rows), *(after or [])]
    if figures:
        blocks.append(Text("## Figures"))
        blocks += [Text(f"![{name}]({name})") for name in figures]
    return blocks


def write_claims_report(folder, title: str, blocks: list, figures: dict | None = None,
                        tables: dict | None = None, results_dir: str | None = "results",
                        html_tables: dict | None = None) -> list[Path]:
    """Write a claims report into ``folder`` (made if missing): ``figures`` ({file name: Figure}:
    PNG beside the report, closed), ``tables`` ({file name: DataFrame}: CSV into
    ``folder/results_dir``), report.md (``blocks``) and report.html (the blocks, each figure
    embedded, ``html_tables`` shown whole or as statistics). Every file atomically; returns the
    paths written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    figures, tables = figures or {}, tables or {}
    written = write_tables(tables, folder / results_dir) if tables and results_dir else []
    written += write_figures(figures, folder)
    write_text(folder / REPORT_MD, markdown(blocks))
    pngs = {name: (folder / name).read_bytes() for name in figures}
    html_blocks = [b for b in blocks if not (isinstance(b, Text) and b.text.startswith("!["))]
    html_blocks = [Text(b.text.lstrip("# ")) if isinstance(b, Text) and b.text.startswith("## ") else b
                   for b in html_blocks]
    write_text(folder / REPORT_HTML, report_html(html_blocks, folder.name, html_tables or {}, pngs, title=title))
    return written + [folder / REPORT_MD, folder / REPORT_HTML]
