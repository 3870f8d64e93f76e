"""Engines siloflow can drive, behind one interface (:class:`~siloflow.engine.base.Engine`).

Engines are registered by name and imported only when asked for (:func:`get_engine`); a new
engine is a subpackage with an ``Engine`` subclass, its deck writer and templates, and a line
in :data:`siloflow.engines.ENGINES`.
"""
from __future__ import annotations

from ..engines import ENGINES
from .base import Engine, LaunchProfile, RunRecord
from .registry import engine_class, get_engine


def __getattr__(name):
    if name == "LiggghtsEngine":          # old import path, without importing it eagerly
        return engine_class("liggghts")
    raise AttributeError(f"module 'siloflow.engine' has no attribute {name!r}")


__all__ = ["Engine", "LaunchProfile", "RunRecord", "get_engine", "engine_class", "ENGINES"]
