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
    """Run a benchmark script's ``main`` and exit with its return code (None: 0). An ohra error (an unknown hand,
    a missing data folder, nothing left to train on) or a missing file is one line on stderr and exit 2, as from
    the ``ohra`` commands; Ctrl-C is one line and exit 130."""
    import sys

    from ohra.errors import OhraError

    name = Path(script).name
    try:
        code = main()
    except OhraError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError) as exc:
        print(f"{name}: error: {exc.strerror or exc}: {exc.filename}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(int(code or 0))


def script_parser(doc: str, script: str):
    """The command-line parser of a benchmark script: its whole docstring as the help (what it measures, how
    long, what it writes), usage errors in one line (exit 2), and every count option (an ``int`` option whose
    name is not a seed) checked: >= 1, or >= 0 when its default is 0 or None (a negative count gave a
    ZeroDivisionError or a numpy error deep inside the run)."""
    import argparse

    from ohra.cli.main import Parser

    class ScriptParser(Parser):
        def parse_args(self, args=None, namespace=None):  # type: ignore[override]
            ns = super().parse_args(args, namespace)
            for a in self._actions:
                if a.type is not int or "seed" in a.dest:
                    continue
                values = getattr(ns, a.dest, None)
                lowest = 0 if a.default in (0, None) or a.default == [0] else 1
                for v in values if isinstance(values, list) else [values]:
                    if v is not None and v < lowest:
                        self.error(f"argument {'/'.join(a.option_strings) or a.dest}: must be >= {lowest}, got {v}")
            return ns

    return ScriptParser(prog=Path(script).name, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog=f"Results go to {RESULTS} (OHRA_RESULTS_DIR writes them elsewhere). Bad input is one "
                               "line on stderr and exit 2.")


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
