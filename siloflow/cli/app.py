"""The ``siloflow`` Typer app and what every command shares: the consoles, terminal-safe text and the error exit."""
from __future__ import annotations

import typer
from rich.console import Console

from ..errors import ANSI_ESCAPES, CaseError, SiloflowError

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Silo discharge DEM simulations: case file -> LIGGGHTS deck -> run -> results.")
err = Console(stderr=True)
out = Console()


def printable(text: str) -> str:
    """``text`` safe for a terminal: escape sequences removed, other control characters and
    undecodable bytes shown as escapes (engine output and case keys can hold anything)."""
    text = ANSI_ESCAPES.sub("", str(text))
    return "".join(c if c in "\n\t" or c.isprintable() else repr(c)[1:-1] for c in text)


def _fail(exc: SiloflowError) -> None:
    kind = "invalid case" if isinstance(exc, CaseError) else type(exc).__name__
    err.print(f"[bold red]siloflow: {kind}[/bold red]")
    err.print(printable(exc), markup=False, highlight=False)
    raise typer.Exit(1)
def _note(text: str) -> None:
    """One line of a study's progress (engine output stripped of escapes), on stderr."""
    err.print(printable(text), markup=False, highlight=False)
