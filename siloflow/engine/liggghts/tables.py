"""The column layouts of LIGGGHTS' ``pair/gran/local`` and ``wall/gran/local`` contact dumps (its
sampled tables are read engine-neutrally by ``siloflow.engine.tables``)."""
from __future__ import annotations

from typing import Sequence

from ...errors import ReadError

#: column names a LIGGGHTS ``compute pair/gran/local`` writes, per keyword, in LIGGGHTS' fixed
#: output order (which does not depend on the order the keywords were given in)
PAIR_LOCAL_LAYOUT = {
    "pos": ["x1", "y1", "z1", "x2", "y2", "z2"],
    "vel": ["vx1", "vy1", "vz1", "vx2", "vy2", "vz2"],
    "id": ["id1", "id2", "periodic"],
    "force": ["fx", "fy", "fz"],
    "force_normal": ["fnx", "fny", "fnz"],
    "force_tangential": ["ftx", "fty", "ftz"],
    "torque": ["tx", "ty", "tz"],
    "history": ["h1", "h2", "h3"],
    "contactArea": ["area"],
    "delta": ["delta"],
}
#: ``compute wall/gran/local`` uses the same order, but ``id`` is (mesh id, triangle id, particle id)
#: and ``pos`` is (contact point on the wall, particle centre): seen in LIGGGHTS 3.8 output, where
#: the first point lies on the cylinder (r = R) and the second at r = R - radius
WALL_LOCAL_ID = ["mesh", "triangle", "id1"]
WALL_LOCAL_POS = ["xw", "yw", "zw", "x1", "y1", "z1"]
#: what siloflow decks ask of wall/gran/local (the force is the force on the particle)
WALL_CONTACT_KEYWORDS = ("pos", "id", "force")
#: what siloflow decks ask of pair/gran/local
CONTACT_KEYWORDS = ("pos", "id", "force", "force_normal")


def local_columns(keywords: Sequence[str], wall: bool = False) -> list[str]:
    """Column names of a LIGGGHTS pair/gran/local (or wall/gran/local) compute with these keywords."""
    unknown = [k for k in keywords if k not in PAIR_LOCAL_LAYOUT]
    if unknown:
        raise ReadError(f"unknown pair/gran/local keyword(s) {unknown}; known: {list(PAIR_LOCAL_LAYOUT)}")
    names: list[str] = []
    for key, cols in PAIR_LOCAL_LAYOUT.items():
        if key in keywords:
            if wall and key == "id":
                cols = WALL_LOCAL_ID
            elif wall and key == "pos":
                cols = WALL_LOCAL_POS
            names += cols
    return names
