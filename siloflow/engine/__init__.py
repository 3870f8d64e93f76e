"""Engines siloflow can drive, behind one interface (:class:`~siloflow.engine.base.Engine`).

Engines are registered by name and imported only when asked for (:func:`get_engine`); a new
engine is a subpackage with an ``Engine`` subclass, its deck writer and templates, and a line
in :data:`siloflow.engines.ENGINES`.
"""
from __future__ import annotations

from importlib import import_module

from ..engines import ENGINES
from ..errors import SetupError
from .base import Engine, LaunchProfile, RunRecord


def engine_class(name: str) -> type[Engine]:
    """The ``Engine`` subclass called ``name`` (``SetupError`` if there is none)."""
    try:
        module, cls = ENGINES[name].split(":")
    except KeyError:
        raise SetupError(f"unknown engine {name!r}; known: {', '.join(ENGINES)}") from None
    return getattr(import_module(module), cls)


def get_engine(name: str, **profile) -> Engine:
    """The engine called ``name``, configured for this machine by ``profile`` (executable, mpirun,
    env, or a ``LaunchProfile`` as ``profile=``)."""
    return engine_class(name)(**profile)


def __getattr__(name):
    if name == "LiggghtsEngine":          # old import path, without importing it eagerly
        return engine_class("liggghts")
    raise AttributeError(f"module 'siloflow.engine' has no attribute {name!r}")


__all__ = ["Engine", "LaunchProfile", "RunRecord", "get_engine", "engine_class", "ENGINES"]
