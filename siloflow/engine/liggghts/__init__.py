"""LIGGGHTS 3.8 (Debian ``liggghts``): the engine (:mod:`.engine`), its deck writer (:mod:`.deck`,
templates in ``templates/liggghts``), the plan's encoding (:mod:`.encoding`), its tables
(:mod:`.tables`) and log reader (:mod:`.log`)."""
from .engine import LiggghtsEngine

__all__ = ["LiggghtsEngine"]
