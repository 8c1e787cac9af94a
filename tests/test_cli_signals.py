"""A command stopped by SIGTERM (a scheduler, `timeout`, `kill`) or SIGHUP (a closed terminal) stops as Ctrl-C does:
one stderr line, exit 130, and its cleanup runs (meshcat's server, started in its own session, was left running)."""

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
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130 and err == "ohra: interrupted\n"
    for _ in range(50):
        if not os.path.exists(f"/proc/{server}"):
            break
        time.sleep(0.1)
    assert not os.path.exists(f"/proc/{server}"), "meshcat's server outlived the command"


@pytest.mark.e2e
def test_a_terminated_evaluation_on_a_worker_pool_ends_in_one_line_without_worker_tracebacks(tmp_path):
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
    assert p.returncode == 130 and "Traceback" not in err and err.strip().splitlines()[-1] == "ohra: interrupted"
