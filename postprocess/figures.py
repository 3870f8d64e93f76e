"""Figures of a run (matplotlib, Agg backend): the ``*_plot`` functions draw and return a
``matplotlib.figure.Figure``; :func:`save_figure` writes one atomically (the report layer,
``postprocess.report``, writes a run's)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from siloflow.atomic_files import atomic_path  # noqa: E402


def save_figure(fig, path, dpi: int = 130) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) atomically (``siloflow.atomic_files.atomic_path``)
    and close it."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=path.suffix[1:].lower() or "png", dpi=dpi)
    finally:
        plt.close(fig)


def first_results_plot(bands, discharge, band_table, t_open: float):
    """Pressure per band vs time (left), static/max-dynamic profile (middle), discharged mass (right);
    a run without wall-pressure sensors (``bands`` None) gets the discharge only. Returns the Figure."""
    if bands is None:
        fig, ax3 = plt.subplots(figsize=(6, 4.5))
        _discharge_panel(ax3, discharge, t_open)
        fig.tight_layout()
        return fig
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(15, 4.5))
    cmap = plt.get_cmap("viridis")
    nb = max(1, bands.band.nunique())
    for b, grp in bands.groupby("band"):
        ax1.plot(grp.time, grp.pressure, lw=0.9, color=cmap(b / max(1, nb - 1)),
                 label=f"band {b} (z = {grp.z_mid.iloc[0] * 100:.1f} cm)")
    ax1.axvline(t_open, color="k", ls="--", lw=0.8)
    ax1.set(xlabel="time (s)", ylabel="normal wall pressure (Pa)", title="wall pressure per band")
    ax1.legend(fontsize=7)
    ax2.plot(band_table.static_pressure, band_table.z_mid * 100, "o-", label="static (settled)")
    ax2.plot(band_table.max_dynamic_pressure, band_table.z_mid * 100, "s--", label="max during discharge")
    ax2.set(xlabel="normal wall pressure (Pa)", ylabel="height of band centre (cm)", title="pressure profile")
    ax2.legend(fontsize=8)
    _discharge_panel(ax3, discharge, t_open)
    fig.tight_layout()
    return fig


def _discharge_panel(ax, discharge, t_open: float) -> None:
    """Mass through the outlet and in the silo (g) against time (s)."""
    ax.plot(discharge.time, discharge.outlet_mass * 1000, label="through the outlet")
    ax.plot(discharge.time, discharge.mass_in_silo * 1000, label="in the silo")
    ax.axvline(t_open, color="k", ls="--", lw=0.8)
    ax.set(xlabel="time (s)", ylabel="mass (g)", title="discharge")
    ax.legend(fontsize=8)


def line_plot(table, x: str, y, hue: str | None = None, xlabel: str = "", ylabel: str = "",
              title: str = "", logy: bool = False):
    """One line per ``hue`` group (or per column when ``y`` is a list); returns the Figure."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if hue is not None:
        for key, grp in table.groupby(hue):
            ax.plot(grp[x], grp[y], marker=".", lw=1, label=str(key))
    else:
        for col in ([y] if isinstance(y, str) else y):
            ax.plot(table[x], table[col], marker=".", lw=1, label=col)
    if logy:
        ax.set_yscale("log")
    ax.set(xlabel=xlabel or x, ylabel=ylabel or str(y), title=title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def line_figure(table, x: str, y, path, hue: str | None = None, xlabel: str = "", ylabel: str = "",
                title: str = "", logy: bool = False):
    """:func:`line_plot` written to ``path``; returns the path."""
    save_figure(line_plot(table, x, y, hue, xlabel, ylabel, title, logy), path)
    return Path(path)
