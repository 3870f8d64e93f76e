"""benchmarks/deck_vs_raw.py's hook in siloflow's LAMMPS MPI ranks: their chunks' loop split.

siloflow's LAMMPS driver runs each chunk as ``run N pre yes|no post no``, and with ``post no`` LAMMPS
prints the "Loop time" line alone, without the table of Pair, Neigh, Comm, Output, Modify and Other.
The bench puts this folder on the ranks' PYTHONPATH (``python -m siloflow.engine.lammps.worker``
imports this module at start-up) with ``SILOFLOW_BENCH_RUN_POST=yes``: the driver's LAMMPS object is
then wrapped so that each of its ``run ... post no`` commands is sent as ``run ... post yes``. Nothing
else changes: the same chunks, the same looks between them; the loop time LAMMPS reports is measured
before the ``post`` output, which adds only the summary's reductions and about 40 log lines per chunk
to the time outside the loop. Without the variable this module does nothing; siloflow's own files are
not touched.
"""
from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys

#: the environment variable that switches the hook on, and its value
SWITCH, ON = "SILOFLOW_BENCH_RUN_POST", "yes"
TARGET = "siloflow.engine.lammps.driver"


class RunPostProxy:
    """A LAMMPS object whose ``command`` sends ``run ... post no`` as ``run ... post yes``; every other
    attribute is the wrapped object's."""

    def __init__(self, lmp):
        self._lmp = lmp

    def command(self, line: str):
        words = line.split()
        if words[:1] == ["run"] and words[-2:] == ["post", "no"]:
            line = " ".join(words[:-1] + ["yes"])
        return self._lmp.command(line)

    def __getattr__(self, name):
        return getattr(self._lmp, name)


def patch(module) -> None:
    """Wrap the LAMMPS object of every ``Driver`` the driver module makes."""
    driver = module.Driver
    if getattr(driver.__init__, "_run_post", False):
        return
    init = driver.__init__

    def __init__(self, lmp, *args, **kwargs):
        init(self, RunPostProxy(lmp), *args, **kwargs)
    __init__._run_post = True
    driver.__init__ = __init__


class _PatchOnImport(importlib.abc.MetaPathFinder):
    """Patches the driver module as it is first imported, then steps aside."""

    def find_spec(self, name, path=None, target=None):
        if name != TARGET:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def run(module):
            exec_module(module)
            patch(module)
        spec.loader.exec_module = run
        return spec


if os.environ.get(SWITCH) == ON:
    if TARGET in sys.modules:
        patch(sys.modules[TARGET])
    else:
        sys.meta_path.insert(0, _PatchOnImport())
