"""An interrupted evaluation of one grasp file loses nothing it finished: ``evaluate(resume=PATH)`` and
``ohra eval -o REPORT`` keep finished grasps and a rerun simulates only the rest, ending as an uninterrupted run."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from ohra.sim import GraspEvaluator, Protocol
from ohra.sim import evaluator as evaluator_module
from sim_fixtures import pinch_box, pinch_grasp, pinch_hand

GRASPS = np.array([pinch_grasp(), pinch_grasp(dx=0.03), pinch_grasp(dy=0.02), pinch_grasp(dx=0.004, dy=-0.003),
                   pinch_grasp(dy=-0.006)])


def _count_grasps(monkeypatch, stop_at: int | None = None) -> list[int]:
    """Count simulated grasps (one process); raise KeyboardInterrupt on grasp number ``stop_at``."""
    calls: list[int] = []
    real = evaluator_module.run_grasp

    def counted(world, grasp, mode):
        calls.append(1)
        if stop_at is not None and len(calls) == stop_at:
            raise KeyboardInterrupt
        return real(world, grasp, mode)

    monkeypatch.setattr(evaluator_module, "run_grasp", counted)
    return calls


def _same(a, b) -> None:
    assert [r.to_dict() for r in a.results] == [r.to_dict() for r in b.results]


def test_an_interrupted_evaluation_resumes_and_ends_as_an_uninterrupted_one(tmp_path, monkeypatch):
    full = GraspEvaluator(pinch_hand(), pinch_box()).evaluate(GRASPS)
    assert 0 < full.success.sum() < len(GRASPS)  # both outcomes present: a swapped verdict would show
    path = tmp_path / "partial.npz"
    _count_grasps(monkeypatch, stop_at=4)
    with pytest.raises(KeyboardInterrupt):
        GraspEvaluator(pinch_hand(), pinch_box()).evaluate(GRASPS, resume=path)
    monkeypatch.undo()
    with np.load(path) as z:
        assert z["index"].tolist() == [0, 1, 2]  # the three grasps finished before the interruption
    calls = _count_grasps(monkeypatch)
    again = GraspEvaluator(pinch_hand(), pinch_box()).evaluate(GRASPS, resume=path)
    assert len(calls) == 2 and again.meta["resumed"] == 3
    _same(full, again)
    calls.clear()
    GraspEvaluator(pinch_hand(), pinch_box()).evaluate(GRASPS, resume=path)  # all stored: nothing simulated
    assert len(calls) == 0


@pytest.mark.parametrize("change", ["grasps", "protocol", "object", "mode", "damaged"])
def test_stored_outcomes_are_used_only_for_the_same_inputs(tmp_path, monkeypatch, change):
    path = tmp_path / "partial.npz"
    GraspEvaluator(pinch_hand(), pinch_box()).evaluate(GRASPS[:2], resume=path)
    grasps, obj, protocol, mode = GRASPS[:2].copy(), pinch_box(), Protocol(), "eval"
    if change == "grasps":
        grasps[1, 0] += 1e-6  # a micrometre
    elif change == "protocol":
        protocol = replace(protocol, friction=protocol.friction * 0.99)
    elif change == "object":
        obj = pinch_box(gap=0.0005)
    elif change == "mode":
        mode = "filter"
    else:
        path.write_bytes(path.read_bytes()[:60])
    calls = _count_grasps(monkeypatch)
    rep = GraspEvaluator(pinch_hand(), obj, protocol).evaluate(grasps, mode=mode, resume=path)
    assert len(calls) == 2 and rep.meta["resumed"] == 0


def test_ohra_eval_keeps_finished_grasps_beside_the_report_until_it_is_written(tmp_path, monkeypatch, capsys):
    from ohra.cli import eval as eval_cli
    from ohra.cli.main import main

    hand = tmp_path / "pinch.json"
    pinch_hand().to_json(hand)
    obj = tmp_path / "pinch_box.stl"
    pinch_box().mesh.export(obj)
    grasps = tmp_path / "g.npy"
    np.save(grasps, GRASPS)
    out = tmp_path / "report.json"
    argv = ["eval", str(grasps), "--hand", str(hand), "--object", str(obj), "-o", str(out), "--quiet"]
    assert main(argv[:-3] + ["--quiet"]) == 0
    plain = capsys.readouterr().out
    _count_grasps(monkeypatch, stop_at=3)
    assert main(argv) == 130  # interrupted
    partial = eval_cli.partial_path(out)
    assert not out.exists() and partial == tmp_path / "report.partial.npz" and partial.is_file()
    monkeypatch.undo()
    calls = _count_grasps(monkeypatch)
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert len(calls) == 3 and "2 of 5 grasps came from the interrupted run's" in captured.err
    assert out.is_file() and not partial.exists()
    assert captured.out.split(" succeeded")[0] == plain.split(" succeeded")[0]  # same verdicts as in one go
    assert json.loads(out.read_text())["resumed"] == 2
