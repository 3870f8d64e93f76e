"""LIGGGHTS 3.8 (Debian ``liggghts``): the engine (:mod:`.engine`), its deck writer (:mod:`.deck`,
templates in ``templates/liggghts``), the plan's encoding (:mod:`.encoding`), its tables
(:mod:`.tables`) and log reader (:mod:`.log`)."""
__all__ = ["LiggghtsEngine"]


def __getattr__(name):
    """``LiggghtsEngine`` loads on first use: its tables and deck modules import without it."""
    if name == "LiggghtsEngine":
        from .engine import LiggghtsEngine
        return LiggghtsEngine
    raise AttributeError(f"module 'siloflow.engine.liggghts' has no attribute {name!r}")
