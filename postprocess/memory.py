"""The memory a post-processing step may plan to use: :data:`MEMORY_SHARE` of what the machine
has available when the step starts (``MemAvailable`` of /proc/meminfo, lowered to the room left
under a cgroup v2 limit ``memory.max`` when a container sets one; elsewhere ``os.sysconf``'s
available physical pages). A grid whose estimated arrays exceed it is refused before anything
is allocated (``SetupError`` naming the options that size it), rather than swapping the machine
or being killed by the kernel part way."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

from siloflow.errors import SetupError

#: the share of the available memory a coarse-graining (or a VTK grid) may plan to hold at once
MEMORY_SHARE = 0.5


def _meminfo_available() -> Optional[int]:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_room() -> Optional[int]:
    """Bytes left under this process' cgroup v2 memory limit (None without one)."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit == "max":
            return None
        used = int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
        return max(0, int(limit) - used)
    except (OSError, ValueError):
        return None


def available_memory() -> Optional[int]:
    """Bytes of memory available now (the module doc), or None where it cannot be told."""
    avail = _meminfo_available()
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = None
    room = _cgroup_room()
    if room is not None:
        avail = room if avail is None else min(avail, room)
    return avail


def memory_budget() -> Optional[int]:
    """Bytes a step may plan to use: :data:`MEMORY_SHARE` of :func:`available_memory` (None: unknown)."""
    avail = available_memory()
    return None if avail is None else int(MEMORY_SHARE * avail)


def size_text(nbytes: float) -> str:
    """``nbytes`` for people: 512 MB, 3.2 GB, 8e+09 GB."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{int(nbytes)} bytes"


def check_memory(need: int, what: str, fix: str, budget: Optional[int] = None) -> None:
    """Refuse (``SetupError``) ``what`` when its estimated ``need`` (bytes) exceeds the budget
    (:func:`memory_budget` unless given); ``fix`` says which options make it smaller."""
    budget = memory_budget() if budget is None else budget
    if budget is None or need <= budget:
        return
    raise SetupError(f"{what} would need about {size_text(need)} of memory at once, more than "
                     f"{MEMORY_SHARE:.0%} of the {size_text(budget / MEMORY_SHARE)} this machine has available "
                     f"(the limit, {size_text(budget)}): {fix}")
