"""``siloflow paper-a``: run paper A's sphere model and multi-element model and write the claims
report (``postprocess.paper_a`` measures, ``postprocess.report.paper_a`` writes).

The runs go to ``runs/paper_a/<model>-seed<k>`` and are reused when they finished (a rerun
continues where the last one stopped: an interrupted run is resumed, a missing one started).
At ``scale="paper"`` nothing runs before the cost is printed and confirmed."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import yaml

from .case_file import case_from_dict
from .errors import SetupError, SiloflowError
from .resources import example_text
from .run_folder import STATUS_NAME, RunFolder, run_state

#: the decks of each scale, and the runs' silo over the paper's (lengths)
SCALES = {"quick": {"spheres": "paper_a_spheres_quick.yaml", "clumps": "paper_a_clumps_quick.yaml", "length_scale": 0.25},
          "paper": {"spheres": "paper_a_spheres.yaml", "clumps": "paper_a_clumps.yaml", "length_scale": 1.0}}
#: engine speed (particle-steps per second) assumed for a cost estimate when no finished run of the
#: model measured one here: LIGGGHTS on 2 ranks with sensor meshes (make bench-engines, issue 41)
DEFAULT_RATE = 2.9e6
#: the machine: a confirmation is needed above this many core-hours
AFFORDABLE_CORE_HOURS = 2.0


@dataclass(frozen=True)
class PaperRun:
    """One run of the report: the model, the seed index, its case (a dict) and its folder."""

    model: str
    index: int
    case: dict
    folder: Path


def plan_runs(scale: str, seeds: int, decks: Optional[Path], runs: Path) -> list[PaperRun]:
    """The runs the report needs: ``seeds`` of each model, the first with the deck's seed, the
    others with the next ones (``seed + k``). The decks are siloflow's shipped ones, or those in
    the folder ``decks``."""
    if scale not in SCALES:
        raise SetupError(f"--scale {scale!r}: one of {', '.join(SCALES)}")
    if not 1 <= seeds <= 50:
        raise SetupError(f"--seeds {seeds}: between 1 and 50")
    out = []
    for model in ("spheres", "clumps"):
        name = SCALES[scale][model]
        path = Path(decks) / name if decks is not None else f"siloflow's shipped {name}"
        try:
            text = Path(path).read_text(encoding="utf-8") if decks is not None else example_text(name)
            data = yaml.safe_load(text)
        except (OSError, yaml.YAMLError) as exc:
            raise SetupError(f"cannot read paper A's deck {path}: {exc}") from None
        for k in range(seeds):
            case = {**data, "seed": int(data.get("seed", 1)) + k, "name": f"{data['name']}_seed{k}"}
            case_from_dict(case)           # a bad deck is refused before anything runs
            out.append(PaperRun(model, k, case, Path(runs) / f"{model}-seed{k}"))
    return out


def finished(folder: Path) -> bool:
    """Whether a run folder holds a complete, post-processed run."""
    try:
        return run_state(folder).get("state") == "complete" and RunFolder(folder).summary_file.is_file()
    except (OSError, ValueError, SiloflowError):      # a missing or unreadable folder is not finished
        return False


def cost(runs: list[PaperRun]) -> dict:
    """The runs' estimated cost: sphere-steps (every sphere of every clump, and the dust, times the
    planned steps), the engine speed (from a finished run of the same model here, else
    :data:`DEFAULT_RATE`), core-hours and disk (bytes)."""
    from .derived import derive
    from .disk_estimate import estimate_bytes
    total, hours, disk, rates = 0.0, 0.0, 0.0, {}
    for r in runs:
        case = case_from_dict(r.case)
        plan = derive(case)
        work = float(plan.expected_atoms) * plan.total_planned_steps
        if r.model not in rates:
            rates[r.model] = measured_rate(r.folder.parent, r.model) or DEFAULT_RATE
        total += work
        hours += work / rates[r.model] / 3600.0 * case.engine.ranks
        disk += estimate_bytes(case, plan)["total"]
    return {"sphere_steps": total, "core_hours": hours, "disk_bytes": disk, "rates": rates}


def measured_rate(runs: Path, model: str) -> Optional[float]:
    """Sphere-steps per second of a finished run of ``model`` under ``runs`` (its atoms times its
    last step over its record's wall time), or None."""
    for folder in sorted(Path(runs).glob(f"{model}-seed*")):
        if finished(folder):
            run = RunFolder(folder)
            try:
                steps = int(run.flow().step.max())
                return run.plan.expected_atoms * steps / run.record.wall_time if run.record.wall_time > 0 else None
            except (OSError, ValueError, KeyError, AttributeError, SiloflowError):   # unreadable: no measurement
                continue
    return None


def cost_text(c: dict, runs: list[PaperRun]) -> str:
    """The cost estimate as the user reads it before confirming."""
    rates = ", ".join(f"{m} {r:.3g} sphere-steps/s" for m, r in c["rates"].items())
    return (f"paper A at this scale: {len(runs)} runs, {c['sphere_steps']:.3g} sphere-steps at {rates} "
            f"(a finished run here measures it, else siloflow's benchmark): about {c['core_hours']:.3g} core-hours "
            f"and {c['disk_bytes'] / 1e9:.3g} GB of disk")


def run_paper_a(scale: str = "quick", seeds: int = 1, decks: Optional[Path] = None, runs: Path = Path("runs/paper_a"),
                out: Path = Path("reports/paper_a"), confirm: bool = False, say: Callable[[str], None] = print,
                progress=None) -> list[Path]:
    """Run what is missing of paper A's runs (finished ones are reused, interrupted ones resumed)
    and write the claims report into ``out``. Above :data:`AFFORDABLE_CORE_HOURS` (and always at
    the paper's scale) nothing runs unless ``confirm``. Returns the report's files."""
    from postprocess.paper_a import chains_at, paper_a_claims, pressure_series
    from postprocess.report.paper_a import write_paper_a_report

    from . import runs as pipeline
    planned = plan_runs(scale, seeds, decks, runs)
    todo = [r for r in planned if not finished(r.folder)]
    if todo:
        c = cost(todo)
        say(cost_text(c, todo))
        if (scale == "paper" or c["core_hours"] > AFFORDABLE_CORE_HOURS) and not confirm:
            raise SetupError("not started: confirm the cost with --yes (make paper-a SCALE=... CONFIRM=yes), "
                             "or run it on a cluster (siloflow sweep --slurm)")
    for r in todo:
        say(f"running {r.model} seed {r.index} in {r.folder}")
        state = run_state(r.folder).get("state") if (r.folder / STATUS_NAME).is_file() else None
        if state in ("interrupted", "failed", "abandoned"):
            pipeline.resume(r.folder, progress=progress)
        else:
            pipeline.run(r.case, r.folder, force=r.folder.exists(), progress=progress)
    spheres = [r.folder for r in planned if r.model == "spheres"]
    clumps = [r.folder for r in planned if r.model == "clumps"]
    length = SCALES[scale]["length_scale"]
    rows, numbers = paper_a_claims(spheres, clumps, length)
    series = pressure_series(spheres, clumps, length)
    t = numbers["contacts_time_after_open_s"]
    chains = {"spheres": chains_at(spheres[0], t), "clumps": chains_at(clumps[0], t)}
    plan = RunFolder(spheres[0]).plan
    meta = {"scale": scale, "seeds": {"spheres": len(spheres), "clumps": len(clumps)},
            "cases": {m: [SCALES[scale][m]] for m in ("spheres", "clumps")}, "length_scale": length,
            "pressure_scale": numbers["pressure_scale"], "time_scale": numbers["time_scale"],
            "grains_across": plan.geometry.width / (2 * plan.particle_radius),
            "command": f"make paper-a SCALE={scale}" + (f" SEEDS={seeds}" if seeds != 1 else "")}
    return write_paper_a_report(out, rows, numbers, meta, series, chains)
