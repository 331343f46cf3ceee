"""A newcomer's first `make demo` (not run in CI): a fresh clone of this repository, then `mocap demo` in it, timed
until the viewer shows a moving skeleton. The clone's numba cache is empty, so every kernel the graph uses is
compiled as on a new machine. By default the clone runs on this checkout's installed environment (the time from
"the install finished"); --install also makes the clone's own .venv first (`make setup`, which needs the package
index) and prints that time apart.

    python benchmarks/first_run.py [--install] [--runs 1]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PORT = 18090


def _state() -> dict | None:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{PORT}/state", timeout=1) as r:
            return json.loads(r.read())
    except (OSError, ValueError):
        return None


def _moving(first: dict | None, now: dict | None) -> bool:
    """Two snapshots of a drawn skeleton at different frames and places."""
    if not first or not now or first.get("frame") == now.get("frame"):
        return False
    a, b = first.get("skeleton", {}).get("positions"), now.get("skeleton", {}).get("positions")
    return bool(a and b and any(p is not None and q is not None and p != q for p, q in zip(a, b)))


def first_demo(clone: Path, python: str, timeout_s: float = 600) -> dict:
    """Start `mocap demo` in the clone; seconds until the viewer serves and until its skeleton moves."""
    env = dict(os.environ, PYTHONPATH=str(clone), PYTHONUNBUFFERED="1")
    env.pop("NUMBA_CACHE_DIR", None)
    log = clone / "demo.log"
    t0 = time.monotonic()
    with open(log, "w") as out:
        proc = subprocess.Popen([python, "-m", "mocap_cli.main", "demo", "--port", str(PORT)], cwd=clone, env=env,
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    times: dict = {}
    first = None
    try:
        while time.monotonic() - t0 < timeout_s and proc.poll() is None:
            time.sleep(0.25)
            now = _state()
            if now is None:
                continue
            times.setdefault("viewer_s", time.monotonic() - t0)
            if first is None or not first.get("skeleton"):
                first = now
            elif _moving(first, now):
                times["moving_s"] = time.monotonic() - t0
                break
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    compiled = re.search(r"compiled and cached in (\d+) s", log.read_text())
    times["compile_s"] = float(compiled.group(1)) if compiled else None
    if "moving_s" not in times:
        sys.exit(f"no moving skeleton within {timeout_s:.0f} s; the demo's log: {log}")
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--install", action="store_true", help="make the clone's own .venv first (needs the index)")
    ap.add_argument("--runs", type=int, default=1, help="fresh clones one after another")
    args = ap.parse_args()
    for run in range(args.runs):
        work = Path(tempfile.mkdtemp(prefix="mocap-first-run-"))
        clone = work / "main"
        subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
        python, install_s = sys.executable, None
        if args.install:
            t = time.monotonic()
            setup = subprocess.run(["make", "-s", "setup"], cwd=clone, capture_output=True, text=True)
            if setup.returncode:
                sys.exit(f"make setup failed in {clone}:\n{setup.stderr[-3000:]}")
            install_s, python = time.monotonic() - t, str(clone / ".venv" / "bin" / "python")
        t = first_demo(clone, python)
        print(f"run {run + 1}: " + (f"install {install_s:.0f} s, then " if install_s is not None else "")
              + f"compile {t['compile_s']:.0f} s, viewer serving at {t['viewer_s']:.0f} s, "
              f"skeleton moving at {t['moving_s']:.0f} s (target 60 s)", flush=True)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
