"""`mocap solve TAKES... --out-dir DIR`: an archive re-solved, takes in parallel.

Locally the takes go to a pool of processes, one per core (``--jobs``), largest first so the last one to finish is a
small one. With ``--cluster`` they go to a Dask cluster instead: Dask because it is pure Python (a pip install on
every machine, a scheduler that is one process, an address all a user gives), where Ray brings its own object
store and C++ daemons for what is here a map over files. Both are optional: without ``--cluster`` nothing but the
standard library runs them. A take that fails is reported and the others are finished; every take's outputs are
what a serial run writes, byte for byte.
"""
from __future__ import annotations

import argparse
import contextlib
import glob
import logging
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

from tqdm import tqdm

log = logging.getLogger("mocap.solve")
SUFFIXES = (".c3d", ".trc", ".mat", ".mcap")


def expand(items: list[str]) -> list[str]:
    """Files, folders (their recordings) and globs -> the takes, in order, once each."""
    out: list[str] = []
    for item in items:
        if ".mat:" in item or item.startswith("synthetic:"):
            found = [item]
        elif Path(item).is_dir():
            found = sorted(str(p) for p in Path(item).iterdir() if p.suffix.lower() in SUFFIXES)
        elif any(c in item for c in "*?["):
            found = sorted(glob.glob(item))
        else:
            found = [item]
        out += [x for x in found if x not in out]
    if not out:
        raise SystemExit(f"mocap solve: no recordings in {' '.join(items)}")
    return out


def _names(takes: list[str]) -> dict[str, str]:
    """A take -> the stem of its outputs (the parent folder's name added where two stems collide)."""
    stems = {t: Path(t.split(".mat:")[0]).stem + (f"_{t.rsplit(':', 1)[1]}" if ".mat:" in t else "") for t in takes}
    counts: dict[str, int] = {}
    for stem in stems.values():
        counts[stem] = counts.get(stem, 0) + 1
    return {t: (f"{Path(t).parent.name}_{s}" if counts[s] > 1 else s) for t, s in stems.items()}


def _solve_one(options: dict) -> dict:
    """In a worker: one take; its figures, or the error that stopped it."""
    from mocap_cli.solve import solve_take

    logging.getLogger("mocap").setLevel(logging.WARNING)  # the table says it all at the end
    args = argparse.Namespace(**options)
    started = time.perf_counter()
    try:
        figures = solve_take(args)
    except SystemExit as e:
        return {"take": args.file, "error": str(e.code)}
    except Exception as e:  # a take's fault is the take's: the others go on
        return {"take": args.file, "error": f"{type(e).__name__}: {e}"}
    return {"take": args.file, **figures, "seconds": time.perf_counter() - started}


def _size(take: str) -> int:
    try:
        return Path(take.split(".mat:")[0]).stat().st_size
    except OSError:
        return 0


def solve_archive(takes: list[str], args) -> int:
    from mocap_core.warmup import ensure_compiled

    ensure_compiled(log)  # once, here, not in every worker at once
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = _names(takes)
    base = {k: v for k, v in vars(args).items() if k not in ("func", "file", "out_dir", "jobs", "cluster", "bvh")}
    jobs = []
    for take in sorted(takes, key=_size, reverse=True):  # largest first: the pool ends on small takes
        options = {**base, "file": take, "quiet": True, "joints_out": str(out / f"{names[take]}.csv"),
                   "bvh_out": str(out / f"{names[take]}.bvh") if args.bvh else None}
        jobs.append(options)
    started = time.perf_counter()
    if args.cluster:
        results = _on_dask(jobs, args.cluster)
    else:
        results = _on_pool(jobs, args.jobs or os.cpu_count() or 1)
    took = time.perf_counter() - started
    results.sort(key=lambda r: takes.index(r["take"]))
    print(table(results, names, took))
    return 1 if any("error" in r for r in results) else 0


def _on_pool(jobs: list[dict], workers: int) -> list[dict]:
    results = []
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=get_context("fork")) as pool:
        futures = [pool.submit(_solve_one, job) for job in jobs]
        for done in tqdm(as_completed(futures), total=len(futures), unit="take", desc="solving takes"):
            results.append(done.result())
    return results


def _on_dask(jobs: list[dict], address: str) -> list[dict]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed as dask_completed
    except ImportError:
        raise SystemExit("mocap solve --cluster needs Dask: pip install 'dask[distributed]'") from None
    logging.getLogger("distributed").setLevel(logging.WARNING)  # its start-up and shutdown chatter
    results = []
    with contextlib.ExitStack() as stack:
        if address == "local":
            address = stack.enter_context(LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1,
                                                       processes=True, dashboard_address=None,
                                                       silence_logs=logging.WARNING))
        client = stack.enter_context(Client(address))
        futures = client.map(_solve_one, jobs, pure=False)
        for done in tqdm(dask_completed(futures), total=len(futures), unit="take", desc="solving takes"):
            results.append(done.result())
    return results


def table(results: list[dict], names: dict[str, str], took: float) -> str:
    w = max([len("take")] + [len(names[r["take"]]) for r in results])
    lines = [f"{'take':<{w}} {'frames':>7} {'missing %':>9} {'estimated %':>11} {'seconds':>8}  result",
             "-" * (w + 48)]
    frames = 0
    for r in results:
        if "error" in r:
            lines.append(f"{names[r['take']]:<{w}} {'':>7} {'':>9} {'':>11} {'':>8}  failed: {r['error']}")
            continue
        frames += r["frames"]
        lines.append(f"{names[r['take']]:<{w}} {r['frames']:>7} {100 * r['missing']:>9.1f} "
                     f"{100 * r['estimated']:>11.1f} {r['seconds']:>8.1f}  ok")
    failed = sum("error" in r for r in results)
    lines.append(f"{len(results)} takes, {frames} frames in {took:.1f} s" + (f"; {failed} failed" if failed else ""))
    return "\n".join(lines)
