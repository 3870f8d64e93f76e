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
* The body's mass is the dump's ``mass`` of its spheres (LIGGGHTS gives every sphere of a clump
  the whole clump's mass), else ``particle_density`` x the union volume.
* Rows with ``mol`` <= 0 or alone in their body (dust, plain spheres) stay as they are.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from siloflow.clumps import union_centroid, union_volume

from .porosity import rows_by_body, clump_bodies, clump_key

#: shape key (order-aware) -> affine weights of the sphere centres giving the union's centroid
_WEIGHTS: dict[tuple, np.ndarray] = {}


def centroid_weights(centers, radii) -> np.ndarray:
    """Affine weights w (sum 1) of the sphere centres whose combination is the union's
    centroid: the least-norm solution, i.e. the centroid projected onto the centres' hull."""
    centers, radii = np.asarray(centers, float), np.asarray(radii, float)
    x = union_centroid(centers, radii)
    A = np.vstack([np.ones(len(centers)), (centers - centers[0]).T])
    b = np.concatenate([[1.0], x - centers[0]])
    return np.linalg.lstsq(A, b, rcond=None)[0]


def body_centres(frame):
    """(centre per row (n, 3), bodies) where a clump sphere's centre is its body's centroid and
    any other row's is its own position; ``bodies`` is (rows per body, weights per body) or
    None when the frame has no clumps."""
    pos = frame.positions()
    found = clump_bodies(frame)
    if found is None:
        return pos, None
    rad = frame.radii()
    body, _ = found
    groups = rows_by_body(body, np.arange(frame.n))
    weights = []
    centre = pos.copy()
    for rows in groups:
        key = clump_key(pos[rows], rad[rows], ordered=True)
        if key not in _WEIGHTS:
            _WEIGHTS[key] = centroid_weights(pos[rows], rad[rows])
        w = _WEIGHTS[key]
        centre[rows] = w @ pos[rows]
        weights.append(w)
    return centre, (groups, weights)


def body_frame(frame, particle_density: float | None = None, centres=None):
    """The frame with each clump replaced by one row at its centroid: id and type of its first
    sphere, velocity sum w_i v_i, the body's mass, and ``radius`` its largest sphere's (species
    by radius then tell clumps from dust). Frames without clumps come back unchanged.
    ``centres``: :func:`body_centres` of the frame, if already computed."""
    centre, bodies = centres or body_centres(frame)
    if bodies is None:
        return frame
    groups, weights = bodies
    d = frame.data
    vel, rad = frame.velocities(), frame.radii()
    loose = np.ones(frame.n, bool)
    first = np.array([rows[0] for rows in groups])
    for rows in groups:
        loose[rows] = False
    if "mass" in d:
        mass = frame.column("mass").astype(float)[first]
    elif particle_density:
        mass = np.array([particle_density * union_volume(frame.positions()[rows], rad[rows]) for rows in groups])
    else:
        raise ValueError(f"{frame.source}: clumps need a mass column or a particle density")
    bodies_table = pd.DataFrame({
        "id": frame.column("id")[first], "type": frame.column("type")[first],
        "mol": frame.column("mol")[first],
        "x": centre[first, 0], "y": centre[first, 1], "z": centre[first, 2],
        "vx": [w @ vel[rows, 0] for rows, w in zip(groups, weights)],
        "vy": [w @ vel[rows, 1] for rows, w in zip(groups, weights)],
        "vz": [w @ vel[rows, 2] for rows, w in zip(groups, weights)],
        "radius": [rad[rows].max() for rows in groups], "mass": mass})
    keep = ["id", "type", "mol", "x", "y", "z", "vx", "vy", "vz", "radius"]
    rest = d.loc[loose, [c for c in keep if c in d]].copy()
    rest["radius"] = rad[loose]
    if "mass" in d:
        rest["mass"] = d.loc[loose, "mass"].to_numpy(float)
    elif particle_density:
        rest["mass"] = particle_density * 4.0 / 3.0 * np.pi * rad[loose] ** 3
    data = pd.concat([bodies_table, rest], ignore_index=True)
    return replace(frame, data=data)


def body_contacts(frame, contacts_frame, centres=None):
    """(pos_i, pos_j, force on i) of a LIGGGHTS contact frame with clumps: each pair contact
    becomes two pieces, X_i - c and c - X_j (c the contact point between the spheres' surfaces,
    X the bodies' centroids); a wall contact runs from the wall point to X_i. Needs ``id1``
    (and ``id2``) columns to find the bodies; ``centres`` as in :func:`body_frame`."""
    d = contacts_frame.data
    centre, _ = centres or body_centres(frame)
    ids = frame.column("id").astype(np.int64)
    order = np.argsort(ids)

    def rows_of(col):
        if col not in d:
            raise ValueError(f"{contacts_frame.source}: clump contact stress needs the {col} column")
        want = d[col].to_numpy(np.int64)
        k = np.clip(np.searchsorted(ids[order], want), 0, len(ids) - 1)
        if np.any(ids[order][k] != want):
            raise ValueError(f"{contacts_frame.source}: a contact names an atom that step {frame.timestep} "
                             "does not have")
        return order[k]

    force = d[["fx", "fy", "fz"]].to_numpy(float)
    i = rows_of("id1")
    if "xw" in d:            # wall: the branch runs from the contact point on the wall to the centre
        return centre[i], d[["xw", "yw", "zw"]].to_numpy(float), force
    keep = (d["periodic"].to_numpy() == 0) if "periodic" in d else np.ones(len(d), bool)
    j = rows_of("id2")
    mol = frame.column("mol").astype(np.int64)
    keep &= ~((mol[i] == mol[j]) & (mol[i] > 0))     # inside one rigid body (LIGGGHTS reports none)
    i, j, force = i[keep], j[keep], force[keep]
    xi, xj = d.loc[keep, ["x1", "y1", "z1"]].to_numpy(float), d.loc[keep, ["x2", "y2", "z2"]].to_numpy(float)
    rad = frame.radii()
    gap = np.linalg.norm(xj - xi, axis=1)
    n = (xj - xi) / np.maximum(gap, 1e-300)[:, None]
    overlap = rad[i] + rad[j] - gap
    c = xi + n * (rad[i] - 0.5 * overlap)[:, None]
    return (np.concatenate([centre[i], c]), np.concatenate([c, centre[j]]), np.concatenate([force, force]))
