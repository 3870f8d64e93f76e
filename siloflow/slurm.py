"""Runs written as Slurm batch scripts instead of run here.

- One run over one or many nodes (``siloflow run CASE -o DIR --slurm``): the folder is rendered here and
  ``DIR/job.sbatch`` runs it (``siloflow run --resume DIR``) as one MPI job over the allocation
  (:class:`SlurmJob`, :func:`write_run_script`).
- A sweep (``siloflow sweep --slurm``): the fills (one task per fill group), then the other runs after
  them, in arrays of at most ``max_array_size`` tasks, and the script that submits them (``submit.sh``).
"""
from __future__ import annotations

import math
import re
import shlex
import sys
from pathlib import Path
from typing import Literal, Optional

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .atomic_files import write_text
from .errors import CaseError, SetupError
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


# ------------------------------------------------------------------ one run over many nodes
#: Slurm's --time forms: minutes, minutes:seconds, hours:minutes:seconds, days-hours,
#: days-hours:minutes, days-hours:minutes:seconds
SLURM_TIME = re.compile(r"^(\d+|\d+:\d{1,2}|\d+:\d{1,2}:\d{1,2}|\d+-\d{1,2}|\d+-\d{1,2}:\d{1,2}|"
                        r"\d+-\d{1,2}:\d{1,2}:\d{1,2})$")
#: a partition or account name as Slurm writes them (no spaces, no shell characters)
SLURM_NAME = re.compile(r"^[A-Za-z0-9_.+-]{1,64}$")
#: the one run's batch script, in its run folder
RUN_SCRIPT = "job.sbatch"


class SlurmJob(BaseModel):
    """The allocation of one run's Slurm job: ``nodes`` x ``ntasks_per_node`` MPI ranks (one CPU each),
    its wall-time limit, partition and account, the MPI launcher (``mpirun``: the site's Open MPI,
    which takes its hosts from the allocation; ``srun``: Slurm's own), and how long before the limit
    Slurm asks the run to stop (``grace_s``, s) so that it is marked interrupted and resumable."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    nodes: int = Field(1, ge=1, le=10000, description="nodes")
    ntasks_per_node: int = Field(1, ge=1, le=1024, description="MPI ranks per node")
    time: str = Field("24:00:00", description="wall-time limit (Slurm's --time)")
    partition: Optional[str] = Field(None, description="partition (Slurm's --partition)")
    account: Optional[str] = Field(None, description="account (Slurm's --account)")
    launcher: Literal["mpirun", "srun"] = Field("mpirun", description="the MPI launcher")
    grace_s: int = Field(300, ge=10, le=86400, description="s before the time limit at which the run is stopped")
    requeue: bool = Field(False, description="requeue the job when the time limit stopped it")

    @field_validator("time")
    @classmethod
    def _time(cls, v: str) -> str:
        if not SLURM_TIME.match(v):
            raise ValueError(f"{v!r} is not a Slurm time (minutes, HH:MM:SS or D-HH:MM:SS)")
        return v

    @field_validator("partition", "account")
    @classmethod
    def _name(cls, v: Optional[str]) -> Optional[str]:
        if v is not None and not SLURM_NAME.match(v):
            raise ValueError(f"{v!r}: letters, digits and _ . + - only")
        return v

    @property
    def ranks(self) -> int:
        """The run's MPI ranks: every task of every node."""
        return self.nodes * self.ntasks_per_node


def slurm_job(**options) -> SlurmJob:
    """A :class:`SlurmJob` from the CLI's options; ``CaseError`` naming each option (``--nodes``...) that is wrong."""
    try:
        return SlurmJob(**options)
    except ValidationError as exc:
        raise CaseError([("--" + str(e["loc"][0]).replace("_", "-"), e["msg"]) for e in exc.errors()],
                        "siloflow run --slurm") from None


def sbatch_header(job: SlurmJob, name: str) -> list[str]:
    """The ``#SBATCH`` lines of ``job`` for a job called ``name`` (made safe for Slurm)."""
    lines = [f"#SBATCH --job-name={re.sub(r'[^A-Za-z0-9_.-]', '_', name)[:64] or 'siloflow'}",
             f"#SBATCH --nodes={job.nodes}", f"#SBATCH --ntasks-per-node={job.ntasks_per_node}",
             f"#SBATCH --ntasks={job.ranks}", "#SBATCH --cpus-per-task=1", f"#SBATCH --time={job.time}",
             f"#SBATCH --signal=B:TERM@{job.grace_s}", "#SBATCH --output=slurm-%j.out", "#SBATCH --open-mode=append"]
    lines += [f"#SBATCH --partition={job.partition}"] if job.partition else []
    lines += [f"#SBATCH --account={job.account}"] if job.account else []
    lines += ["#SBATCH --requeue"] if job.requeue else []
    return lines


def siloflow_here() -> list[str]:
    """The command that starts this siloflow (its Python, absolute: on a cluster the environment that
    rendered the folder sits on the shared file system the job sees)."""
    return [sys.executable, "-m", "siloflow.cli"]


def run_script(job: SlurmJob, folder: Path, name: str, engine: str, siloflow: Optional[list[str]] = None,
               cache: Optional[Path] = None) -> str:
    """The batch script that runs the rendered run folder ``folder`` (absolute) over ``job``'s
    allocation: ``siloflow run --resume`` (``siloflow``: the command, default :func:`siloflow_here`)
    in the background of the batch shell, which passes Slurm's stop signal on to it."""
    q = shlex.quote
    resume = " ".join([*map(q, siloflow or siloflow_here()), "run", "--resume", q(str(folder)), *(["--cache", q(str(cache))] if cache else [])])
    launcher = "srun" if job.launcher == "srun" else "mpirun"
    requeue = ('if [ -n "$stopping" ] && [ "$status" -eq 130 ]; then\n'
               '    scontrol requeue "$SLURM_JOB_ID"          # the run resumes where it stopped\n'
               'fi\n') if job.requeue else ""
    return "\n".join([
        "#!/bin/bash",
        f"# siloflow run --slurm: the run {name} ({engine}) as one MPI job of {job.ranks} ranks,",
        f"# {job.nodes} node(s) x {job.ntasks_per_node}. Its folder was rendered by siloflow: {folder}",
        "# The folder must be on a file system every node sees (the ranks read its meshes and fill, and",
        "# write its output there). Submit: cd to it and sbatch job.sbatch (siloflow prints the line).",
        f"# {job.grace_s} s before the time limit Slurm sends SIGTERM (--signal): siloflow stops the engine",
        "# and marks the run interrupted; submitting again resumes it (siloflow run --resume) from its last",
        "# restart point" + (", and this job requeues itself." if job.requeue else "."),
        *sbatch_header(job, name),
        "set -uo pipefail",
        "export COLUMNS=200",
        f"export SILOFLOW_MPIRUN={launcher}       # the launcher of the engine's ranks (siloflow.engine.base)",
        'stopping=""',
        f"{resume} &",
        "child=$!",
        "trap 'stopping=yes; kill -TERM \"$child\" 2>/dev/null' TERM",
        'wait "$child"; status=$?',
        'if [ -n "$stopping" ]; then wait "$child"; status=$?; fi',
        requeue + 'exit "$status"', ""])


def write_run_script(job: SlurmJob, folder: Path, name: str, engine: str, siloflow: Optional[list[str]] = None,
                     cache: Optional[Path] = None) -> tuple[Path, str]:
    """Write ``folder/job.sbatch`` (:func:`run_script`, atomically) into a run folder siloflow just
    rendered; return its path and the shell line that submits it."""
    folder = Path(folder).absolute()
    script = folder / RUN_SCRIPT
    write_text(script, run_script(job, folder, name, engine, siloflow, Path(cache).absolute() if cache else None))
    script.chmod(0o755)
    return script, f"cd {shlex.quote(str(folder))} && sbatch {RUN_SCRIPT}"
