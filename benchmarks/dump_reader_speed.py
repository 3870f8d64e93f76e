"""Dump reader speed: siloflow's reader against MDAnalysis' LAMMPSDUMP reader on the same
fixed-N text dump (positions and velocities of every frame), plain and gzip. Prints the
times of one run each and their ratio (this machine is noisy: read the ratio).

    python benchmarks/dump_reader_speed.py [atoms] [frames]
"""
from __future__ import annotations

import gzip
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from postprocess.dumps import read_frames  # noqa: E402


def write_dump(path: Path, n: int, frames: int, seed: int = 0) -> None:
    """A LIGGGHTS-like dump custom (id type x y z vx vy vz radius), atoms in shuffled order."""
    rng = np.random.default_rng(seed)
    with open(path, "w") as fh:
        for k in range(frames):
            ids = rng.permutation(n) + 1
            data = np.column_stack([rng.random((n, 3)), rng.normal(size=(n, 3)), np.full(n, 1e-3)])
            fh.write(f"ITEM: TIMESTEP\n{k * 1000}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS ff ff ff\n"
                     "0 1\n0 1\n0 1\nITEM: ATOMS id type x y z vx vy vz radius \n")
            body = np.column_stack([ids, np.ones(n), data])
            np.savetxt(fh, body, fmt=["%d", "%d"] + ["%.6g"] * 7)


def ours(path: Path) -> float:
    total = 0.0
    for frame in read_frames(path):
        total += frame.positions().sum() + frame.velocities().sum()
    return total


def mdanalysis(path: Path) -> float:
    import MDAnalysis
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u = MDAnalysis.Universe(str(path), format="LAMMPSDUMP", topology_format="LAMMPSDUMP",
                                lammps_coordinate_convention="unscaled")
        total = 0.0
        for ts in u.trajectory:
            total += float(ts.positions.sum(dtype=np.float64)) + float(ts.velocities.sum(dtype=np.float64))
    return total


def timed(fn, path):
    t0 = time.perf_counter()
    value = fn(path)
    return time.perf_counter() - t0, value


def main(n: int = 100_000, frames: int = 10) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp) / "bench.dump"
        write_dump(plain, n, frames)
        packed = Path(tmp) / "bench.dump.gz"
        with open(plain, "rb") as src, gzip.open(packed, "wb", compresslevel=1) as dst:
            shutil.copyfileobj(src, dst)
        size = plain.stat().st_size / 1e6
        print(f"dump: {frames} frames x {n} atoms, {size:.0f} MB")
        t_ours, v_ours = timed(ours, plain)
        t_mda, v_mda = timed(mdanalysis, plain)
        t_gz, _ = timed(ours, packed)
        agree = abs(v_ours - v_mda) <= 1e-5 * max(1.0, abs(v_ours))
        print(f"siloflow reader       {t_ours:7.2f} s  ({n * frames / t_ours / 1e6:.2f} M atoms/s)")
        print(f"siloflow reader, gzip {t_gz:7.2f} s")
        print(f"MDAnalysis            {t_mda:7.2f} s  ({n * frames / t_mda / 1e6:.2f} M atoms/s)")
        print(f"speed ratio MDAnalysis / siloflow = {t_mda / t_ours:.1f}x (goal >= 5x); "
              f"same sums: {agree}")


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    main(*args)
