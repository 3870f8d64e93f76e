"""A sweep written as Slurm job arrays instead of run here (``siloflow sweep --slurm``): the fills
(one task per fill group), then the other runs after them, in arrays of at most ``max_array_size``
tasks, and the script that submits them (``submit.sh``)."""
from __future__ import annotations

import math
import shlex
from pathlib import Path
from typing import Optional

from .errors import SetupError
from .sweep_folder import check_cases, check_owned, open_record, save_record, write_cases, write_owned
from .sweep_plan import StageProgress, Variant, variant_keys

#: most tasks of one Slurm job array by default (Slurm's MaxArraySize is 1001 unless raised)
DEFAULT_MAX_ARRAY_SIZE = 1000


def _relative(path: Path, out: Path) -> str:
    """``path`` relative to the sweep folder when inside it (the folder can move to a cluster)."""
    path = Path(path).absolute()
    return path.relative_to(out).as_posix() if out in path.parents else str(path)


def _array_script(job_name: str, tasks: str, variants: list[Variant], what: str, siloflow: str, cache: str,
                  max_array_size: int) -> str:
    """A job array script: task k of an array submitted with offset o (the script's argument,
    default 0) runs ``siloflow run`` on the case file on line o + k + 1 of ``tasks``."""
    ranks = max(v.case.engine.ranks for v in variants)
    arrays = math.ceil(len(variants) / max_array_size)
    run = f"{shlex.quote(siloflow)} run \"$case_file\" -o \"runs/$name\" --cache {shlex.quote(cache)}"
    return f"""#!/bin/bash
# siloflow sweep: {what}
# One array task per line of {tasks}: task k of an array submitted with offset o (this script's
# argument, default 0) runs the case file on line o + k + 1, in the sweep folder (submit.sh
# submits from there). Slurm's MaxArraySize (1001 by default) bounds an array's task indices, so
# submit.sh submits {len(variants)} tasks as {arrays} array(s) of at most {max_array_size} tasks
# (siloflow sweep --max-array-size); #SBATCH --array below is the first.
# siloflow starts the engine itself (mpirun -np <engine.ranks>) inside the task's allocation, so a
# task is one node with one Slurm task per MPI rank, one CPU each: --ntasks = --ntasks-per-node =
# the largest engine.ranks of these cases ({ranks}), --cpus-per-task=1. Open MPI's mpirun takes its
# slots from the allocation; srun is not used. The fill cache must be on a file system every node sees.
#SBATCH --job-name={job_name}
#SBATCH --array=0-{min(len(variants), max_array_size) - 1}
#SBATCH --nodes=1
#SBATCH --ntasks={ranks}
#SBATCH --ntasks-per-node={ranks}
#SBATCH --cpus-per-task=1
#SBATCH --output=logs/%x-%A_%a.out
set -euo pipefail
offset=${{1:-0}}
case $offset in
    ''|*[!0-9]*) echo "the offset into {tasks} must be a whole number, not '$offset'" >&2; exit 1 ;;
esac
line=$((offset + SLURM_ARRAY_TASK_ID + 1))
case_file=$(sed -n "${{line}}p" {tasks})
if [ -z "$case_file" ]; then
    echo "no case file on line $line of {tasks}" >&2
    exit 1
fi
name=$(basename "$case_file" .yaml)
export COLUMNS=200
exec {run}
"""


def _arrays(count: int, size: int) -> list[tuple[int, int]]:
    """(offset, tasks) of the arrays that cover ``count`` lines, at most ``size`` tasks each."""
    return [(start, min(size, count - start)) for start in range(0, count, size)]


def _submit_script(fills: list[tuple[int, int]], runs: list[tuple[int, int, list[int]]]) -> str:
    """``fills``: (offset, tasks) of each fills array; ``runs``: (offset, tasks, the fills
    arrays holding its runs' fills) of each runs array."""
    lines = ["#!/bin/bash",
             "# Submit the sweep: the fills (one per distinct settled bed), then the other runs, each array",
             "# of them once every fills array holding their fills succeeded (afterok), so they start from",
             "# the cached beds. Each array is at most --max-array-size tasks; its argument is its offset",
             "# into fills.txt or runs.txt. If a fill fails, the runs after it stay pending",
             "# (DependencyNeverSatisfied): scancel them, fix the case, submit again.",
             "set -euo pipefail",
             'cd "$(dirname "$0")"']

    def submit(kind: str, k: int, total: int, offset: int, tasks: int, options: str, after: str) -> list[str]:
        var = f"{kind}_{k}"
        return [f"{var}=$(sbatch --parsable --array=0-{tasks - 1}{options} {kind}.sbatch {offset})",
                f"{var}=${{{var}%%;*}}                 # --parsable prints jobid[;cluster]",
                f'echo "{kind} {k + 1}/{total}: job ${var} ({tasks} task{"s" if tasks != 1 else ""}, lines '
                f'{offset + 1}-{offset + tasks} of {kind}.txt{after})"']

    for k, (offset, tasks) in enumerate(fills):
        lines += submit("fills", k, len(fills), offset, tasks, "", "")
    for k, (offset, tasks, needs) in enumerate(runs):
        jobs = ":".join(f'"$fills_{j}"' for j in needs)
        shown = ", ".join(f"$fills_{j}" for j in needs)
        lines += submit("runs", k, len(runs), offset, tasks, f" --dependency=afterok:{jobs}", f", after job(s) {shown}")
    return "\n".join(lines) + "\n"


def write_slurm(variants: list[Variant], groups: dict[str, list[Variant]], out: Path, cache: Path,
                siloflow: str = "siloflow", max_array_size: int = DEFAULT_MAX_ARRAY_SIZE,
                progress: Optional[StageProgress] = None) -> Path:
    """Write the sweep as Slurm job arrays instead of running it; return ``out/submit.sh``.

    Writes ``out/cases/*.yaml`` (``progress`` as :func:`write_cases`); ``fills.txt`` (the first
    variant of each fill group) and ``runs.txt`` (the others), one case file per line;
    ``fills.sbatch`` and ``runs.sbatch``, their job array scripts (each task ``siloflow run
    <case> -o runs/<name> --cache <cache>``); ``submit.sh``, which submits the fills as arrays of
    at most ``max_array_size`` tasks, each with its offset into ``fills.txt``, then the runs
    likewise, each runs array with ``--dependency=afterok:`` the fills arrays holding its runs'
    fills (only the fills when every group has one variant); the empty ``logs/`` and ``runs/``
    folders. Paths inside ``out`` are written relative to it. A file siloflow wrote is replaced
    only while unchanged (:func:`write_owned`); ``SetupError`` for a folder of another sweep, a
    file edited or not siloflow's (before anything is written), or ``max_array_size`` < 1.
    """
    out = Path(out).absolute()
    if not variants:
        raise SetupError("the sweep has no variants")
    if isinstance(max_array_size, bool) or not isinstance(max_array_size, int) or max_array_size < 1:
        raise SetupError(f"--max-array-size {max_array_size!r}: the tasks of one job array must be a whole number >= 1")
    keys = variant_keys(groups, variants)
    record = open_record(out, variants)
    fills = [members[0] for members in groups.values()]
    runs = sorted((v for members in groups.values() for v in members[1:]), key=lambda v: v.index)
    fill_line = {v.name: k for k, v in enumerate(fills)}
    first_of = {key: members[0].name for key, members in groups.items()}
    base = variants[0].name.rsplit("-", 1)[0]
    cache_path = _relative(cache, out)
    texts = {}
    for kind, members, what in [
            ("fills", fills, f"the fills: one task per fill group ({len(fills)}), each computing a settled bed and "
                             "caching it for the group's other runs"),
            ("runs", runs, f"the other runs ({len(runs)}), each starting from its group's cached bed")]:
        if members:
            texts[f"{kind}.txt"] = "".join(f"cases/{v.name}.yaml\n" for v in members)
            texts[f"{kind}.sbatch"] = _array_script(f"{base}-{kind}", f"{kind}.txt", members, what, siloflow,
                                                    cache_path, max_array_size)
    run_arrays = [(offset, tasks, sorted({fill_line[first_of[keys[v.name]]] // max_array_size
                                          for v in runs[offset:offset + tasks]}))
                  for offset, tasks in _arrays(len(runs), max_array_size)]
    texts["submit.sh"] = _submit_script(_arrays(len(fills), max_array_size), run_arrays)
    check_owned(out, record, texts)             # everything checked before anything is written
    check_cases(out, variants)
    out.mkdir(parents=True, exist_ok=True)
    save_record(out, record)
    write_cases(variants, out, progress, checked=True)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_owned(out, record, texts)
    submit = out / "submit.sh"
    submit.chmod(0o755)
    return submit
