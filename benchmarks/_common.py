"""Shared helpers for benchmark scripts: single-thread setup, timing, peak memory, result files."""

from __future__ import annotations

import json
import re
import os
import platform
import resource
import time
from pathlib import Path
from typing import Any, Callable

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# OHRA_RESULTS_DIR: write elsewhere (tests run the study scripts without touching the committed results)
RESULTS = Path(os.environ.get("OHRA_RESULTS_DIR") or Path(__file__).resolve().parent / "results")


def run_script(main: Callable[[], Any], script: str) -> None:
    """Run a benchmark script's ``main``; an ohra error (a missing data folder, nothing left to train on) is one
    line on stderr and exit 2, as from the ``ohra`` commands."""
    import sys

    from ohra.errors import OhraError

    try:
        main()
    except OhraError as exc:
        print(f"{Path(script).name}: error: {exc}", file=sys.stderr)
        sys.exit(2)


def natural_sorted(paths: list[str]) -> list[str]:
    """Data folders in natural order (``s2`` before ``s10``) whatever order the shell's glob gave: the
    order of the data folders is part of the studies' run keys."""
    return sorted(paths, key=lambda d: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", str(d))])


def best_of(fn: Callable[[], Any], repeat: int = 3) -> float:
    """Fastest wall time of ``repeat`` runs of ``fn`` [s]."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def peak_rss_mib() -> float:
    """Peak resident memory of this process [MiB]."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def machine() -> dict[str, Any]:
    return {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(), "python": platform.python_version()}


def read_results(names: list[str], script: str) -> dict[str, dict[str, Any]]:
    """``name -> parsed benchmarks/results/NAME.json`` for each name; a missing file ends the script with
    one line naming it (``script``: the reading script, for the message)."""
    out = {}
    for name in names:
        path = RESULTS / f"{name}.json"
        if not path.is_file():
            raise SystemExit(f"{script}: no results {path}")
        out[name] = json.loads(path.read_text())
    return out


def write_results(name: str, data: dict[str, Any], table: str) -> None:
    """Write ``results/<name>.json`` and ``results/<name>.md``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    data = {"machine": machine(), **data}
    (RESULTS / f"{name}.json").write_text(json.dumps(data, indent=2) + "\n")
    (RESULTS / f"{name}.md").write_text(table.rstrip() + "\n")
    print(table)
