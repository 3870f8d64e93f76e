"""The engine registry's look-up: an ``Engine`` subclass by its name in :data:`siloflow.engines.ENGINES`,
imported only when asked for (imports no engine, nor the engine base)."""
from __future__ import annotations

from importlib import import_module

from ..engines import ENGINES
from ..errors import SetupError


def engine_class(name: str) -> type:
    """The ``Engine`` subclass called ``name`` (``SetupError`` if there is none)."""
    try:
        module, cls = ENGINES[name].split(":")
    except KeyError:
        raise SetupError(f"unknown engine {name!r}; known: {', '.join(ENGINES)}") from None
    return getattr(import_module(module), cls)


def get_engine(name: str, **profile):
    """The engine called ``name``, configured for this machine by ``profile`` (executable, mpirun,
    env, or a ``LaunchProfile`` as ``profile=``)."""
    return engine_class(name)(**profile)
