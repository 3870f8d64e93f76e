"""Answers computed from a case or from finished runs, without running an engine: EN 1991-4 design
loads of a case's silo (:func:`design`) and Beverloo's law fitted across runs (:func:`beverloo`).

``siloflow design`` and ``siloflow beverloo`` print and write what these return; a notebook calls
them directly. Both raise siloflow's named errors (``CaseError``, ``ReadError``, ``SetupError``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from .case import Case, DesignSettings
from .case_file import load_case
from .errors import CaseError, ReadError, SetupError
from .run_folder import RESULT_TABLES, RunFolder, case_differences

#: the Annex E solid a case without a design section is designed for
DEFAULT_DESIGN = DesignSettings(material="wheat")


@dataclass
class DesignResult:
    """The design loads of one case (``siloflow.design_loads.DesignLoads``); with a run of the case,
    its band table (``bands.csv``: static and dynamic band pressures, Pa) to set beside them."""

    case: Case
    loads: object
    bands: Optional[object] = None      # pandas.DataFrame of the run's bands, or None
    bulk_unit_weight: float = float("nan")    # the DEM grains' bulk unit weight, rho_p phi g (N/m3)

    @property
    def defaulted(self) -> bool:
        """True when the case has no design section and was designed as wheat, D2, AAC 2."""
        return self.case.design is None


def run_case(run: RunFolder) -> Case:
    """The validated case a run folder was rendered from (its ``case.yaml``); ``ReadError``."""
    if not run.case_file.is_file():
        raise ReadError(f"{run.path} is not a siloflow run folder (no {run.case_file.name})")
    try:
        return load_case(run.case_file)
    except CaseError as exc:
        raise ReadError(f"{run.case_file} is not a valid case (edited, or written by another siloflow "
                        f"version):\n{exc}") from None


def design(case, run_folder: Optional[Path] = None, top: str = "flat") -> DesignResult:
    """EN 1991-4 loads (filling, discharge, patch, hopper) of ``case``'s silo filled to its bed
    height; ``case`` is a ``Case`` or a case-file path. ``run_folder``: a finished, post-processed
    run of the same case (checked field by field against what the loads depend on), whose band
    pressures come with the result. ``top``: ``flat`` (h_o = 0) or ``heap`` (a cone at the angle of
    repose)."""
    import pandas as pd

    from .derived import derive
    from .design_loads import CASE_FIELDS, bulk_solid, design_loads
    source = "the case" if isinstance(case, Case) else str(case)
    if not isinstance(case, Case):
        case = load_case(case)
    try:
        plan = derive(case)
    except CaseError as exc:
        raise CaseError(exc.problems, source) from None
    bands = None
    if run_folder is not None:
        run = RunFolder(run_folder)
        differs = case_differences(case, run_case(run), CASE_FIELDS)
        if differs:
            raise SetupError(f"--run {run_folder} is a run of another case: its {run.case_file.name} "
                             f"differs from {source} in what the design loads and its band pressures depend on:\n"
                             + "\n".join(f"  {path}: {msg}" for path, msg in differs[:10])
                             + (f"\n  and {len(differs) - 10} more" if len(differs) > 10 else "")
                             + f"\ngive a run of this case, or design with the run's own case: "
                             f"siloflow design {run.case_file}")
        bands_file = run.results / RESULT_TABLES["bands"]
        if not bands_file.is_file():
            raise ReadError(f"{bands_file} not found: post-process the run first (siloflow post {run_folder})")
        bands = pd.read_csv(bands_file)
    s = case.design or DEFAULT_DESIGN
    solid = bulk_solid(s.material, unit_weight=s.unit_weight, K=s.K, mu=s.mu, phi_r=s.phi_r_deg, C_op=s.C_op)
    loads = design_loads(plan.geometry, solid, plan.fill.bed_height_estimate, s.wall_type, s.action_assessment_class,
                         s.eccentricity, top=top)
    rho_g = case.materials.particle.density * plan.fill.packing_fraction * case.gravity
    return DesignResult(case, loads, bands, rho_g)


def sweep_table_runs(table_file: Path) -> list[Path]:
    """The run folders of a sweep table's complete runs (its ``run`` column; a relative path is
    taken from the table's folder). Raises ``ReadError``."""
    import pandas as pd
    try:
        rows = pd.read_csv(table_file)
    except (OSError, ValueError) as exc:
        raise ReadError(f"cannot read the sweep table {table_file}: {exc}") from None
    if "run" not in rows.columns:
        raise ReadError(f"{table_file} has no 'run' column: give run folders, or the sweep.csv of siloflow sweep")
    if "status" in rows.columns:
        rows = rows[rows.status == "complete"]
    runs = [path if path.is_absolute() else table_file.parent / path for path in map(Path, rows.run.astype(str))]
    if not runs:
        raise ReadError(f"{table_file} lists no complete run")
    return runs


def _left_out_lines(table) -> str:
    """The runs left out of a Beverloo fit, one line each with why ('' when none is)."""
    left = table[table.left_out != ""]
    return "".join(f"\n  left out: {row.run}: {row.left_out}" for row in left.itertuples())


def beverloo(folders: Sequence[Path]):
    """Beverloo's law W = C rho_b sqrt(g) (D0 - k d)^(5/2) (slabs' slots: C rho_b sqrt(g) L (D0 - k
    d)^(3/2), L the slab's depth) fitted across finished runs (different orifices or grains), or across the complete runs of one sweep table (``sweep.csv``). Returns
    ``(table, fit)``: one row per run (D0, d, W, rho_b, g; SI; ``left_out``: why a run is no point
    of the fit, '' for those fitted) and ``postprocess.flow_rate``'s fit (C and k with standard
    errors) over the runs not left out. A run whose discharge clogged, or that never flowed
    steadily (``postprocess.flow_rate.flow_verdict``), is left out. ``ReadError`` when the runs
    differ in gravity or cannot be read, when fewer than 3 runs are left to fit, or when the fit
    misses them by more than ``MAX_RMS_RELATIVE_RESIDUAL`` (20 %, rms relative residual): no C and k
    are given then."""
    from postprocess.flow_rate import beverloo as law
    from postprocess.flow_rate import beverloo_table, check_beverloo_fit, fit_beverloo
    folders = [Path(f) for f in folders]
    if len(folders) == 1 and folders[0].suffix == ".csv" and folders[0].is_file():
        folders = sweep_table_runs(folders[0])
    table = beverloo_table(folders)
    used = table[table.left_out == ""]
    left = _left_out_lines(table)
    if used.empty:
        raise ReadError(f"no run to fit: none of the {len(table)} given flowed steadily{left}")
    if used.g.nunique() > 1:
        raise ReadError("the runs differ in gravity; one Beverloo fit needs one g")
    slots = used.L.notna()
    if slots.any() and not slots.all():
        raise ReadError("the runs mix slots (slabs) and round orifices: one Beverloo fit needs one outlet shape")
    g, slot_length = float(used.g.iloc[0]), used.L if slots.all() else None
    try:
        fit = fit_beverloo(used.D0, used.d, used.W, used.rho_b, g, slot_length=slot_length, slot_ends=used.L_ends)
    except ValueError as exc:
        raise ReadError(f"{exc}{left}") from None
    except RuntimeError as exc:                 # scipy's curve_fit that did not converge
        raise ReadError(f"the Beverloo fit over {len(used)} runs did not converge ({exc}){left}") from None
    try:
        check_beverloo_fit(fit)
    except ValueError as exc:
        model = law(used.D0, used.d, fit.C, fit.k, used.rho_b, g, slot_length, used.L_ends)
        runs = "".join(f"\n  {row.run}: W = {row.W:.4g} kg/s, the fit's {w:.4g} kg/s"
                       for row, w in zip(used.itertuples(), model))
        raise ReadError(f"{exc}:{runs}{left}\nlook for a run that clogged or never reached a steady flow "
                        "(siloflow post RUN says), or orifices too near k d") from None
    return table, fit
