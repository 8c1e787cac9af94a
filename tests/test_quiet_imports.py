"""Importing ohra's simulation code writes nothing to the terminal.

PyBullet's C extension prints ``pybullet build time: ...`` when it is first imported in a process. Left
alone, that line made a one-line CLI error two lines, and a vectorised PPO run printed it once more per
SubprocVecEnv worker (each worker unpickles ``ohra.learn.rl.train._make_env``, importing that module).
"""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["ohra.sim", "ohra.sim.evaluator", "ohra.sim.rotation", "ohra.hands.check",
                                    "ohra.learn.rl.train"])
def test_importing_a_simulation_module_prints_nothing(module):
    if "rl" in module or "rotation" in module:
        pytest.importorskip("gymnasium")
    proc = subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == "", (proc.stdout, proc.stderr)


def test_the_quiet_import_returns_the_pybullet_module_and_restores_the_descriptors():
    code = ("import os, sys; from ohra.sim.pybullet_import import import_pybullet; pb = import_pybullet(); "
            "print(pb.__name__); print('to stderr', file=sys.stderr); os.write(1, b'fd1\\n')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "pybullet\nfd1\n" and proc.stderr == "to stderr\n"
