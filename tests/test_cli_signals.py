"""A command stopped by SIGTERM (a scheduler, `timeout`, `kill`) or SIGHUP (a closed terminal) ends at once, as before,
but stops the meshcat servers it started first (started in their own session, they were left running)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

_SERVE_AND_WAIT = """
import sys, time, argparse
from ohra.cli.main import execute
from ohra import viz

def command(args):
    vis = viz.new_visualizer()
    print(vis.window.server_proc.pid, flush=True)
    time.sleep(60)

sys.exit(execute(argparse.Namespace(func=command)))
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_terminated_command_stops_its_meshcat_server_and_says_so_in_one_line(sig):
    p = subprocess.Popen([sys.executable, "-c", _SERVE_AND_WAIT], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    server = int(p.stdout.readline())
    assert os.path.exists(f"/proc/{server}")
    p.send_signal(sig)
    p.communicate(timeout=60)
    assert p.returncode == -sig  # ended by the signal, at once
    for _ in range(50):
        if not os.path.exists(f"/proc/{server}"):
            break
        time.sleep(0.1)
    assert not os.path.exists(f"/proc/{server}"), "meshcat's server outlived the command"


@pytest.mark.e2e
def test_a_terminated_evaluation_on_a_worker_pool_ends_without_worker_tracebacks_or_workers_left(tmp_path):
    from ohra.canonical.kinematics import HandModel
    from ohra.hands import get_hand
    from ohra.objects.model import ObjectModel
    from ohra.sim.heuristic import heuristic_grasps

    grasps = tmp_path / "g.npy"
    np.save(grasps, heuristic_grasps(HandModel.from_params(get_hand("barrett_hand")), ObjectModel.builtin("box"), 200, seed=0))
    p = subprocess.Popen([sys.executable, "-m", "ohra.cli", "eval", str(grasps), "--hand", "barrett_hand", "--object",
                          "builtin:box", "--workers", "2", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(8.0)  # imports, then the pool is busy (200 grasps take ~40 s on two workers)
    assert p.poll() is None, "finished before it could be stopped"
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == -signal.SIGTERM and "Traceback" not in err

    def left() -> list[str]:  # forked workers carry the driver's command line
        out = []
        for proc in os.listdir("/proc"):
            try:
                with open(f"/proc/{proc}/cmdline", "rb") as fh:
                    if str(grasps).encode() in fh.read():
                        out.append(proc)
            except OSError:
                continue
        return out

    for _ in range(100):
        if not left():
            break
        time.sleep(0.1)
    assert not left(), "pool workers outlived the evaluation"
