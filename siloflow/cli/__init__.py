"""Command line: ``siloflow validate | schema | render | example | run | post | status | cg | cg-scaling |
sweep | bench | stability | paper-a | beverloo | design | vtk | cache``.

The only package that prints, exits or sets up logging; everything else raises siloflow's named
errors, mapped here to a message and exit code 1. One module per group of commands
(``case_commands``, ``run_commands``, ``result_commands``, ``study_commands``, ``cache_commands``),
all registered on the one Typer ``app`` (``cli/app.py``).
"""
from __future__ import annotations

import sys

# the commands register on ``app`` in this order, which is the order ``siloflow --help`` lists them
from . import case_commands  # noqa: F401, I001
from . import run_commands  # noqa: F401
from . import result_commands  # noqa: F401
from . import study_commands  # noqa: F401
from . import cache_commands  # noqa: F401
from .app import app, err, printable
from .case_commands import profile_note

__all__ = ["app", "main", "printable", "profile_note"]


def main() -> None:
    """The ``siloflow`` command: the app, with an operating-system error (a file that cannot be
    read or written) told in one line rather than a traceback."""
    from ..atomic_files import os_error
    try:
        app()
    except OSError as exc:
        err.print("[bold red]siloflow: SetupError[/bold red]")
        err.print(printable(os_error(exc, exc.filename or "a file", "use")), markup=False, highlight=False)
        sys.exit(1)
