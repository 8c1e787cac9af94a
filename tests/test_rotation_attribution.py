"""Attribution of a rotation gap (benchmarks/rotation_attribution.py): an arm of several PPO seeds is classed by
the mean of its seeds' window means, and its evaluation episodes are pooled over its seeds."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
try:
    import rotation_attribution
finally:
    sys.path.pop(0)


def _run(root: Path, name: str, rotation: float) -> str:
    """A run folder whose progress.csv logs ``rotation`` per training episode from 0 to 2M PPO steps."""
    d = root / name
    d.mkdir()
    rows = ["timesteps,wall_s,episodes,ep_reward_mean,ep_length_mean,rotation_mean"]
    rows += [f"{s},{s / 100},1,0,400,{rotation if s >= 500_000 else 0.0}" for s in range(100_000, 2_000_001, 100_000)]
    (d / "progress.csv").write_text("\n".join(rows) + "\n")
    return str(d)


@pytest.fixture
def results(tmp_path, monkeypatch):
    monkeypatch.setattr(rotation_attribution, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(sys.modules["_common"], "RESULTS", tmp_path / "results")
    return tmp_path


def _refs(root: Path) -> list[str]:
    return ["--canonical", _run(root, "c0", 0.8), _run(root, "c1", 1.0),  # mean 0.90
            "--original", _run(root, "o0", 1.2), _run(root, "o1", 1.2)]   # mean 1.20


def test_an_arm_of_two_seeds_is_classed_by_the_mean_of_their_window_means(results):
    # seed means 1.30 (original-like) and 0.82 (canonical-like): arm mean 1.06, nearer 1.20 than 0.90 by 0.02
    a, b = _run(results, "a0", 1.30), _run(results, "a1", 0.82)
    # seed means 1.10 and 0.88: arm mean 0.99, nearer 0.90 (by 0.09) than 1.20 (by 0.21)
    c, d = _run(results, "b0", 1.10), _run(results, "b1", 0.88)
    assert rotation_attribution.main(_refs(results) + ["--runs", f"arm A={a},{b}", f"arm B={c},{d}",
                                                      "--name", "attr"]) == 0
    out = json.loads((results / "results" / "attr.json").read_text())
    assert out["reference_means"] == pytest.approx({"canonical": 0.9, "original": 1.2})
    arm_a, arm_b = out["attribution"]["arm A"], out["attribution"]["arm B"]
    assert arm_a["mean"] == pytest.approx(1.06) and arm_a["verdict"] == "original-like"
    assert [s["verdict"] for s in arm_a["seeds"]] == ["original-like", "canonical-like"]
    assert arm_b["mean"] == pytest.approx(0.99) and arm_b["verdict"] == "canonical-like"
    assert "| arm A, mean over seeds | | **1.06** | | | original-like |" in (results / "results" / "attr.md").read_text()


def _evals(results: Path, name: str, entries: dict[str, tuple[str, list[float], list[float]]]) -> None:
    runs = {label: {"hand": "h", "urdf": "canonical", "budget": {"steps": 1000, "minutes": 120.0, "seed": 0},
                    "per_episode": {"run": run, "steps_to_fall": stf, "cumulative_rotation": rot}}
            for label, (run, stf, rot) in entries.items()}
    (results / "results").mkdir(exist_ok=True)
    (results / "results" / f"{name}.json").write_text(json.dumps({"episodes": 2, "seed": 1000, "runs": runs}))


def test_evaluations_are_pooled_per_arm_over_its_seeds_matched_by_run_folder(results):
    a, b, c = _run(results, "a0", 1.3), _run(results, "a1", 1.1), _run(results, "b0", 1.0)
    _evals(results, "ev0", {"x": (a, [400, 200], [4.0, 2.0]), "y": (c, [100, 300], [1.0, 1.0])})
    _evals(results, "ev1", {"z": (b, [400, 400], [6.0, 0.0])})
    assert rotation_attribution.main(_refs(results) + ["--runs", f"A={a},{b}", f"B={c}", "--evals", "ev0", "ev1",
                                                      "--name", "attr"]) == 0
    ev = json.loads((results / "results" / "attr.json").read_text())["evaluations"]
    assert ev["A"]["cumulative_rotation"]["n"] == 4 and ev["A"]["cumulative_rotation"]["mean"] == pytest.approx(3.0)
    assert ev["A"]["cumulative_rotation"]["seed_means"] == pytest.approx([3.0, 3.0])
    assert ev["A"]["steps_to_fall"]["mean"] == pytest.approx(350.0)
    assert ev["B"]["cumulative_rotation"]["n"] == 2 and ev["B"]["steps_to_fall"]["mean"] == pytest.approx(200.0)


def test_an_arm_whose_seeds_are_not_all_evaluated_is_refused(results):
    a, b = _run(results, "a0", 1.3), _run(results, "a1", 1.1)
    _evals(results, "ev0", {"x": (a, [400, 200], [4.0, 2.0])})
    with pytest.raises(SystemExit, match="arm 'A' has 2 run"):
        rotation_attribution.main(_refs(results) + ["--runs", f"A={a},{b}", "--evals", "ev0", "--name", "attr"])


def test_table3_states_both_budgets_of_a_run_started_from_another():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import rotation_table3
    finally:
        sys.path.pop(0)
    own = {"steps": 1_688_000, "minutes": 120.2}
    assert rotation_table3._budget_text(own) == "1688k steps, 120 min"
    fine = {"steps": 2_200_000, "minutes": 60.0, "init_from": {"run": "src", "steps": 3_578_340, "minutes": 170.0}}
    assert rotation_table3._budget_text(fine) == "3578k + 2200k steps, 170 + 60 min"
    unknown = {**fine, "init_from": {"run": "src", "steps": None, "minutes": None}}  # a source with no budget file
    assert rotation_table3._budget_text(unknown) == "? + 2200k steps, ? + 60 min"


def test_the_returns_table_splits_an_evaluation_into_its_reward_terms():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import rotation_returns
    finally:
        sys.path.pop(0)
    from ohra.learn.rl.evaluate import EvalResult
    from ohra.sim.rotation.rewards import TERMS

    returns = {t: [0.0, 0.0] for t in TERMS} | {"rotation": [10.0, 20.0], "work": [-100.0, -200.0]}
    res = EvalResult("r", 2, 0, [400, 200], [1.0, 2.0], [None, "fell"], 400, returns)
    text, data = rotation_returns.row("gait", res)
    assert text.startswith("| gait | 1.50 +- 0.50 | 300.0 | -135.0 | +15.0 |") and "| -150.0 |" in text
    assert data["returns"]["total"] == -135.0 and data["summary"]["survived"] == 0.5
