"""The benchmarks' ``--torch-only`` stand-ins: the grasp-training path imports without the simulation
stack, and any use of a stood-in package fails loudly, naming it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"

SCRIPT = f"""
import sys
sys.path.insert(0, {str(BENCH)!r})
from _torch_only import stand_in_for_missing
print(stand_in_for_missing(force=True))
import ohra.learn.grasp.train, ohra.learn.grasp.data  # the whole training path
import pinocchio
try:
    pinocchio.SE3
except ImportError as exc:
    print("refused:", exc)
"""


def test_the_training_path_imports_with_stand_ins_and_a_stood_in_package_refuses_use():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "['pinocchio', 'coal', 'casadi', 'pybullet', 'pybullet_data']"
    assert lines[1].startswith("refused: pinocchio.SE3: pinocchio is not installed on this machine")


def test_installed_packages_are_left_alone_unless_forced():
    script = f"import sys; sys.path.insert(0, {str(BENCH)!r}); from _torch_only import stand_in_for_missing; " \
             "import numpy; print(stand_in_for_missing(('numpy', 'no_such_package_ohra')))"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "['no_such_package_ohra']", out.stderr
