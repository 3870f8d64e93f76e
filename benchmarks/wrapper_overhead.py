"""Wrapper overhead on the quick case: siloflow (render + run with progress + checks + post)
against LIGGGHTS run directly on the same deck. Prints measured times and ratios (one run each;
this machine is noisy, so read the ratio, not the seconds).

    python benchmarks/wrapper_overhead.py [case.yaml]
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from postprocess.report import post_process as analyse  # noqa: E402
from siloflow.case_file import load_case  # noqa: E402
from siloflow.engine import LiggghtsEngine  # noqa: E402


def main(case_file: Path) -> None:
    case = load_case(case_file)
    engine = LiggghtsEngine()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        folder = engine.prepare(case, tmp / "wrapped")
        t_render = time.perf_counter() - t0

        calls = 0

        def progress(stage, step, total):
            nonlocal calls
            calls += 1

        t0 = time.perf_counter()
        engine.execute(folder, progress=progress)
        t_execute = time.perf_counter() - t0
        t0 = time.perf_counter()
        engine.collect(folder)
        t_collect = time.perf_counter() - t0
        t0 = time.perf_counter()
        analyse(folder)
        t_post = time.perf_counter() - t0

        bare = engine.prepare(case, tmp / "bare")
        cmd = engine.command(case.engine.ranks)
        t0 = time.perf_counter()
        with open(bare / "screen.txt", "wb") as screen:
            subprocess.run(cmd, cwd=bare, stdout=screen, stderr=subprocess.STDOUT, check=True)
        t_bare = time.perf_counter() - t0

    overhead = t_render + (t_execute - t_bare) + t_collect
    print(f"case {case.name}: {calls} progress updates")
    print(f"  LIGGGHTS alone            {t_bare:8.2f} s")
    print(f"  siloflow execute          {t_execute:8.2f} s  (ratio to alone {t_execute / t_bare:.4f})")
    print(f"  render {t_render:.3f} s, collect {t_collect:.3f} s, first results {t_post:.3f} s")
    print(f"  wrapper overhead (render + execute - alone + collect) / engine: {overhead / t_bare:+.2%}")
    print(f"  including first results and figure:                         "
          f"{(overhead + t_post) / t_bare:+.2%}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "decks" / "quick.yaml")
