"""The ``siloflow`` Typer app and what every command shares: the consoles, terminal-safe text and the error exit."""
from __future__ import annotations

from typing import Optional

import typer
from rich.console import Console

from .._version import __version__
from ..engines import ENGINES
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


def versions() -> list[str]:
    """One line for siloflow's version and one for each engine of the registry: its version, or
    why it cannot run here (not installed, and what to install)."""
    from ..engine import get_engine
    lines = [f"siloflow {__version__}"]
    for name in ENGINES:
        try:
            lines.append(f"{name}: {get_engine(name).version()}")
        except Exception as exc:                # a missing engine is a line, not a failure
            lines.append(f"{name}: not available ({type(exc).__name__}: {exc})")
    return lines


def _print_versions(value: bool) -> None:
    if value:
        for line in versions():
            out.print(printable(line), markup=False, highlight=False, soft_wrap=True)
        raise typer.Exit()


@app.callback()
def _options(version: Optional[bool] = typer.Option(
        None, "--version", callback=_print_versions, is_eager=True,
        help="Print siloflow's version and each engine's (or why it is not available), and exit.")) -> None:
    """Silo discharge DEM simulations: case file -> LIGGGHTS deck -> run -> results."""
