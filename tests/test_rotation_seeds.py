"""Table 3 pooled over PPO seeds (benchmarks/rotation_seeds.py): per hand and URDF every seed's episodes
together, and the canonical / original ratio against the within-10 % target."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
try:
    import rotation_seeds
finally:
    sys.path.pop(0)


def _run(urdf: str, seed: int, steps: list[int], rotation: list[float], run: str = "no/such/run") -> dict:
    return {"hand": "h", "urdf": urdf, "budget": {"steps": 1000, "minutes": 1.0, "seed": seed},
            "per_episode": {"steps_to_fall": steps, "cumulative_rotation": rotation, "run": run}}


def _write(results: Path, name: str, runs: dict, episodes: int = 3) -> None:
    (results / f"{name}.json").write_text(json.dumps({"episodes": episodes, "seed": 1000, "runs": runs}))


@pytest.fixture
def results(tmp_path, monkeypatch):
    monkeypatch.setattr(rotation_seeds, "RESULTS", tmp_path)
    monkeypatch.setattr(sys.modules["_common"], "RESULTS", tmp_path)
    return tmp_path


def test_pooled_mean_is_over_all_episodes_and_the_ratio_is_canonical_over_original(results):
    _write(results, "s0", {"c": _run("canonical", 0, [400, 400, 100], [1.0, 2.0, 3.0]),
                           "o": _run("original", 0, [400, 400, 300], [3.0, 3.0, 3.0])})
    _write(results, "s1", {"c": _run("canonical", 1, [400, 400, 400], [1.0, 1.0, 1.0]),
                           "o": _run("original", 1, [400, 400, 400], [2.0, 2.0, 2.0])})
    assert rotation_seeds.main(["s0", "s1", "--name", "out"]) == 0
    out = json.loads((results / "out.json").read_text())
    can = out["groups"]["h/canonical"]["cumulative_rotation"]
    assert can["n"] == 6 and can["mean"] == pytest.approx(1.5)
    assert can["seed_means"] == pytest.approx([2.0, 1.0])
    assert can["se"] == pytest.approx(np.std([1, 2, 3, 1, 1, 1], ddof=1) / np.sqrt(6))
    rot = out["comparisons"]["h"]["cumulative_rotation"]
    assert rot["ratio"] == pytest.approx(1.5 / 2.5) and rot["difference"] == pytest.approx(-1.0)
    assert not rot["within_target"]
    steps = out["comparisons"]["h"]["steps_to_fall"]
    assert steps["ratio"] == pytest.approx(2100 / 2300)


def test_within_target_holds_at_ten_percent_either_way_and_not_past_it(results):
    # canonical rotation 0.9 of original: on the boundary, inside; 0.89: outside; 1.1 ahead: inside
    for can_rot, inside in ((0.9, True), (0.89, False), (1.1, True), (1.11, False)):
        _write(results, "a", {"c": _run("canonical", 0, [400] * 3, [can_rot] * 3),
                              "o": _run("original", 0, [400] * 3, [1.0] * 3)})
        rotation_seeds.main(["a", "--name", "out"])
        verdict = json.loads((results / "out.json").read_text())["comparisons"]["h"]["cumulative_rotation"]
        assert verdict["within_target"] is inside, can_rot


def test_two_runs_with_the_same_ppo_seed_are_refused(results):
    """The same seed twice would be one policy counted twice, not a second seed."""
    _write(results, "a", {"c": _run("canonical", 0, [400] * 3, [1.0] * 3)})
    _write(results, "b", {"c": _run("canonical", 0, [400] * 3, [1.0] * 3)})
    with pytest.raises(SystemExit, match="PPO seed"):
        rotation_seeds.main(["a", "b", "--name", "out"])


def test_results_evaluated_on_different_episodes_are_refused(results):
    _write(results, "a", {"c": _run("canonical", 0, [400] * 3, [1.0] * 3)})
    _write(results, "b", {"c": _run("canonical", 1, [400] * 2, [1.0] * 2)}, episodes=2)
    with pytest.raises(SystemExit, match="different episodes"):
        rotation_seeds.main(["a", "b", "--name", "out"])


def test_curves_are_drawn_over_the_seeds_when_the_runs_are_present(results):
    runs = []
    for k in range(2):
        d = results / f"run{k}"
        d.mkdir()
        rows = "\n".join(f"{t},{t / 100},{-10 + t / 1000 + k},{t / 10000 + k}" for t in range(0, 4000, 500))
        (d / "progress.csv").write_text("timesteps,wall_s,ep_reward_mean,rotation_mean\n" + rows + "\n")
        runs.append(str(d))
    _write(results, "a", {"c": _run("canonical", 0, [400] * 3, [1.0] * 3, runs[0])})
    _write(results, "b", {"c": _run("canonical", 1, [400] * 3, [1.0] * 3, runs[1])})
    assert rotation_seeds.main(["a", "b", "--name", "out"]) == 0
    out = json.loads((results / "out.json").read_text())
    assert out["curves"] == ["out_curves.png", "out_curves_rotation.png"]
    assert (results / "out_curves_rotation.png").read_bytes()[:4] == b"\x89PNG"
    _write(results, "b", {"c": _run("canonical", 1, [400] * 3, [1.0] * 3)})  # a run folder missing: no curves
    assert rotation_seeds.main(["a", "b", "--name", "out2"]) == 0
    assert json.loads((results / "out2.json").read_text())["curves"] == []


def test_per_step_rotation_is_read_over_the_same_steps_for_every_run(results):
    """Run 0 reached 3,500 steps, run 1 only 2,000: both are read over the window before 2,000."""
    dirs = []
    for k, (end, level) in enumerate(((3500, 1.0), (2000, 3.0))):
        d = results / f"r{k}"
        d.mkdir()
        # rotation rises with the steps: a window at each run's own end would read run 0 higher
        rows = "\n".join(f"{t},{t / 100},-1,{level + t / 1000}" for t in range(500, end + 1, 500))
        (d / "progress.csv").write_text("timesteps,wall_s,ep_reward_mean,rotation_mean\n" + rows + "\n")
        dirs.append(str(d))
    _write(results, "a", {"c": _run("canonical", 0, [400] * 3, [1.0] * 3, dirs[0]),
                          "o": _run("original", 0, [400] * 3, [1.0] * 3, dirs[1])})
    monkey_window = rotation_seeds.WINDOW
    rotation_seeds.WINDOW = 1000
    try:
        assert rotation_seeds.main(["a", "--name", "out"]) == 0
    finally:
        rotation_seeds.WINDOW = monkey_window
    e = json.loads((results / "out.json").read_text())["matched_steps"]["h"]
    assert e["steps"] == [1000, 2000]
    assert e["canonical"]["per_seed"] == [2.75] and e["original"]["per_seed"] == [4.75]
