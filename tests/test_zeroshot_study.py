"""The zero-shot study script (benchmarks/zeroshot_study.py) end to end on a tiny dataset: every model
trains with its split, every table is filled, Table 9's wrong conditions change the grasps, and the
gallery draws each unseen variant with a model that never saw it. Budget: 2 training steps, 1 grasp
per pair (it checks the plumbing, not grasping)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("torch")

from grasp_fixtures import write_dataset  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]
HANDS = ("leap_3033", "leap_3303", "leap_3330", "leap_3333", "leap_0303")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("zs")
    data = write_dataset(tmp / "data", hands=HANDS, objects=("sphere", "box"), per_pair=4)
    objs = tmp / "eval.yaml"
    objs.write_text("objects:\n  - builtin:cylinder\n")
    results = tmp / "results"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "zeroshot_study.py"), "--data", str(data), "--objects-file", str(objs),
           "--steps", "2", "-n", "2", "--runs", str(tmp / "runs"), "--name", "zs_test", "--quiet"]
    env = {**__import__("os").environ, "OHRA_RESULTS_DIR": str(results)}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return tmp, results, json.loads((results / "zs_test.json").read_text())


def test_every_table_is_filled(study):
    _, _, res = study
    assert set(res["table7"]) == {"leap_3033", "leap_3303", "leap_3330"}
    assert set(res["table8"]) == {"leap_0303"}
    assert set(res["table9"]) == {"leap_3033", "leap_3303", "leap_3330", "leap_3333"}
    for r in res["table7"].values():
        assert r["all"]["n"] == r["zero_shot"]["n"] == 2
        assert len(r["ratio_interval"]) == 2  # nan where a side had no success (2 grasps)
    assert set(res["saliency"]) == {"leap_3333", "leap_3033"}


def test_the_study_states_its_compute(study):
    """Every model and every distinct evaluation is counted once (Table 9's true condition is Table 7's
    evaluation), each with a positive cost, and the markdown states the total."""
    _, results, res = study
    c = res["compute"]
    assert set(c["training"]) == {"all", "zs-leap_3033", "zs-leap_3303", "zs-leap_3330", "only-leap_0303"}
    assert len(c["simulation"]) == 6 + 2 + 6 and all(v > 0 for v in [*c["training"].values(), *c["simulation"].values()])
    assert c["training_core_hours"] == pytest.approx(sum(c["training"].values()) / 3600)
    assert "Compute (core-hours" in (results / "zs_test.md").read_text()


def test_zero_shot_models_never_saw_their_variant(study):
    tmp, _, res = study
    for v in res["table7"]:
        per_hand = json.loads((tmp / "runs" / f"zs-{v}" / "metrics.json").read_text())["data"]["per_hand"]
        assert v not in per_hand and len(per_hand) == 3
    assert res["train_counts"].keys() == {"leap_3033", "leap_3303", "leap_3330", "leap_3333"}  # no low-sum variant


def test_variant_specific_models_saw_their_variant_alone(study):
    """Table 8: ``only-<v>`` trains on ``v``'s grasps and nothing else, and the table states that count."""
    tmp, _, res = study
    for v, row in res["table8"].items():
        per_hand = json.loads((tmp / "runs" / f"only-{v}" / "metrics.json").read_text())["data"]["per_hand"]
        assert list(per_hand) == [v] and row["specific_grasps"] == per_hand[v] > 0


def test_wrong_condition_evaluations_are_kept_apart_from_the_true_one(study):
    tmp, _, _ = study
    true = json.loads((tmp / "runs" / "eval_all_leap_3033.json").read_text())
    wrong = json.loads((tmp / "runs" / "eval_all_leap_3033_as_leap_3333.json").read_text())
    assert true["key"]["condition_hand"] is None and wrong["key"]["condition_hand"] == "leap_3333"


@pytest.mark.slow  # two more study runs (~11 s each); the suite keeps the first
@pytest.mark.parametrize("flag, suffix, touch", [([], "_refined", False), (["touch"], "_touched", True)])
def test_refined_evaluations_are_cached_apart(study, flag, suffix, touch):
    """--refine [open|touch] on the same runs: no retraining, new evaluation files (one per refinement)
    whose keys carry the settings, and the results say which refinement ran."""
    import os

    tmp, results, _ = study
    data, objs = tmp / "data", tmp / "eval.yaml"
    name = "zs" + suffix
    cmd = [sys.executable, str(ROOT / "benchmarks" / "zeroshot_study.py"), "--data", str(data), "--objects-file", str(objs),
           "--steps", "2", "-n", "2", "--runs", str(tmp / "runs"), "--name", name, "--quiet", "--tables", "7", "--refine", *flag]
    before = {p.name: p.stat().st_mtime for p in (tmp / "runs").glob("*/model.pt")}
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OHRA_RESULTS_DIR": str(results)}, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert {p.name: p.stat().st_mtime for p in (tmp / "runs").glob("*/model.pt")} == before
    ref = json.loads((tmp / "runs" / f"eval_all_leap_3303{suffix}.json").read_text())
    assert ref["key"]["refine"]["clearance_m"] == 0.001 and ref["key"]["refine"]["touch"] is touch
    assert json.loads((results / f"{name}.json").read_text())["refine"] == ("touch" if touch else "open")


def test_the_gallery_and_the_saliency_figure_are_written(study):
    _, results, res = study
    assert (results / res["pictures"]["sheet"]).stat().st_size > 5000
    assert (results / "zs_test_saliency.png").stat().st_size > 5000
    assert "Gallery of unseen variants" in (results / "zs_test.md").read_text()


def test_notebook_07_runs_on_the_study(study, tmp_path, monkeypatch):
    """notebooks/07_zero_shot.ipynb reads the study's models and tables (here the tiny study's, through
    its environment variables): the split is shown clean, an untrained variant is sampled by name and by
    params JSON and simulated, the saliency and the study's tables are shown."""
    pytest.importorskip("nbclient")
    from notebook_utils import execute

    tmp, results, _ = study
    monkeypatch.setenv("OHRA_ZS_RUNS", str(tmp / "runs"))
    monkeypatch.setenv("OHRA_RESULTS_DIR", str(results))
    monkeypatch.setenv("OHRA_ZS_NAME", "zs_test")
    nb, texts = execute("07_zero_shot.ipynb", tmp_path, timeout=600)
    assert "condition params, 4 LEAP variants" in texts[0]
    for v in ("leap_3033", "leap_3303", "leap_3330"):
        assert f"{v} among them: False" in texts[0]
    assert "leap_2211 in the training data: False" in texts[1]
    assert "(16, 31) grasps; from the params JSON: same grasps True" in texts[1]
    assert "leap_2211 on cylinder-500:" in texts[2] and "<png>" in texts[2]
    assert texts[3].count("index") == 2 and "<png>" in texts[3]
    assert texts[4].count("ratio") == 3 and "<png>" in texts[4]  # the gallery
    shown = [o["data"].get("text/markdown", "") for o in [c for c in nb.cells if c.cell_type == "code"][4].outputs if "data" in o]
    assert any("Table 9" in m for m in shown)
    assert (tmp_path / "zero_shot_saliency.png").is_file() and (tmp_path / "leap_2211.json").is_file()


def test_train_only_trains_the_named_runs_and_nothing_else(study):
    """Two study processes can share the training (one core each): --train-only trains its runs and
    stops; an unknown run name is one line and exit 2."""
    import os

    tmp, results, _ = study
    runs = tmp / "runs_split"
    base = [sys.executable, str(ROOT / "benchmarks" / "zeroshot_study.py"), "--data", str(tmp / "data"),
            "--steps", "2", "--runs", str(runs), "--quiet"]
    env = {**os.environ, "OHRA_RESULTS_DIR": str(results)}
    r = subprocess.run(base + ["--train-only", "zs-leap_3303", "only-leap_0303"], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert sorted(p.parent.name for p in runs.glob("*/model.pt")) == ["only-leap_0303", "zs-leap_3303"]
    bad = subprocess.run(base + ["--train-only", "zs-leap_3333"], capture_output=True, text=True, env=env, timeout=600)
    assert bad.returncode == 2 and "unknown run(s) ['zs-leap_3333']" in bad.stderr and "Traceback" not in bad.stderr


def test_cli_samples_an_untrained_variant_by_name_and_by_params_json(study, tmp_path, capsys):
    """Issue 14's "any hand, zero-shot" from the shell: a params-conditioned model samples leap_2211 (in no
    dataset) by name and from its params JSON with the same grasps; a hand it cannot read is one line, exit 2."""
    import numpy as np

    from ohra.cli.main import main as cli
    from ohra.hands import get_hand

    tmp, _, _ = study
    model = str(tmp / "runs" / "all")
    get_hand("leap_2211").to_json(tmp_path / "leap_2211.json")
    out = {}
    for key, hand in (("name", "leap_2211"), ("json", str(tmp_path / "leap_2211.json"))):
        f = tmp_path / f"{key}.npz"
        assert cli(["grasp", "sample", "--model", model, "--hand", hand, "--object", "builtin:cylinder", "-n", "4", "-o", str(f)]) == 0
        with np.load(f) as z:
            out[key] = z["grasps"]
    assert out["name"].shape == (4, 31) and np.array_equal(out["name"], out["json"])
    assert cli(["grasp", "sample", "--model", model, "--hand", str(tmp_path / "none.json"), "--object", "builtin:cylinder",
                "-o", str(tmp_path / "x.npz")]) == 2
    assert "none.json" in capsys.readouterr().err


def test_a_partial_study_trains_and_fills_only_its_tables(study):
    """--tables 9: the all-data model and zs-leap_3033 only (no other zero-shot or variant-specific
    model), Table 9 filled, Tables 7 and 8 empty and marked "not computed" in the markdown."""
    import os

    tmp, results, _ = study
    runs = tmp / "runs_partial"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "zeroshot_study.py"), "--data", str(tmp / "data"), "--objects-file",
           str(tmp / "eval.yaml"), "--steps", "2", "-n", "1", "--runs", str(runs), "--name", "zs_partial", "--quiet", "--tables", "9"]
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OHRA_RESULTS_DIR": str(results)}, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert sorted(p.parent.name for p in runs.glob("*/model.pt")) == ["all", "zs-leap_3033"]
    res = json.loads((results / "zs_partial.json").read_text())
    assert res["tables"] == ["9"] and res["table7"] == {} and res["table8"] == {}
    assert set(res["table9"]) == {"leap_3033", "leap_3303", "leap_3330", "leap_3333"}
    assert (results / "zs_partial.md").read_text().count("not computed in this run") == 2
