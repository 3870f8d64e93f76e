"""Coordination number from pair contacts (dump local) or, when a dump has only positions and
radii, from geometric overlaps.

Conventions (written into every table row):

* ``z_mean`` = mean number of contacts per grain over the selected grains (each contact
  counts for both grains; contacts with walls are not counted);
* ``z_mech`` = mechanical coordination number, rattlers removed with the usual correction
  (Thornton 2000): (sum z_i - N1) / (N - N0 - N1), N0/N1 the grains with 0/1 contacts;
* clumps (a ``mol`` column): contacts are counted per clump, i.e. between distinct clumps,
  several sub-sphere contacts between the same two clumps count once
  (``convention = "per_body"``); otherwise per sphere.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from siloflow.errors import ReadError

from .analysis_base import FrameAnalysis


def overlap_pairs(positions: np.ndarray, radii: np.ndarray, tolerance: float = 0.0):
    """Index pairs (i, j), i < j, of spheres whose distance is < (r_i + r_j)(1 + tolerance)."""
    if len(positions) < 2:
        return np.empty(0, int), np.empty(0, int)
    tree = cKDTree(positions)
    pairs = tree.query_pairs(2.0 * radii.max() * (1.0 + tolerance), output_type="ndarray")
    if len(pairs) == 0:
        return np.empty(0, int), np.empty(0, int)
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(positions[i] - positions[j], axis=1)
    keep = d < (radii[i] + radii[j]) * (1.0 + tolerance)
    return i[keep], j[keep]


def local_pairs(frame, contacts, min_normal_force: float = 0.0):
    """Index pairs (into ``frame``'s rows) of the contacts of a dump local frame (``id1 id2``).

    Contacts that name an atom not in ``frame`` (deleted meanwhile) are dropped. With
    ``min_normal_force`` > 0, contacts whose normal force is below it are dropped.
    """
    for col in ("id1", "id2"):
        if col not in contacts.data:
            raise ReadError(f"{contacts.source}: contact frame has no {col} column; name the columns of "
                            "the dump local (postprocess.dumps.local_columns)")
    ids = frame.column("id")
    i, found_i = rows_of(ids, contacts.column("id1"))
    j, found_j = rows_of(ids, contacts.column("id2"))
    keep = found_i & found_j
    if min_normal_force > 0:
        keep &= normal_force(contacts.data, frame) >= min_normal_force
    return i[keep], j[keep]


def rows_of(ids: np.ndarray, wanted) -> tuple[np.ndarray, np.ndarray]:
    """Row of each of the atom ids ``wanted`` in a frame's id column ``ids``, and whether it is there."""
    wanted = np.asarray(wanted)
    if len(ids) == 0:
        return np.zeros(len(wanted), dtype=np.int64), np.zeros(len(wanted), bool)
    order = np.argsort(ids)
    sorted_ids = ids[order]
    k = np.searchsorted(sorted_ids, wanted).clip(0, len(ids) - 1)
    return order[k], sorted_ids[k] == wanted


def normal_force(data, frame=None) -> np.ndarray:
    """Normal force magnitude (N) per contact: from fn columns, or the total force projected on
    the branch vector (pos columns, or atom positions of ``frame``)."""
    if "fnx" in data:
        return np.linalg.norm(data[["fnx", "fny", "fnz"]].to_numpy(), axis=1)
    if "fx" in data:
        branch = branch_vectors(data, frame)
        unit = branch / np.maximum(np.linalg.norm(branch, axis=1, keepdims=True), 1e-300)
        return np.abs((data[["fx", "fy", "fz"]].to_numpy() * unit).sum(axis=1))
    raise ReadError("contacts have no force columns (need force or force_normal in the dump local)")


def branch_vectors(data, frame=None) -> np.ndarray:
    """Centre-to-centre vectors (m) of contacts, from pos columns or the atoms of ``frame``."""
    if "x1" in data:
        return data[["x2", "y2", "z2"]].to_numpy() - data[["x1", "y1", "z1"]].to_numpy()
    if frame is None:
        raise ReadError("contacts have no pos columns and no atom frame was given")
    ids = frame.column("id")
    pos = frame.positions()
    rows = []
    for col in ("id1", "id2"):
        wanted = data[col].to_numpy()
        r, found = rows_of(ids, wanted)
        if not found.all():
            raise ReadError(f"contact names atom {int(wanted[~found][0])} that is not in the atom frame")
        rows.append(r)
    return pos[rows[1]] - pos[rows[0]]


def coordination(n: int, i: np.ndarray, j: np.ndarray, body: np.ndarray | None = None,
                 select: np.ndarray | None = None) -> dict:
    """Coordination numbers of ``n`` grains with contacts (i, j) (row indices).

    ``body`` maps each row to a body (clump) id: contacts within a body are dropped and each
    pair of bodies counts once. ``select`` (boolean per row; a body is selected when any of its
    rows is) restricts the grains averaged over; contacts with unselected grains still count.
    """
    i = np.asarray(i, int)
    j = np.asarray(j, int)
    if body is not None:
        body = np.asarray(body)
        keys, inverse = np.unique(body, return_inverse=True)
        bi, bj = inverse[i], inverse[j]
        other = bi != bj
        pairs = np.unique(np.sort(np.column_stack([bi[other], bj[other]]), axis=1), axis=0)
        i, j = pairs[:, 0], pairs[:, 1]
        if select is not None:
            sel = np.zeros(len(keys), bool)
            np.logical_or.at(sel, inverse, np.asarray(select, bool))
            select = sel
        n = len(keys)
    z = np.bincount(i, minlength=n) + np.bincount(j, minlength=n)
    sel = np.ones(n, bool) if select is None else np.asarray(select, bool)
    zs = z[sel]
    N = int(sel.sum())
    n0 = int((zs == 0).sum())
    n1 = int((zs == 1).sum())
    mech_n = N - n0 - n1
    return {"grains": N, "contacts": int(len(i)), "z_mean": float(zs.mean()) if N else float("nan"),
            "z_mech": float((zs.sum() - n1) / mech_n) if mech_n > 0 else float("nan"),
            "rattlers_0": n0, "rattlers_1": n1, "per_grain": z}


class Coordination(FrameAnalysis):
    """Coordination number per frame (all grains, and per ``type``), and the contact count.

    ``select(frame) -> bool array`` picks the grains averaged over (for example the core of the
    bed, away from walls, where wall contacts are missing); default all. Contacts come from
    the dump local frames when given, else from overlaps (``tolerance`` relative to r_i + r_j).
    """

    name = "coordination"

    def __init__(self, select=None, tolerance: float = 0.0, min_normal_force: float = 0.0):
        super().__init__()
        self.select = select
        self.tolerance = tolerance
        self.min_normal_force = min_normal_force

    def _single_frame(self, frame, contacts):
        if contacts is not None:
            i, j = local_pairs(frame, contacts, self.min_normal_force)
            source = "dump_local"
        else:
            i, j = overlap_pairs(frame.positions(), frame.radii(), self.tolerance)
            source = "overlaps"
        sel = np.ones(frame.n, bool) if self.select is None else np.asarray(self.select(frame), bool)
        body = frame.column("mol") if "mol" in frame.data else None
        convention = "per_body" if body is not None else "per_sphere"
        result = coordination(frame.n, i, j, body, sel)
        rows = [{"species": "all", "source": source, "convention": convention,
                 **{k: v for k, v in result.items() if k != "per_grain"}}]
        if "type" in frame.data and body is None and frame.data["type"].nunique() > 1:
            z = result["per_grain"]
            types = frame.column("type")
            for t in np.unique(types[sel]):
                m = sel & (types == t)
                rows.append({"species": f"type {int(t)}", "source": source, "convention": convention,
                             "grains": int(m.sum()), "contacts": int(len(i)), "z_mean": float(z[m].mean()),
                             "z_mech": float("nan"), "rattlers_0": int((z[m] == 0).sum()),
                             "rattlers_1": int((z[m] == 1).sum())})
        return rows
