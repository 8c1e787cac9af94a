"""The Ray backend gives the same shard bytes as the process pool (a local 2-CPU cluster)."""

from __future__ import annotations

import pytest

from ohra.data.dataset import read_manifest
from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.synth.pipeline import SynthSettings, synthesize
from ohra.synth.robust import RobustnessSettings

ray = pytest.importorskip("ray", reason="the ray extra is not installed (pip install -e '.[ray]')")

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_ray_and_the_process_pool_write_byte_identical_shards(tmp_path):
    hands = [("leap_2200", get_hand("leap_2200"))]
    objs = [ObjectModel.builtin("box"), ObjectModel.procedural("capsule", 1)]
    settings = SynthSettings(grasps_per_object=2, seed=4, robustness=RobustnessSettings(trials=1))
    synthesize(hands, objs, tmp_path / "pool", settings, workers=2, progress=False)
    synthesize(hands, objs, tmp_path / "ray", settings, workers=2, backend="ray", progress=False)
    a, b = (read_manifest(tmp_path / d / "manifest.json")["hands"]["leap_2200"]["shards"] for d in ("pool", "ray"))
    assert {k: s["sha256"] for k, s in a.items()} == {k: s["sha256"] for k, s in b.items()}
    for k, s in a.items():
        assert (tmp_path / "pool" / s["file"]).read_bytes() == (tmp_path / "ray" / b[k]["file"]).read_bytes()
    # resumable on Ray too: nothing to recompute
    again = synthesize(hands, objs, tmp_path / "ray", settings, workers=2, backend="ray", resume=True, progress=False)
    assert {k: s["timing"] for k, s in again["hands"]["leap_2200"]["shards"].items()} == {k: s["timing"] for k, s in b.items()}


def test_ray_evaluation_matches_the_process_pool():
    import numpy as np

    from ohra.sim import GraspEvaluator
    from sim_fixtures import pinch_box, pinch_grasp, pinch_hand

    G = np.array([pinch_grasp(), pinch_grasp(dx=0.03), pinch_grasp(dy=0.02), pinch_grasp(dx=0.004, dy=-0.003)])
    with GraspEvaluator(pinch_hand(), pinch_box()) as ev:
        a = ev.evaluate(G)
        b = ev.evaluate(G, workers=2, backend="ray")
    assert np.array_equal(a.success, b.success) and np.array_equal(a.post_grasps, b.post_grasps)
