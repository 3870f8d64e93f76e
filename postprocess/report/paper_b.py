"""Paper B's claims report (``make paper-b``): the figures drawn from
:class:`postprocess.paper_b.PaperBAnalysis`, the report's text, and the files
(``claims_report.write_claims_report``): report.md, report.html, the PNG figures beside them and
the result tables (``results/``) the report is made from, so that it can be made again without
the runs (``python -m siloflow.paper_b --from-results``)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from siloflow.atomic_files import write_text

from ..paper_b import BATCHES, RUNS, STUDY, TOL, PaperBAnalysis
from .claims_report import claims_blocks, write_claims_report
from .figures import plt
from .text import Items, Text

TITLE = "Paper B (Rubio-Largo et al. 2016, polydisperse silo flow): claims against siloflow"
FIGURES = ("flow_rates.png", "outlet_profiles.png", "scaling.png", "contact_pressure.png", "kinetic_pressure.png",
           "species_kinetic.png")


def _colors(keys):
    cmap = plt.get_cmap("viridis")
    return {k: cmap(i / max(1, len(keys) - 1) * 0.85) for i, k in enumerate(keys)}


def flow_rates_plot(a: PaperBAnalysis):
    """Fig. 2's layout: Wf (symbols) and Wr (lines) against (t - t_open)/t_d; the same rescaled."""
    keys, t_d = a.numbers["apertures_rb"], a.numbers["t_d"]
    R, col = a.numbers["R_by_key"], _colors(a.numbers["apertures_rb"])
    rho_p = a.numbers.get("rho_p", float("nan"))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    flow = a.curves["flow"]
    top = 0.0
    for k in keys:
        f = flow[(flow.R_over_rb == k) & (flow.time >= a.curves["t_open"][k] - 2 * t_d)]
        t = (f.time - a.curves["t_open"][k]) / t_d
        top = max(top, float(np.nanmax(f.Wf_kg_s)) if len(f) else 0.0)
        ax1.plot(t, f.Wf_kg_s, "o", ms=2.5, color=col[k], label=f"Wf, R = {k:g} r_b")
        wr = f.Wr_kg_s.notna()          # Wr exists at the dump frames only, Wf at every sample
        ax1.plot(t[wr], f.Wr_kg_s[wr], "-", lw=1, color=col[k], label=f"Wr, R = {k:g} r_b")
        scale = rho_p * a.curves["phi_c"][k].value * a.curves["v_c"][k].value * math.pi * R[k] ** 2
        ax2.plot(t, f.Wf_kg_s / scale, "o", ms=2.5, color=col[k], label=f"R = {k:g} r_b")
        t0, t1 = a.curves["window"][k]
        ax1.axvspan((t0 - a.curves["t_open"][k]) / t_d, (t1 - a.curves["t_open"][k]) / t_d, color=col[k], alpha=0.05)
    ax1.set(xlabel="(t - t_open) / t_d", ylabel="flow rate (kg/s)", title="Wf (symbols), Wr (lines); shaded: steady window")
    ax2.set(xlabel="(t - t_open) / t_d", ylabel="Wf / (rho_p phi_c v_c pi R^2)", title="rescaled flow rate")
    ax1.set_ylim(0, 1.3 * top if top > 0 else None)
    ax1.legend(fontsize=7, ncol=2)
    ax2.legend(fontsize=7)
    ax2.set_ylim(0, None)
    fig.tight_layout()
    return fig


def outlet_profiles_plot(a: PaperBAnalysis):
    """Figs. 4b and 5b: phi(r)/phi(0) and v_z(r)/v_z(0) against r/R, all apertures, with sqrt(1 - (r/R)^2)."""
    keys, col = a.numbers["apertures_rb"], _colors(a.numbers["apertures_rb"])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for k in keys:
        c = a.curves["outlet"][k]
        ax1.errorbar(c.r_over_R, c.phi_n, yerr=c.phi_n_se, fmt="o-", ms=3, lw=0.8, color=col[k], label=f"R = {k:g} r_b")
        ax2.errorbar(c.r_over_R, c.v_n, yerr=c.v_n_se, fmt="o-", ms=3, lw=0.8, color=col[k], label=f"R = {k:g} r_b")
    x = np.linspace(0, 1, 200)
    ax2.plot(x, np.sqrt(1 - x ** 2), "k--", lw=1, label="sqrt(1 - (r/R)^2)")
    ax1.set(xlabel="r / R", ylabel="phi(r) / phi(0)", title="solid fraction at the outlet", xlim=(0, 1))
    ax2.set(xlabel="r / R", ylabel="v_z(r) / v_z(0)", title="vertical velocity at the outlet", xlim=(0, 1))
    for ax in (ax1, ax2):
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def scaling_plot(a: PaperBAnalysis):
    """v_z(0) against sqrt(R) and h_c against R, with their batch-means errors (95 %)."""
    keys, R = a.numbers["apertures_rb"], a.numbers["R_by_key"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    sq = np.array([math.sqrt(R[k]) for k in keys])
    v = [a.curves["vz0"][k] for k in keys]
    ax1.errorbar(sq, [e.value for e in v], yerr=[e.value - e.interval()[0] for e in v], fmt="o", capsize=3)
    slope = float(np.sum(sq * [e.value for e in v]) / np.sum(sq * sq))
    xs = np.linspace(0, sq.max() * 1.1, 50)
    ax1.plot(xs, slope * xs, "k--", lw=1, label="v_z(0) proportional to sqrt(R)")
    b = a.numbers["vz_exponent"]
    ax1.set(xlabel="sqrt(R) (m^1/2)", ylabel="v_z(0) (m/s)", title=f"outlet centre velocity; exponent {b.value:.2f} +/- {b.stderr:.2f}")
    ax1.legend(fontsize=8)
    h = [a.curves["hc"][k] for k in keys]
    Rs = np.array([R[k] for k in keys])
    ax2.errorbar(Rs * 100, [e.value * 100 for e in h], yerr=[(e.value - e.interval()[0]) * 100 for e in h],
                 fmt="s", capsize=3, color="C1")
    ratio = float(np.sum(Rs * [e.value for e in h]) / np.sum(Rs * Rs))
    xr = np.linspace(0, Rs.max() * 1.1, 50)
    ax2.plot(xr * 100, ratio * xr * 100, "k--", lw=1, label=f"h_c = {ratio:.2f} R")
    ax2.set(xlabel="R (cm)", ylabel="h_c (cm)", title="height of the kinetic-pressure peak (error bars: 95 %)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _map(ax, m, field, title, log=False, R=None):
    piv = m.pivot(index="height", columns="r", values=field)
    r, z = piv.columns.to_numpy(), piv.index.to_numpy()
    vals = piv.to_numpy()
    rr = np.concatenate([-r[::-1], r])
    vv = np.concatenate([vals[:, ::-1], vals], axis=1)
    if log:
        from matplotlib.colors import LogNorm
        pos = vv[vv > 0]
        norm = LogNorm(vmin=max(pos.max() * 1e-3, pos.min()), vmax=pos.max()) if pos.size else None
        im = ax.pcolormesh(rr * 100, z * 100, np.where(vv > 0, vv, np.nan), norm=norm, shading="nearest")
    else:
        im = ax.pcolormesh(rr * 100, z * 100, vv, shading="nearest")
    if R is not None:
        ax.plot([-R * 100, R * 100], [0, 0], "r-", lw=2)
    ax.set(xlabel="r (cm)", ylabel="z (cm)", title=title, aspect="equal")
    plt.colorbar(im, ax=ax, shrink=0.8, label="Pa")


def contact_pressure_plot(a: PaperBAnalysis):
    """Fig. 6: the contact pressure map (middle aperture) and the axial profiles of every aperture."""
    keys, R, col = a.numbers["apertures_rb"], a.numbers["R_by_key"], _colors(a.numbers["apertures_rb"])
    mid = keys[len(keys) // 2]
    maps = a.curves["maps"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5.5), gridspec_kw={"width_ratios": [1.2, 1]})
    _map(ax1, maps[maps.R_over_rb == mid], "contact_pressure", f"contact pressure, R = {mid:g} r_b (red: outlet)",
         R=R[mid])
    for k in keys:
        c = a.curves["axial"][k]
        ax2.fill_between(c.height / R[k], c.contact_pressure - 2 * c.contact_pressure_se,
                         c.contact_pressure + 2 * c.contact_pressure_se, color=col[k], alpha=0.25)
        ax2.plot(c.height / R[k], c.contact_pressure, color=col[k], label=f"R = {k:g} r_b")
    ax2.set(xlabel="z / R", ylabel="contact pressure on the axis (Pa)", title="axial contact pressure (band: +/- 2 SE)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return fig


def kinetic_pressure_plot(a: PaperBAnalysis):
    """Figs. 7-8: the kinetic pressure maps (log colour) and the axial profiles against z/R (linear, semi-log)."""
    keys, R, col = a.numbers["apertures_rb"], a.numbers["R_by_key"], _colors(a.numbers["apertures_rb"])
    maps = a.curves["maps"]
    n = len(keys)
    fig = plt.figure(figsize=(4 * n + 1, 9))
    gs = fig.add_gridspec(2, max(n, 2))
    for i, k in enumerate(keys):
        ax = fig.add_subplot(gs[0, i])
        m = maps[(maps.R_over_rb == k) & (maps.height <= 6 * R[k])]
        _map(ax, m, "kinetic_pressure", f"kinetic pressure, R = {k:g} r_b", log=True, R=R[k])
    ax_lin = fig.add_subplot(gs[1, 0])
    ax_log = fig.add_subplot(gs[1, 1])
    for k in keys:
        c = a.curves["axial"][k]
        x = c.height / R[k]
        for ax in (ax_lin, ax_log):
            ax.fill_between(x, c.kinetic_pressure - 2 * c.kinetic_pressure_se,
                            c.kinetic_pressure + 2 * c.kinetic_pressure_se, color=col[k], alpha=0.25)
            ax.plot(x, c.kinetic_pressure, color=col[k], label=f"R = {k:g} r_b")
        h = a.curves["hc"][k]
        ax_lin.axvline(h.value / R[k], color=col[k], ls=":", lw=1)
    ax_lin.set(xlabel="z / R", ylabel="kinetic pressure on the axis (Pa)", title="axial kinetic pressure (dotted: h_c)",
               xlim=(0, 8))
    ax_log.set(xlabel="z / R", ylabel="kinetic pressure (Pa)", yscale="log", title="semi-log", xlim=(0, 8))
    ax_lin.legend(fontsize=8)
    fig.tight_layout()
    return fig


def species_kinetic_plot(a: PaperBAnalysis):
    """Figs. 11-12: partial kinetic pressure per size on the axis against z/(2 r_b) (middle aperture),
    the same over each size's solid fraction, and both at h_c for every aperture."""
    keys, rb = a.numbers["apertures_rb"], a.numbers["rb"]
    mid = keys[len(keys) // 2]
    s = a.curves["species_axial"][mid]
    radii = np.sort(s.radius.unique())
    cmap = plt.get_cmap("plasma")
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    for i, r in enumerate(radii):
        g = s[s.radius == r].sort_values("height")
        c = cmap(i / max(1, len(radii) - 1) * 0.9)
        axes[0].plot(g.height / (2 * rb), g.kinetic_pressure, color=c, label=f"r = {r / rb:.3g} r_b")
        with np.errstate(divide="ignore", invalid="ignore"):
            axes[1].plot(g.height / (2 * rb), g.kinetic_pressure / g.solid_fraction, color=c)
    axes[0].set(xlabel="z / (2 r_b)", ylabel="partial kinetic pressure (Pa)", title=f"R = {mid:g} r_b, on the axis",
                yscale="log")
    axes[1].set(xlabel="z / (2 r_b)", ylabel="partial kinetic pressure / phi_j (Pa)", title="normalised by phi_j",
                yscale="log")
    axes[0].legend(fontsize=7)
    col = _colors(keys)
    for k in keys:
        c = a.curves["species_at_hc"][k]
        axes[2].errorbar(c.radius / rb, c.p_k / c.p_k.max(), yerr=c.p_k_se / c.p_k.max(), fmt="o-", ms=3,
                         color=col[k], label=f"p_k,j, R = {k:g} r_b")
        axes[2].errorbar(c.radius / rb, c.p_k_over_phi / c.p_k_over_phi.max(), yerr=c.p_k_over_phi_se / c.p_k_over_phi.max(),
                         fmt="s--", ms=3, color=col[k], label=f"p_k,j / phi_j, R = {k:g} r_b")
    axes[2].set(xlabel="grain radius / r_b", ylabel="at h_c, relative to the largest", title="per size at h_c")
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    return fig


def paper_b_figures(a: PaperBAnalysis) -> dict:
    """{file name: Figure} of the report."""
    draw = (flow_rates_plot, outlet_profiles_plot, scaling_plot, contact_pressure_plot, kinetic_pressure_plot,
            species_kinetic_plot)
    return dict(zip(FIGURES, (f(a) for f in draw)))


def paper_b_blocks(a: PaperBAnalysis, study: dict) -> list:
    """The report's blocks: what was run, the claims table, how each number was measured."""
    keys, rb, t_d = a.numbers["apertures_rb"], a.numbers["rb"], a.numbers["t_d"]
    runs = study.get("runs", [])
    run_lines = [f"  - R = {r['R_over_rb']:g} r_b ({r['R'] * 100:.3g} cm): {r.get('particles')} grains, "
                 f"engine {r['engine_wall_s'] / 60:.1f} min" + (" (settled bed from the fill cache)" if r.get("fill_from_cache") else
                                                                 " (this run made the shared fill)")
                 for r in runs if isinstance(r.get("engine_wall_s"), (int, float)) and math.isfinite(r["engine_wall_s"])]
    intro = [
        Text(f"Scale: {study['scale']} ({study['deck']}, regenerated by `make paper-b SCALE={study['scale']}`; "
             f"from the committed results alone by `make paper-b-report`). {study['why']}"),
        Items([f"- apertures R = {', '.join(f'{k:g}' for k in keys)} r_b (r_b = {rb * 1000:.4g} mm, the largest radius), "
               "one settled bed (grains shrunk after settling, then the outlet opened) shared by the three discharges "
               "through the fill cache (`siloflow sweep --set geometry.orifice_radius=...`)",
               *run_lines,
               f"- coarse-graining: paper B's Gaussian kernel, w = {a.numbers['width_flow'] / rb:g} r_b for phi and v_z, "
               f"w = {a.numbers['width_stress'] / rb:g} r_b for the pressures, azimuthal average on an (r, z) grid",
               f"- errors: each run's steady window cut into {a.numbers['batches']} contiguous batches; every number "
               "is measured per batch (its own frames, its own flow samples) and its error is the batch means' "
               "(Student's t, batches - 1 dof): one fill gives no seed spread, and frames are autocorrelated",
               f"- t_d = sqrt(2 r_b / g) = {t_d * 1000:.3g} ms"],
              lead="What was run:"),
    ]
    after = [Text("Tolerances that make the paper's words testable (each row's note says which applies): "
                  + "; ".join(f"{k} {v:g}" for k, v in TOL.items()) + ".")]
    if study.get("cg_scaling"):
        cs = study["cg_scaling"]
        after.append(Text("`siloflow cg-scaling` on the whole-window coarse-graining (w = 2 mean radii, unweighted "
                          f"fit, 3 points): v_z(0) exponent {cs['v_z0']['exponent']:.3f}"
                          + (f", h_c exponent {cs['h_c']['exponent']:.3f}" if "h_c" in cs else "")
                          + "; the rows above use the batch-weighted fit."))
    return claims_blocks(TITLE, intro, a.rows, after, figures=list(FIGURES))


def write_paper_b_report(folder, a: PaperBAnalysis, study: dict, tables: dict | None = None) -> list[Path]:
    """Write the report into ``folder``: report.md, report.html, the figures and, when given, the
    result ``tables`` and the study's record (results/study.json) it is made from."""
    folder = Path(folder)
    if tables is not None:
        (folder / "results").mkdir(parents=True, exist_ok=True)
        write_text(folder / "results" / STUDY, json.dumps(study, indent=1, sort_keys=True) + "\n")
    html_tables = {n: t for n, t in (tables or {}).items() if n in (RUNS, BATCHES)}
    return write_claims_report(folder, TITLE, paper_b_blocks(a, study), paper_b_figures(a), tables,
                               html_tables=html_tables)
