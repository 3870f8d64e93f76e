"""report.html: the report's blocks (``report.text``), every figure embedded as a base64 PNG,
every CSV table. Self-contained: its style is inline, a Content-Security-Policy forbids every
request but ``data:`` images, and it holds no script, no link and no external URL; every text
is escaped (``html.escape``)."""
from __future__ import annotations

import base64
import html

import pandas as pd

from .card import Card
from .text import CARD_HEADER, Heading, Items, Link, Table, Title

#: report.html allows nothing but data: images and its own inline style
CONTENT_SECURITY_POLICY = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
#: the figures report.html shows right below the summary card: the wall unrolled
LEAD_FIGURES = ("wall_map.png",)
#: report.html shows a table of at most this many rows whole, a longer one as per-column statistics
HTML_TABLE_ROWS = 200

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 1.5em auto; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ccc; }
h3 { font-size: 1em; margin-top: 1.5em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.85em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; vertical-align: top; }
th { background: #f0f0f0; } td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0; } img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; } .note { color: #555; font-size: 0.9em; }
.wide { overflow-x: auto; }
section.card { border: 2px solid #2b5d8a; border-radius: 6px; padding: 0.3em 0.8em; margin: 0.8em 0 1.5em;
  background: #f5f9fc; }
table.card { border: none; width: 100%; margin: 0.3em 0; font-size: 0.95em; }
table.card th, table.card td { border: none; border-bottom: 1px solid #d5e0ea; text-align: left; padding: 0.35em 0.5em; }
table.card thead th { background: none; color: #555; font-weight: normal; font-size: 0.85em; }
table.card tbody th { white-space: nowrap; width: 14em; } table.card td.value { font-weight: bold; font-size: 1.1em; width: 22em; }
table.card td.detail { color: #444; font-size: 0.85em; }
"""


def _esc(text) -> str:
    """Text for an HTML text node (``&``, ``<``, ``>`` escaped; quotes kept, as report.md has them)."""
    return html.escape(str(text), quote=False)


def _html_items(b: Items) -> str:
    """A nested <ul> of Markdown bullets ``- `` and ``  - ``."""
    items: list[tuple[str, list[str]]] = []
    for line in b.lines:
        if line.startswith("  - ") and items:
            items[-1][1].append(line[4:])
        else:
            items.append((line[2:] if line.startswith("- ") else line, []))
    lis = "".join(f"<li>{_esc(text)}" + (f"<ul>{''.join(f'<li>{_esc(s)}</li>' for s in subs)}</ul>" if subs else "")
                  + "</li>\n" for text, subs in items)
    return (f"<p>{_esc(b.lead)}</p>\n" if b.lead else "") + f"<ul>\n{lis}</ul>"


def _html_card(card: Card) -> str:
    """The summary card: a table of one row per answer (id ``card-<key>``), the value set large."""
    head = "".join(f"<th>{_esc(h)}</th>" for h in CARD_HEADER)
    rows = "".join(f'<tr id="card-{_esc(r.key)}"><th scope="row">{_esc(r.label)}</th><td class="value">{_esc(r.value)}'
                   f'</td><td class="detail">{_esc(r.detail)}</td></tr>\n' for r in card.rows)
    return (f'<section class="card" id="summary-card">\n<table class="card">\n<thead><tr>{head}</tr></thead>\n'
            f"<tbody>\n{rows}</tbody>\n</table>\n</section>")


def _html_cell(cell) -> str:
    """A table cell: its text escaped; a :class:`Link` as ``<a href>`` (its URL escaped too)."""
    if isinstance(cell, Link):
        return f'<a href="{html.escape(cell.href, quote=True)}">{_esc(cell.text)}</a>'
    return _esc(cell)


def html_blocks(blocks) -> str:
    """The blocks as HTML, every text escaped."""
    out = []
    for b in blocks:
        if isinstance(b, Title):
            out.append(f"<h1>{_esc(b.text)}</h1>")
        elif isinstance(b, Heading):
            out.append(f"<h2>{_esc(b.text)}</h2>")
        elif isinstance(b, Card):
            out.append(_html_card(b))
        elif isinstance(b, Items):
            out.append(_html_items(b))
        elif isinstance(b, Table):
            head = "".join(f"<th>{_esc(h)}</th>" for h in b.header)
            body = "".join("<tr>" + "".join(f"<td>{_html_cell(c)}</td>" for c in row) + "</tr>\n" for row in b.rows)
            out.append(f"<table>\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody>\n</table>")
        else:
            out.append(f"<p>{_esc(b.text)}</p>")
    return "\n".join(out)


# ---------------------------------------------------------------- report.html

def _html_table(name: str, table: pd.DataFrame) -> str:
    """One written table: whole up to :data:`HTML_TABLE_ROWS` rows, else its per-column statistics."""
    head = f"<h3>{_esc(name)}</h3>\n"
    if len(table) <= HTML_TABLE_ROWS:
        return head + f'<div class="wide">{table.to_html(index=False, border=0, na_rep="nan", escape=True)}</div>'
    return (head + f'<p class="note">{len(table)} rows x {len(table.columns)} columns; per-column statistics:</p>\n'
            f'<div class="wide">{table.describe().to_html(border=0, na_rep="nan", escape=True)}</div>')


def _html_figure(fname: str, png: bytes) -> str:
    """One figure, embedded as a base64 ``data:`` URL, captioned with its file name."""
    return (f'<figure><img src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}" '
            f'alt="{html.escape(fname, quote=True)}"><figcaption>{_esc(fname)}</figcaption></figure>')


def report_html(blocks, name: str, tables: dict, figures: dict, title: str | None = None,
                lead_figures=LEAD_FIGURES, tables_where: str = "beside this report (results/)") -> str:
    """report.html: the report's blocks, every figure (``figures``: file name -> PNG bytes)
    embedded as a base64 ``data:`` URL, and every CSV table (``tables``: file name -> DataFrame).
    The figures named in ``lead_figures`` follow the summary card (the blocks' first :class:`Card`),
    the others come after the blocks. ``title``: the page's title (default "Run report: ``name``");
    ``tables_where``: where the tables are, as the Tables section says."""
    blocks = list(blocks)
    cut = next((k + 1 for k, b in enumerate(blocks) if isinstance(b, Card)), 0)
    lead = {f: figures[f] for f in lead_figures if f in figures and cut}
    figs = "\n".join(_html_figure(fname, png) for fname, png in figures.items() if fname not in lead)
    csvs = "\n".join(_html_table(fname, t) for fname, t in tables.items() if fname.endswith(".csv"))
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{CONTENT_SECURITY_POLICY}\">\n"
        f"<title>{_esc(title or f'Run report: {name}')}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
        f"{html_blocks(blocks[:cut])}\n"
        + "".join(f"{_html_figure(fname, png)}\n" for fname, png in lead.items())
        + f"{html_blocks(blocks[cut:])}\n"
        + (f"<h2>Figures</h2>\n{figs}\n" if figs else "")
        + (f"<h2>Tables</h2>\n<p class=\"note\">The tables written {_esc(tables_where)}.</p>\n{csvs}\n"
           if csvs else "")
        + "</body>\n</html>\n")
