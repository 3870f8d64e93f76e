"""Force-chain figure (paper A, Fig. 14): the contact network of one frame in a slice, each
contact drawn as the segment between the two grain centres, line width proportional to the
normal force."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.collections import LineCollection

from siloflow.errors import ReadError

from .coordination import normal_force, rows_of
from .dumps import Frame
from .figures import plt, save_figure


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


def force_chain_plot(atoms: Frame, contacts: Frame, axis: int = 1, center: float | None = None,
                     thickness: float | None = None, max_width: float = 3.0):
    """The contact network of a slice (:func:`chain_segments`), line width = max_width * Fn / max Fn;
    returns the Figure."""
    seg, fn, (center, thickness) = chain_segments(atoms, contacts, axis, center, thickness)
    fig, ax = plt.subplots(figsize=(5.5, 8))
    if len(fn):
        widths = max_width * fn / max(float(fn.max()), 1e-300)
        lines = LineCollection(seg * 1000, linewidths=widths, colors="k", capstyle="round")
        ax.add_collection(lines)
        ax.autoscale()
    names = "xyz"
    plane = [names[k] for k in range(3) if k != axis]
    ax.set_aspect("equal")
    ax.set(xlabel=f"{plane[0]} (mm)", ylabel=f"{plane[1]} (mm)",
           title=f"force chains, step {atoms.timestep}: {len(fn)} contacts in |{names[axis]} - "
                 f"{center * 1000:.1f} mm| <= {thickness * 500:.1f} mm\nline width ~ normal force "
                 f"(max {fn.max() if len(fn) else 0:.3g} N)")
    ax.title.set_fontsize(8)
    fig.tight_layout()
    return fig


def force_chain_figure(atoms: Frame, contacts: Frame, path, axis: int = 1, center: float | None = None,
                       thickness: float | None = None, max_width: float = 3.0) -> Path:
    """:func:`force_chain_plot` written to ``path`` (PNG); returns the path."""
    save_figure(force_chain_plot(atoms, contacts, axis, center, thickness, max_width), path)
    return Path(path)
