"""Adapters from engine dump frames to coarse-graining inputs.

* :func:`liggghts_contacts`: (pos_i, pos_j, force on i) arrays (m, m, N) from a LIGGGHTS
  pair/gran/local or wall/gran/local dump local frame;
* :func:`joined_contacts`: those of several contact frames (pairs and walls) in one set, with
  clump branches through the clumps' centroids;
* :func:`species_of`: each particle's species index (by ``type`` or radius, m) and the labels.
"""
from __future__ import annotations

import numpy as np

from .clump_bodies import body_contacts


def species_of(frame, by: str | None, classes=None):
    """Species index per particle and the class labels: by ``type``, by ``radius`` (distinct
    radii, rounded to 1e-9 m; or the given ``classes``), or None (no partial fields)."""
    if by is None:
        return None, []
    if by == "type":
        values = frame.column("type")
    elif by == "radius":
        values = np.round(frame.radii(), 9)
    else:
        raise ValueError("species must be 'type', 'radius' or None")
    labels = np.unique(values) if classes is None else np.asarray(classes)
    idx = np.searchsorted(labels, values)
    idx = np.clip(idx, 0, len(labels) - 1)
    if np.any(labels[idx] != values):
        raise ValueError(f"{frame.source}: a particle's {by} is not among the species classes {list(labels)}")
    return idx, list(labels)


def liggghts_contacts(contacts_frame, with_ids: bool = False):
    """(pos_i, pos_j, force on i) from a LIGGGHTS pair/gran/local frame (pos and force columns)
    or wall/gran/local frame (pos: wall point then particle; branch from the wall point).
    ``with_ids``: also (id_i, id_j), id_j None for a wall frame (needs the id columns).

    LIGGGHTS reports the force on the first particle of a pair (checked on a settled bed: the
    normal force points from particle 2 to particle 1 in 99 % of contacts, the rest being
    damping-dominated separating contacts) and, for walls, the force on the particle."""
    d = contacts_frame.data
    if "fx" not in d or not ("x1" in d):
        raise ValueError(f"{contacts_frame.source}: contact stress needs pos and force columns "
                         "(compute pair/gran/local pos id force)")
    wall = "xw" in d   # wall contact: the branch runs from the contact point on the wall to the centre
    keep = (d["periodic"].to_numpy() == 0) if "periodic" in d and not wall else np.ones(len(d), bool)
    rows = d.loc[keep]
    out = (rows[["x1", "y1", "z1"]].to_numpy(float), rows[["xw", "yw", "zw"] if wall else ["x2", "y2", "z2"]]
           .to_numpy(float), rows[["fx", "fy", "fz"]].to_numpy(float))
    if not with_ids:
        return out
    names = ["id1"] if wall else ["id1", "id2"]
    if any(n not in d for n in names):
        raise ValueError(f"{contacts_frame.source}: clump contact stress needs the {' and '.join(names)} column(s)")
    return out + (rows["id1"].to_numpy(np.int64), None if wall else rows["id2"].to_numpy(np.int64))


def joined_contacts(*frames, atoms=None, centres=None):
    """Concatenate the (pos_i, pos_j, force) of several contact frames (pairs, walls); None if
    none. With ``atoms`` and its clumps' ``centres`` (:func:`clump_bodies.body_centres`), the
    branches run through the clumps' centroids."""
    if centres is not None and centres[1] is not None:
        parts = [body_contacts(atoms, *liggghts_contacts(f, with_ids=True), centres=centres)
                 for f in frames if f is not None]
    else:
        parts = [liggghts_contacts(f) for f in frames if f is not None]
    if not parts:
        return None
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

