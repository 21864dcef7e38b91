"""Time the README main job from a clean clone (dependencies already installed).

Clones the committed HEAD into a scratch folder with ``../shared`` linked beside it (as CI
has it), runs the main-job workflow with this environment's snakemake, then runs it again
(which must do nothing). Prints ``RESULT main_job_seconds`` (target < 600 on 2 cores),
``RESULT noop_rerun_seconds`` (target < 10) and the path of ``results/index.html``.

``--worktree`` copies the working tree (tracked and untracked, not ignored files) instead of
cloning HEAD, to time uncommitted changes.

Usage: .venv/bin/python benchmarks/main_job.py [--keep] [--worktree]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", action="store_true", help="keep the scratch clone")
    ap.add_argument("--worktree", action="store_true", help="copy the working tree instead of cloning HEAD")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="uavpipe-mainjob-"))
    clone = work / "main"
    if args.worktree:
        files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, check=True,
                               capture_output=True, text=True).stdout.split("\0")
        for f in filter(None, files):
            src, dst = ROOT / f, clone / f
            if src.is_file():
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, dst)
    else:
        subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    shared = ROOT.parent / "shared"
    if shared.is_dir():
        (work / "shared").symlink_to(shared)
    snakemake = str(Path(sys.executable).parent / "snakemake")
    t0 = time.perf_counter()
    p = subprocess.run([snakemake, "--cores", "2"], cwd=clone, capture_output=True, text=True)
    t_main = time.perf_counter() - t0
    if p.returncode != 0:
        print(p.stderr[-5000:], file=sys.stderr)
        print(f"main job failed with exit {p.returncode}", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    p2 = subprocess.run([snakemake, "--cores", "2"], cwd=clone, capture_output=True, text=True)
    t_noop = time.perf_counter() - t0
    nothing = "Nothing to be done" in (p2.stdout + p2.stderr)
    index = clone / "results" / "index.html"
    n_jobs = (p.stdout + p.stderr).count("Finished job")
    print(f"main job: {t_main:.1f} s ({n_jobs} jobs); no-op rerun: {t_noop:.1f} s "
          f"({'nothing to be done' if nothing else 'JOBS RERAN'})")
    print(f"RESULT main_job_seconds {t_main:.1f}")
    print(f"RESULT noop_rerun_seconds {t_noop:.1f}")
    print(f"RESULT noop_rerun_nothing_to_do {int(nothing)}")
    print(index)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if nothing and index.exists() else 1


if __name__ == "__main__":
    sys.exit(main())
