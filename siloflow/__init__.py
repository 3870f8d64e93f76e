"""siloflow: silo discharge simulations with LIGGGHTS/LAMMPS, from a YAML case file to results.

``siloflow.open_run(folder)`` and ``siloflow.run(case, folder)`` return a ``Run`` (state,
summary, flow and wall-pressure tables, dump frames, coarse-grained fields, an MDAnalysis
Universe): see ``siloflow.runs``. Cases are read with ``Case.from_yaml(path)``
(``siloflow.case_file``) or validated from a dict with ``Case.model_validate(data)``
(``siloflow.case``), and changed with ``case.with_changes({"geometry.orifice_radius": 0.006})``. ``siloflow.design(case)`` gives a case's EN 1991-4
loads and ``siloflow.beverloo(folders)`` fits Beverloo's law across runs (``siloflow.answers``).
"""
from ._version import __version__

__all__ = ["Run", "open_run", "run", "design", "beverloo", "__version__"]


def __getattr__(name):
    """``Run``, ``open_run``, ``run``, ``design`` and ``beverloo`` load on first use (pandas is not
    imported with siloflow)."""
    if name in ("Run", "open_run", "run"):
        from . import runs
        return getattr(runs, name)
    if name in ("design", "beverloo"):
        from . import answers
        return getattr(answers, name)
    raise AttributeError(f"module 'siloflow' has no attribute {name!r}")
