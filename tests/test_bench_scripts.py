"""The benchmark scripts' command line: bad input is one line and exit 2 (it was a traceback in 39 of 42), a
misspelt hand writes no results (it replaced committed tables with empty ones), and --help shows what runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e  # python subprocesses (~5 s)

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _run(tmp_path, script, *argv):
    env = {**__import__("os").environ, "OHRA_RESULTS_DIR": str(tmp_path / "results")}
    return subprocess.run([sys.executable, str(BENCH / script), *argv], capture_output=True, text=True, timeout=120,
                          env=env, cwd=tmp_path)


@pytest.mark.parametrize("script, argv, said", [
    ("bench_ceiling.py", ["--grasps", "-1"], "argument --grasps: must be >= 1, got -1"),  # was a ZeroDivisionError
    ("bench_refine.py", ["--repeat", "0"], "argument --repeat: must be >= 1, got 0"),  # was an AttributeError
    ("bench_eval.py", ["--hands", "nosuchhand"], "unknown hand 'nosuchhand'"),  # wrote a results table without it
    ("dataset_table.py", ["--root", "missing"], "No such file or directory"),  # a FileNotFoundError traceback
])
def test_bad_input_is_one_line_exit_2_and_writes_no_results(tmp_path, script, argv, said):
    proc = _run(tmp_path, script, *argv)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("pybullet build time")]
    assert proc.returncode == 2 and len(lines) == 1 and said in lines[0], proc.stderr
    assert lines[0].startswith(f"{script}: error: ")
    assert not (tmp_path / "results").exists()


def test_help_shows_the_whole_docstring_and_where_results_go(tmp_path):
    proc = _run(tmp_path, "bench_eval.py", "--help")
    assert proc.returncode == 0 and "python benchmarks/bench_eval.py [--grasps 24]" in proc.stdout, proc.stdout
    assert "OHRA_RESULTS_DIR writes them elsewhere" in proc.stdout
