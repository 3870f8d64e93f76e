"""The silo kinds siloflow knows, by the case's ``geometry.kind``: a new kind is its module in
``siloflow/silos/`` plus its line in :data:`SILO_KINDS` (``docs/new_silo.md``)."""
from __future__ import annotations

from . import box, cylinder, hopper, mesh, planar
from .base import SiloKind

#: every kind, by its ``geometry.kind``
SILO_KINDS: dict[str, SiloKind] = {k.name: k for k in (cylinder.KIND, hopper.KIND, planar.KIND, box.KIND, mesh.KIND)}


def silo_kind(name: str) -> SiloKind:
    """The kind called ``name`` (``KeyError`` naming the known ones if there is none: the case
    schema admits no other)."""
    try:
        return SILO_KINDS[name]
    except KeyError:
        raise KeyError(f"unknown silo kind {name!r}; known: {', '.join(SILO_KINDS)}") from None


def kind_of(geometry) -> SiloKind:
    """The kind of a case's ``geometry`` or of a plan's silo (anything with a ``kind``)."""
    return silo_kind(geometry.kind)
