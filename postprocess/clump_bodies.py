"""Clumps (LIGGGHTS multisphere bodies) as rigid bodies, for coarse-graining.

A clump is one particle: its mass sits at its centre of mass X and moves with X's velocity V;
contact forces act at contact points and reach the body's centre through the body, so a
contact's branch runs X_j -> c -> X_i (two straight pieces) instead of sphere centre to sphere
centre. For spheres the pieces are collinear and this is the usual branch vector.

* X is the centroid of the union of the clump's spheres (exact, by the divergence theorem:
  :func:`siloflow.clumps.union_centroid`), found once per shape and kept as affine weights w
  of the sphere centres (sum w = 1, X = sum w_i x_i). The union is symmetric about the affine
  hull of its centres, so its centroid lies in that hull and the weights exist; being affine
  they survive any rigid motion, and V = sum w_i v_i exactly for a rigid body.
* The body's mass comes from the dump's ``mass`` column, as the engine writes it
  (``clump_mass``): ``"body"``, every sphere carries the whole clump's mass (LIGGGHTS
  multisphere), or ``"sum"``, each sphere its share (rigid bodies of LAMMPS); without a mass
  column it is ``particle_density`` x the union volume.
* Rows with ``mol`` <= 0 or alone in their body (dust, plain spheres) stay as they are.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from siloflow.clumps import union_centroid, union_volume

from .porosity import clump_bodies

#: shape key (order-aware, scale-free) -> (affine weights of the sphere centres giving the
#: union's centroid, union volume / sum of the spheres' volumes); both survive rigid motion
#: and scaling
_WEIGHTS: dict[tuple, tuple] = {}


def centroid_weights(centers, radii) -> np.ndarray:
    """Affine weights w (sum 1) of the sphere centres whose combination is the union's
    centroid: the least-norm solution, i.e. the centroid projected onto the centres' hull."""
    centers, radii = np.asarray(centers, float), np.asarray(radii, float)
    x = union_centroid(centers, radii)
    A = np.vstack([np.ones(len(centers)), (centers - centers[0]).T])
    b = np.concatenate([[1.0], x - centers[0]])
    return np.linalg.lstsq(A, b, rcond=None)[0]


def _body_blocks(body: np.ndarray):
    """Clump rows as blocks of bodies with the same sphere count: a list of (m, n) row-index
    arrays, each row one body's spheres in dump order."""
    rows = np.flatnonzero(body >= 0)
    rows = rows[np.argsort(body[rows], kind="stable")]
    starts = np.flatnonzero(np.r_[True, np.diff(body[rows]) != 0])
    counts = np.diff(np.r_[starts, len(rows)])
    blocks = []
    for n in np.unique(counts):
        first = starts[counts == n]
        blocks.append(rows[first[:, None] + np.arange(n)[None, :]])
    return blocks


def _block_weights(pos, rad, rows) -> tuple[np.ndarray, np.ndarray]:
    """Centroid weights (m, n) and union volumes (m,) (m3) of a block of bodies, computed once
    per shape: the key is the radii and pair distances in row order (the weights follow the
    rows) over the largest radius, rounded to 1e-4 (dumps carry about six digits)."""
    P, R = pos[rows], rad[rows]
    n = rows.shape[1]
    iu = np.triu_indices(n, 1)
    D = np.sqrt(((P[:, :, None, :] - P[:, None, :, :]) ** 2).sum(-1))[:, iu[0], iu[1]]
    scale = 1e-4 * R.max(axis=1, keepdims=True)
    keys = np.concatenate([np.round(R / scale), np.round(D / scale)], axis=1).astype(np.int64)
    unique, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    spheres = 4.0 / 3.0 * np.pi * (R ** 3).sum(axis=1)
    table = np.empty((len(unique), n))
    share = np.empty(len(unique))
    for u, (key, b) in enumerate(zip(unique, first)):
        k = (tuple(key[:n]), tuple(key[n:]))
        if k not in _WEIGHTS:
            _WEIGHTS[k] = centroid_weights(P[b], R[b]), union_volume(P[b], R[b]) / spheres[b]
        table[u], share[u] = _WEIGHTS[k]
    return table[inverse.ravel()], share[inverse.ravel()] * spheres


def body_centres(frame):
    """(centre per row (n, 3), blocks) where a clump sphere's centre is its body's centroid and
    any other row's is its own position; ``blocks`` is a list of (rows (m, k), weights (m, k),
    union volumes (m,)) for the bodies of k spheres, or None when the frame has no clumps."""
    pos = frame.positions()
    found = clump_bodies(frame)
    if found is None:
        return pos, None
    rad = frame.radii()
    centre = pos.copy()
    blocks = []
    for rows in _body_blocks(found[0]):
        w, volume = _block_weights(pos, rad, rows)
        centre[rows] = np.einsum("mk,mkd->md", w, pos[rows])[:, None, :]
        blocks.append((rows, w, volume))
    return centre, blocks


#: how a dump's ``mass`` column carries a clump's mass (see the module docstring)
CLUMP_MASS = ("body", "sum")


def body_frame(frame, particle_density: float | None = None, centres=None, clump_mass: str = "body"):
    """The frame with each clump replaced by one row at its centroid: id and type of its first
    sphere, velocity sum w_i v_i, the body's mass, its union ``volume`` (m3; spheres: their own),
    and ``radius`` its largest sphere's (species by radius then tell clumps from dust). Frames
    without clumps come back unchanged. ``centres``: :func:`body_centres` of the frame, if
    already computed; ``clump_mass``: one of :data:`CLUMP_MASS`."""
    if clump_mass not in CLUMP_MASS:
        raise ValueError(f"clump_mass must be one of {CLUMP_MASS}, not {clump_mass!r}")
    centre, blocks = centres or body_centres(frame)
    if blocks is None:
        return frame
    d = frame.data
    vel, rad, pos = frame.velocities(), frame.radii(), frame.positions()
    loose = np.ones(frame.n, bool)
    tables = []
    for rows, w, volume in blocks:
        loose[rows.ravel()] = False
        first = rows[:, 0]
        if "mass" in d:
            column = frame.column("mass").astype(float)
            mass = column[first] if clump_mass == "body" else column[rows].sum(axis=1)
        elif particle_density:
            mass = particle_density * volume
        else:
            raise ValueError(f"{frame.source}: clumps need a mass column or a particle density")
        v = np.einsum("mk,mkd->md", w, vel[rows])
        tables.append(pd.DataFrame({
            "id": frame.column("id")[first], "type": frame.column("type")[first], "mol": frame.column("mol")[first],
            "x": centre[first, 0], "y": centre[first, 1], "z": centre[first, 2],
            "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2], "radius": rad[rows].max(axis=1), "mass": mass,
            "volume": volume}))
    keep = ["id", "type", "mol", "x", "y", "z", "vx", "vy", "vz", "radius"]
    rest = d.loc[loose, [c for c in keep if c in d]].copy()
    rest["radius"] = rad[loose]
    rest["volume"] = 4.0 / 3.0 * np.pi * rad[loose] ** 3
    if "mass" in d:
        rest["mass"] = d.loc[loose, "mass"].to_numpy(float)
    elif particle_density:
        rest["mass"] = particle_density * 4.0 / 3.0 * np.pi * rad[loose] ** 3
    data = pd.concat(tables + [rest], ignore_index=True)
    return replace(frame, data=data)


def body_contacts(frame, pos_i, pos_j, force, id_i, id_j=None, centres=None):
    """Contacts (:func:`postprocess.coarse_grain.liggghts_contacts` with ids) with their branches
    through the clumps' centroids X: each pair contact (id_j given) becomes two pieces, X_i - c
    and c - X_j (c the contact point between the spheres' surfaces); a wall contact (pos_j the
    wall point) runs from the wall point to X_i. Returns (pos_i, pos_j, force on i);
    ``centres`` as in :func:`body_frame`."""
    centre, _ = centres or body_centres(frame)
    ids = frame.column("id").astype(np.int64)
    order = np.argsort(ids)

    def rows_of(want):
        k = np.clip(np.searchsorted(ids[order], want), 0, len(ids) - 1)
        if np.any(ids[order][k] != want):
            raise ValueError(f"{frame.source}: a contact names an atom that step {frame.timestep} does not have")
        return order[k]

    i = rows_of(id_i)
    if id_j is None:
        return centre[i], pos_j, force
    j = rows_of(id_j)
    mol = frame.column("mol").astype(np.int64)
    keep = ~((mol[i] == mol[j]) & (mol[i] > 0))     # inside one rigid body (LIGGGHTS reports none)
    i, j, force, xi, xj = i[keep], j[keep], force[keep], pos_i[keep], pos_j[keep]
    rad = frame.radii()
    gap = np.linalg.norm(xj - xi, axis=1)
    n = (xj - xi) / np.maximum(gap, 1e-300)[:, None]
    overlap = rad[i] + rad[j] - gap
    c = xi + n * (rad[i] - 0.5 * overlap)[:, None]
    return (np.concatenate([centre[i], c]), np.concatenate([c, centre[j]]), np.concatenate([force, force]))
