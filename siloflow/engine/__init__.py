"""Engines siloflow can drive, behind one interface (:class:`~siloflow.engine.base.Engine`)."""
from __future__ import annotations

from ..errors import SetupError
from .base import Engine, RunRecord
from .liggghts import LiggghtsEngine

ENGINES = {"liggghts": LiggghtsEngine}


def get_engine(name: str, **profile) -> Engine:
    """The engine called ``name``, configured for this machine by ``profile`` (binary, launcher)."""
    try:
        return ENGINES[name](**profile)
    except KeyError:
        raise SetupError(f"unknown engine {name!r}; known: {', '.join(ENGINES)}") from None


__all__ = ["Engine", "RunRecord", "LiggghtsEngine", "get_engine", "ENGINES"]
