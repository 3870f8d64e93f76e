"""Exception tree of siloflow.

Setup errors are raised before anything runs (bad case, missing engine),
run errors after the engine started, read errors while reading its output.
The CLI maps every one of them to a message and exit code 1; the library never
prints or exits.
"""
from __future__ import annotations

import re

#: terminal escape sequences (CSI ``ESC [ ... final``, OSC ``ESC ] ... BEL/ST``, two-byte ``ESC x``),
#: removed from engine output and case text before either reaches the terminal
ANSI_ESCAPES = re.compile(r"\x1b(\[[0-?]*[ -/]*[@-~]|\][^\x07\x1b]*(\x07|\x1b\\)?|[@-Z\\-_])")


class SiloflowError(Exception):
    """Base class of every error siloflow raises on purpose."""


class CaseError(SiloflowError):
    """Raised when a case file cannot be read or fails validation.

    ``problems`` is a list of ``(field_path, message)`` pairs, one per problem.
    """

    def __init__(self, problems: list[tuple[str, str]], source: str = "case"):
        self.problems = list(problems)
        self.source = source
        lines = [f"{source}: {len(self.problems)} problem(s)"]
        lines += [f"  {path}: {msg}" for path, msg in self.problems]
        super().__init__("\n".join(lines))


class SetupError(SiloflowError):
    """Raised before the engine starts: missing binary, folder in the way, disk, ranks."""


class EngineRunError(SiloflowError):
    """Raised when the engine ran but failed.

    Carries the command, exit code, run folder, the diagnosis (likely cause and fix)
    and the last lines of the engine's log.
    """

    def __init__(self, message: str, *, command=None, returncode=None, folder=None,
                 cause: str = "", fix: str = "", log_tail: str = ""):
        self.command = command
        self.returncode = returncode
        self.folder = folder
        self.cause = cause
        self.fix = fix
        self.log_tail = log_tail
        parts = [message]
        if cause:
            parts.append(f"likely cause: {cause}")
        if fix:
            parts.append(f"what to do: {fix}")
        if returncode is not None:
            parts.append(f"exit code: {returncode}")
        if folder is not None:
            parts.append(f"run folder (kept as it is): {folder}")
        if log_tail:
            parts.append("last lines of the engine log:\n" + log_tail)
        super().__init__("\n".join(parts))


class ReadError(SiloflowError):
    """Raised when engine output (log, tables, dumps) is missing or malformed."""
