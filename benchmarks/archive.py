"""Archive re-solve (not run in CI): every take in ../shared/data, each several times (under other names), solved by
`mocap solve --out-dir` in one process (--jobs 1) and in the default pool (one process per core). Prints both
times and the ratio, and checks the two runs wrote the same bytes. Six copies (30 takes) by default: both runs pay
the command's start-up (about 1 s: Python, imports, kernels) once, which with fewer takes is a large share of the
pool's time and little of an archive's.

    python benchmarks/archive.py [--copies 6]
"""
from __future__ import annotations

import argparse
import filecmp
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"


def run(takes: Path, out: Path, *extra: str) -> float:
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(takes), "--out-dir", str(out), *extra],
                   cwd=REPO, check=True, capture_output=True)
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--copies", type=int, default=6)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="mocap-archive-"))
    takes = work / "takes"
    takes.mkdir()
    for f in sorted(DATA.iterdir()):
        if f.suffix.lower() in (".c3d", ".trc", ".mat"):
            for k in range(args.copies):
                (takes / f"{f.stem}_{k}{f.suffix}").symlink_to(f)
    n = len(list(takes.iterdir()))
    serial = run(takes, work / "serial", "--jobs", "1")
    pooled = run(takes, work / "pool")
    same = all(filecmp.cmp(p, work / "pool" / p.name, shallow=False) for p in (work / "serial").iterdir())
    print(f"{n} takes: one process {serial:.1f} s, the pool (one process per core) {pooled:.1f} s: "
          f"{serial / pooled:.2f}x; outputs identical: {same}")


if __name__ == "__main__":
    main()
