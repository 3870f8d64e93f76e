"""What the demo deck's walls, sensors and outputs cost (issue 56): deck variants from one settled bed.

Takes a finished demo run folder written by the sensor-mesh deck (siloflow bbe14bc: ``git worktree add
/tmp/baseline bbe14bc``, then that checkout's ``siloflow run decks/demo.yaml -o RUN``; its settled restart
is what every variant starts from), writes its resume deck's variants beside it, and runs each alone,
one at a time, for the static stage (2,000 steps), the opening and 3,000 steps of discharge:

- V0: the deck as it was (52 sensor meshes in one wall/gran; 480/720/720-triangle floor, plate, disc);
- V1: the side wall as one mesh of the same triangles (no band sensors);
- V2: V1 with a one-ring floor, a fan plate and a fan counting disc (96, 48, 48 triangles);
- V3: the side wall a primitive zcylinder (store_force), V2's floor, plate and disc, every output;
- V4: V3 with each of the 52 band sectors binned in the engine (compute reduce/region): siloflow's deck now;
- V5: V2 with the wall contacts dumped at every wall-force sample (the per-contact alternative);
- V6: the raw deck: V3 without outputs, dumps, guard or time-step check;
- V7: V0 without outputs, dumps, guard or time-step check.

The measure is CPU seconds (user, ``/usr/bin/time``) of a one-rank run, which a busy machine disturbs
less than wall time; LIGGGHTS' loop split (wall seconds) is beside it. Writes
``benchmarks/results/deck_variants/variants.csv``.

    .venv/bin/python benchmarks/deck_variants.py RUN
"""
from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd

from bench_runs import LOOP, loop_split

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "deck_variants"
STATIC, DISCHARGE = 2000, 3000
#: LIGGGHTS' band heights of the demo (decks/demo.yaml sensors.heights)
HEIGHTS = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.10, 0.11, 0.12, 0.22]
SECTORS = 4
UNSAMPLED = ("dump", "compute         contacts", "compute         guard", "fix             wall_forces",
             "compute         wall_contacts", "fix             timestep_check")


def stl(name: str, tris) -> str:
    out = [f"solid {name}"]
    for t in tris:
        n = np.cross(t[1] - t[0], t[2] - t[0])
        n = n / np.linalg.norm(n)
        out += [f"facet normal {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}", "outer loop",
                *(f"vertex {v[0]:.12g} {v[1]:.12g} {v[2]:.12g}" for v in t), "endloop", "endfacet"]
    return "\n".join(out + [f"endsolid {name}"]) + "\n"


def read_stl(path: Path) -> np.ndarray:
    v = [list(map(float, line.split()[1:])) for line in path.read_text().splitlines()
         if line.strip().startswith("vertex")]
    return np.array(v).reshape(-1, 3, 3)


def ring(r: float, z: float, n: int) -> np.ndarray:
    th = np.linspace(0, 2 * np.pi, n + 1)[:-1]
    return np.stack([r * np.cos(th), r * np.sin(th), np.full(n, z)], 1)


def annulus(r0: float, r1: float, z: float, n: int) -> np.ndarray:
    a, b = ring(r0, z, n), ring(r1, z, n)
    return np.array([t for i in range(n) for t in ([a[i], b[i], b[(i + 1) % n]], [a[i], b[(i + 1) % n], a[(i + 1) % n]])])


def fan(r: float, z: float, n: int) -> np.ndarray:
    a, c = ring(r, z, n), np.array([0.0, 0.0, z])
    return np.array([[c, a[i], a[(i + 1) % n]] for i in range(n)])


def replace_lines(lines, start: str, new: str | None) -> list[str]:
    """``lines`` with each line starting with ``start`` replaced by ``new`` (None: dropped)."""
    return [new if line.startswith(start) else line for line in lines if not (line.startswith(start) and new is None)]


def after(lines, start: str, new: list[str]) -> list[str]:
    out = []
    for line in lines:
        out.append(line)
        if line.startswith(start):
            out += new
    return out


def variants(run: Path, base: str) -> dict[str, list[str]]:
    """The eight decks (see the module docstring) as lists of lines, their meshes written into ``run``."""
    plan = json.loads((run / "plan.json").read_text())
    g = plan["geometry"]
    R, n, r_out = g["radius"], g["mesh_segments"], g["outlet_radius"]
    meshes = run / "meshes"
    side = [p for p in sorted(meshes.glob("*.stl")) if p.stem.startswith(("band", "wall_"))]
    (meshes / "side_one.stl").write_text(stl("side", np.concatenate([read_stl(p) for p in side])))
    (meshes / "bottom_c.stl").write_text(stl("bottom_c", annulus(r_out, R, 0.0, n)))
    (meshes / "plate_c.stl").write_text(stl("plate_c", fan(r_out, 0.0, n)))
    (meshes / "outlet_c.stl").write_text(stl("outlet_c", fan(plan["outlet"]["radius"], plan["outlet"]["z"], n)))
    lines = base.splitlines()
    lines = [re.sub(r"^run             \d+$", f"run             {STATIC}", l) if i < _stage(lines, "open") else l
             for i, l in enumerate(lines)]
    lines = [re.sub(r"^run             \d+$", f"run             {DISCHARGE}", l) if i > _stage(lines, "discharge") else l
             for i, l in enumerate(lines)]
    walls_fix = "fix             walls all wall/gran model hertz tangential history mesh n_meshes {} meshes {}"
    is_side = re.compile(r"fix\s+(band\d+_s\d+|wall_above|wall_below)\s")
    no_side = [l for l in lines if not is_side.match(l)]

    def sampled(names):
        return ("fix             wall_forces all ave/time 42 5 210" + "".join(f" {s}[1] {s}[2] {s}[3]" for s in names)
                + " file output/wall_forces.txt")

    def coarse(ls):
        return [re.sub(r"meshes/(bottom|plate|outlet)\.stl", r"meshes/\1_c.stl", l) for l in ls]

    one = after(no_side, "fix             outlet_resumed",
                ["fix             side all mesh/surface/stress file meshes/side_one.stl type 2"])
    one = replace_lines(one, "fix             walls all", walls_fix.format(3, "side bottom_resumed plate_resumed"))
    one = replace_lines(one, "fix             wall_forces", sampled(["f_side", "f_bottom_resumed", "f_plate_resumed"]))
    prim = replace_lines(coarse(no_side), "fix             walls all", walls_fix.format(2, "bottom_resumed plate_resumed"))
    prim = after(prim, "fix             walls all", [
        f"fix             side all wall/gran model hertz tangential history primitive type 2 zcylinder {R} 0.0 0.0 "
        "store_force yes"])
    prim = replace_lines(prim, "fix             wall_forces", sampled(["f_bottom_resumed", "f_plate_resumed"]))
    regions, names = [], []
    for s in range(SECTORS):
        t0, t1 = 2 * math.pi * s / SECTORS, 2 * math.pi * (s + 1) / SECTORS
        regions += [f"region          sa{s} plane 0.0 0.0 0.0 {-math.sin(t0):.12g} {math.cos(t0):.12g} 0.0 units box",
                    f"region          sb{s} plane 0.0 0.0 0.0 {math.sin(t1):.12g} {-math.cos(t1):.12g} 0.0 units box"]
    for b, (z0, z1) in enumerate(zip(HEIGHTS, HEIGHTS[1:])):
        regions.append(f"region          zb{b} block INF INF INF INF {z0} {z1} units box")
        for s in range(SECTORS):
            regions += [f"region          b{b}s{s} intersect 3 zb{b} sa{s} sb{s}",
                        f"compute         rb{b}s{s} all reduce/region b{b}s{s} sum f_force_side[1] f_force_side[2] "
                        "f_force_side[3]"]
            names.append(f"c_rb{b}s{s}")
    binned = replace_lines(after(prim, "fix             side all wall/gran", regions), "fix             wall_forces",
                           sampled(["f_bottom_resumed", "f_plate_resumed"] + names))
    samples = after(coarse(one), "dump_modify     wall_contacts", [
        "dump            wall_samples all local 42 output/dumps/wall_samples.txt c_wall_contacts[1] c_wall_contacts[2] "
        "c_wall_contacts[3] c_wall_contacts[7] c_wall_contacts[8] c_wall_contacts[9] c_wall_contacts[10] "
        "c_wall_contacts[11] c_wall_contacts[12]"])

    def raw(ls):
        return ["thermo_style    custom step time atoms" if l.startswith("thermo_style") else l
                for l in ls if not l.startswith(UNSAMPLED)]

    return {"V0_sensor_meshes": lines, "V1_one_side_mesh": one, "V2_one_side_mesh_few_triangle_floor": coarse(one),
            "V3_primitive_side": prim, "V4_primitive_side_binned": binned, "V5_one_side_mesh_contact_samples": samples,
            "V6_raw_primitive": raw(prim), "V7_sensor_meshes_no_outputs": raw(lines)}


def _stage(lines, name: str) -> int:
    return next(i for i, l in enumerate(lines) if l.startswith(f'print           "SILOFLOW_STAGE {name}'))


def loop_rates(log: str) -> dict:
    """Loop wall seconds, particle-steps and the loop split (``bench_runs.loop_split``) over a log's runs."""
    loops = LOOP.findall(log)
    return {"loop_s": sum(float(a) for a, *_ in loops), "particle_steps": sum(int(s) * int(n) for *_, s, n in loops),
            **loop_split(log)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path, help="a finished demo run folder of the sensor-mesh deck (bbe14bc)")
    args = ap.parse_args()
    resume = args.run / "in.resume.liggghts"
    if not resume.exists() or "band00_s00.stl" not in resume.read_text():
        raise SystemExit(f"{resume}: write the sensor-mesh deck's resume deck there with the baseline's code: PYTHONPATH="
                         "/tmp/baseline python -c \"from siloflow.engine.processes import read_plan; from siloflow."
                         "engine.liggghts.deck import write_resume_deck; write_resume_deck(read_plan('RUN'), 'RUN')\"")
    rows = []
    for name, lines in variants(args.run, (args.run / "in.resume.liggghts").read_text()).items():
        (args.run / f"in.{name}").write_text("\n".join(lines) + "\n")
        done = subprocess.run(["/usr/bin/time", "-f", "%U %S %e", "mpirun", "--allow-run-as-root", "-np", "1", "liggghts",
                               "-in", f"in.{name}", "-log", f"log.{name}", "-screen", f"screen.{name}"],
                              cwd=args.run, capture_output=True, text=True)
        user, system, wall = (float(x) for x in done.stderr.strip().splitlines()[-1].split())
        rows.append({"variant": name, "cpu_user_s": user, "wall_s": wall,
                     **loop_rates((args.run / f"log.{name}").read_text(errors="replace"))})
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    raw = float(table.loc[table.variant == "V6_raw_primitive", "cpu_user_s"].iloc[0])
    table["fraction_of_raw_rate"] = raw / table.cpu_user_s
    OUT.mkdir(parents=True, exist_ok=True)
    table.to_csv(OUT / "variants.csv", index=False)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
