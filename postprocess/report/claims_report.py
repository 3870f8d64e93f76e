"""A paper's claims report: the claim rows (``postprocess.paper_a.ClaimRow``) as a table with
verdicts, the tables and figures behind them, written as report.md and a self-contained
report.html (``html_page``), and the data that regenerates both (``data/``) without a run."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from siloflow.atomic_files import write_text

from ..claims import CONFIDENCE, Estimate
from .files import write_figures, write_tables
from .html_page import report_html
from .text import Items, Table, Text, Title, markdown

#: the data folder beside a report, from which it is regenerated
DATA = "data"


def _number(x: float) -> str:
    return f"{x:.4g}"


def ours_text(row) -> str:
    """Our value with its 95 % interval, or why there is none."""
    e = row.ours
    if e is None:
        return "not measured"
    lo, hi = e.interval(CONFIDENCE)
    unit = f" {row.unit}" if row.unit else ""
    return f"{_number(e.value)}{unit} [{_number(lo)}, {_number(hi)}]"


def claims_table(rows) -> Table:
    """The claims as a report table: section, claim, paper, ours [95 % interval], verdict, how."""
    return Table(["section", "claim", "paper", f"ours [{100 * CONFIDENCE:.0f} % interval]", "verdict", "how measured"],
                 [[r.section, r.claim, r.paper, ours_text(r), r.verdict, r.basis] for r in rows])


def rows_to_json(rows) -> list[dict]:
    """Claim rows as JSON-ready dicts (an estimate as value, stderr, dof; inf as null)."""
    out = []
    for r in rows:
        e = r.ours
        out.append({"section": r.section, "claim": r.claim, "paper": r.paper, "unit": r.unit, "verdict": r.verdict,
                    "basis": r.basis, "ours": None if e is None else
                    {"value": e.value, "stderr": e.stderr, "dof": None if math.isinf(e.dof) else e.dof}})
    return out


def rows_from_json(data: list[dict], row_type) -> list:
    """Claim rows (of ``row_type``) back from :func:`rows_to_json`."""
    rows = []
    for d in data:
        e = d.get("ours")
        ours = None if e is None else Estimate(e["value"], e["stderr"], math.inf if e["dof"] is None else e["dof"])
        rows.append(row_type(d["section"], d["claim"], d["paper"], ours, d["unit"], d["verdict"], d["basis"]))
    return rows


def write_claims_report(folder, title: str, lead: list, rows, tables: dict[str, pd.DataFrame],
                        figures: dict, data: dict) -> list[Path]:
    """Write report.md and report.html (blocks: ``title``, the ``lead`` paragraphs, the verdict
    counts, the claims table, then each table of ``tables``), the figures (file name ->
    Figure), the tables as CSV, and ``data/claims.json`` (the rows and ``data``) beside them.
    Returns the paths written."""
    folder = Path(folder)
    (folder / DATA).mkdir(parents=True, exist_ok=True)
    counts = {}
    for r in rows:
        counts[r.verdict] = counts.get(r.verdict, 0) + 1
    blocks = [Title(title), *[Text(t) for t in lead],
              Items([f"- {k}: {v}" for k, v in sorted(counts.items())], lead="Verdicts:"),
              claims_table(rows)]
    for name, table in tables.items():
        blocks.append(Text(f"{name}:"))
        blocks.append(Table(list(table.columns), [[_cell(v) for v in rec] for rec in table.itertuples(index=False)]))
    written = write_figures(figures, folder)
    pngs = {p.name: p.read_bytes() for p in written if p.suffix == ".png"}
    written += write_tables({f"{name}.csv": t for name, t in tables.items()}, folder / DATA)
    text = markdown(blocks) + "".join(f"\n![{name}]({name})\n" for name in pngs)
    write_text(folder / "report.md", text)
    write_text(folder / "report.html", report_html(blocks, title, {}, pngs, kind="Claims report"))
    write_text(folder / DATA / "claims.json", json.dumps({"rows": rows_to_json(rows), **data}, indent=1,
                                                         allow_nan=False) + "\n")
    return written + [folder / "report.md", folder / "report.html", folder / DATA / "claims.json"]


def _cell(value) -> str:
    if isinstance(value, float):
        return _number(value)
    return str(value)
