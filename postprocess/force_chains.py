"""Force chains (paper A, Fig. 14): the contact network of one frame in a slice, each contact
the segment between the two grain centres, with its normal force; the report layer draws it
(``postprocess.report.figures.force_chain_plot``: line width proportional to the force)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from siloflow.errors import ReadError

from .coordination import normal_force, rows_of
from .dumps import Frame


def chain_segments(atoms: Frame, contacts: Frame, axis: int = 1, center: float | None = None,
                   thickness: float | None = None):
    """Segments (k, 2, 2) in the slice plane, normal forces (k,) N, and the slice (center, thickness).

    The slice is ``|coordinate[axis] - center| <= thickness / 2``; by default the mid-plane of
    the grains and one mean grain diameter. A contact is drawn when both centres lie in the slice.
    """
    data = contacts.data
    if "id1" not in data:
        raise ReadError(f"{contacts.source}: contacts need id1/id2 columns")
    pos = atoms.positions()
    ids = atoms.column("id")
    i, found_i = rows_of(ids, data["id1"].to_numpy())
    j, found_j = rows_of(ids, data["id2"].to_numpy())
    known = found_i & found_j
    if "periodic" in data:
        known &= data["periodic"].to_numpy() == 0
    if center is None:
        center = float(np.median(pos[:, axis]))
    if thickness is None:
        thickness = 2.0 * float(np.mean(atoms.radii()))
    fn = normal_force(data, atoms if "x1" not in data else None) if len(data) else np.empty(0)
    c = pos[:, axis]
    in_slice = np.abs(c - center) <= 0.5 * thickness
    keep = known.copy()
    keep[known] &= in_slice[i[known]] & in_slice[j[known]]
    plane = [k for k in range(3) if k != axis]
    seg = np.stack([pos[i[keep]][:, plane], pos[j[keep]][:, plane]], axis=1)
    return seg, fn[keep], (center, thickness)


@dataclass
class ForceChains:
    """The contact network of one frame's slice (:func:`force_chains`): ``segments`` (k, 2, 2), m,
    in the slice plane; ``forces`` (k,) normal forces, N; the slice (``axis``: 0, 1, 2 for x, y, z;
    ``center`` and ``thickness``, m) and the frame's ``step``. The report draws it
    (``postprocess.report.figures.force_chain_plot``)."""

    step: int
    axis: int
    segments: np.ndarray
    forces: np.ndarray
    center: float
    thickness: float


def force_chains(atoms: Frame, contacts: Frame, axis: int = 1, center: float | None = None,
                 thickness: float | None = None) -> ForceChains:
    """The contact network of a slice (:func:`chain_segments`) of ``atoms``' frame."""
    seg, fn, (center, thickness) = chain_segments(atoms, contacts, axis, center, thickness)
    return ForceChains(int(atoms.timestep), axis, seg, fn, center, thickness)
