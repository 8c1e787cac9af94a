"""Robustness trials and replay: stored grasps are exactly the evaluated vectors and pass again."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.data.dataset import GraspDataset
from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.rotations import grasp_to_pose
from ohra.sim import GraspEvaluator
from ohra.synth.pipeline import SynthSettings, synthesize
from ohra.synth.robust import RobustnessSettings, as_stored, perturb


def _grasp() -> np.ndarray:
    hm = HandModel.from_params(get_hand("leap_3303"))
    g = np.zeros(31)
    g[:3] = [0.01, -0.02, 0.03]
    g[3:9] = [1, 0, 0, 0, 1, 0]
    g[9:] = hm.random_configurations(1, seed=1)[0]
    return g, hm


def test_perturbations_have_the_stated_sizes_stay_in_limits_and_are_seeded():
    g, hm = _grasp()
    s = RobustnessSettings(trials=5, translation_m=0.001, rotation_rad=0.01, joints_rad=0.02)
    a = perturb(g, s, np.random.default_rng(7), hm.lower, hm.upper, hm.movable_joints)
    b = perturb(g, s, np.random.default_rng(7), hm.lower, hm.upper, hm.movable_joints)
    assert a.shape == (5, 31) and np.array_equal(a, b)
    assert np.array_equal(a, as_stored(a))  # what the simulator gets is what float32 shards store
    T0, q0 = grasp_to_pose(g)
    T, q = grasp_to_pose(a)
    assert np.allclose(np.linalg.norm(T[:, :3, 3] - T0[:3, 3], axis=1), 0.001, atol=1e-6)
    angle = np.arccos(np.clip((np.einsum("kij,ij->k", T[:, :3, :3], T0[:3, :3]) - 1) / 2, -1, 1))
    assert np.allclose(angle, 0.01, atol=1e-5)
    dq = q - q0
    assert np.all(np.abs(dq) <= 0.02 + 1e-6) and np.all(dq[:, ~hm.movable_joints] == 0)
    assert np.all(q >= hm.lower - 1e-7) and np.all(q <= hm.upper + 1e-7)
    assert np.abs(dq[:, hm.movable_joints]).max() > 0.01


def test_bad_robustness_settings_are_refused():
    from ohra.errors import OhraError

    with pytest.raises(OhraError, match="trials must be >= 0"):  # an ohra error: the CLI gives one line, exit 2
        RobustnessSettings(trials=-1)


@pytest.mark.parametrize("extra, named", [(["--robust-trials", "-1"], "trials must be >= 0"),
                                          (["--seed", "-1"], "seed must be a whole number >= 0")])
def test_bad_synthesis_options_are_one_line_and_exit_2(tmp_path, capsys, extra, named):
    from ohra.cli.synth import main  # what python -m ohra.synth runs

    argv = ["--hand", "leap_2211", "--objects", "procedural:box:7", "--grasps-per-object", "1", "-o", str(tmp_path / "o")]
    assert main(argv + extra) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and named in err and not (tmp_path / "o").exists()


def test_stored_grasps_replay_to_the_same_verdicts(tmp_path):
    """Every stored candidate re-evaluated from the shard gives the stored verdict; kept grasps pass."""
    params = get_hand("leap_3303")
    obj = ObjectModel.builtin("box")
    settings = SynthSettings(grasps_per_object=3, seed=2, robustness=RobustnessSettings(trials=1))
    man = synthesize([("leap_3303", params)], [obj], tmp_path, settings, progress=False)
    assert man["settings"]["robustness"]["trials"] == 1
    shard = GraspDataset(tmp_path).load_shard("leap_3303", "box")
    solved = shard["solver_success"]
    assert solved.any()
    with GraspEvaluator(params, obj, settings.protocol) as ev:
        rep = ev.evaluate(shard["raw"][solved], mode="filter")
    assert np.array_equal(rep.success, shard["sim_success"][solved])
    kept = shard["robust_success"]
    assert np.array_equal(shard["grasps"], shard["raw"][kept]) and np.array_equal(shard["grasps_post"], shard["post"][kept])
    assert np.all(shard["sim_success"][kept]) and np.all(shard["robust_trials"][kept] == 1)
    assert np.array_equal(GraspDataset(tmp_path, which="post").grasps(), shard["grasps_post"])


def test_rounding_to_float32_never_leaves_the_joint_limits():
    lower = np.full(22, -0.1234567891234)
    upper = np.full(22, 0.9876543219876)
    g = np.zeros((2, 31))
    g[:, 3:9] = [1, 0, 0, 0, 1, 0]
    g[0, 9:], g[1, 9:] = upper, lower
    s = as_stored(g, lower, upper)
    assert np.all(s[0, 9:] <= upper) and np.all(s[1, 9:] >= lower)
    assert np.array_equal(s, s.astype(np.float32).astype(np.float64))
    assert np.abs(s[:, 9:] - g[:, 9:]).max() < 1e-7


def test_candidates_too_deep_in_the_body_are_not_simulated(tmp_path):
    """With an impossible penetration limit every converged candidate is pre-filtered: none simulated."""
    obj = ObjectModel.builtin("box")
    hands = [("leap_2200", get_hand("leap_2200"))]
    strict = SynthSettings(grasps_per_object=2, seed=1, max_penetration_m=-1.0)  # demands 1 m of clearance
    synthesize(hands, [obj], tmp_path / "a", strict, progress=False)
    sh = GraspDataset(tmp_path / "a").load_shard("leap_2200", "box")
    assert sh["solver_success"].any()
    assert np.array_equal(sh["prefiltered"], sh["solver_success"]) and not sh["sim_success"].any() and len(sh["grasps"]) == 0
    assert np.all(np.isnan(sh["post"][sh["prefiltered"]]))
    synthesize(hands, [obj], tmp_path / "b", SynthSettings(grasps_per_object=2, seed=1, max_penetration_m=None), progress=False)
    sh = GraspDataset(tmp_path / "b").load_shard("leap_2200", "box")
    assert not sh["prefiltered"].any() and np.all(np.isfinite(sh["post"][sh["solver_success"]]))


def test_the_summary_names_the_trials_that_ran_and_only_this_runs_hands(tmp_path, capsys):
    """With --robust-trials 0 the summary claimed grasps 'also passed the robustness trials'; a second hand
    synthesised into the same folder reprinted the first hand's line as if just made."""
    from ohra.cli.synth import main

    out = tmp_path / "o"
    base = ["--objects", "builtin:box", "--grasps-per-object", "1", "--robust-trials", "0", "-o", str(out), "--quiet"]
    assert main(["--hand", "leap_3303", *base]) == 0
    text = capsys.readouterr().out
    assert "no robustness trials (--robust-trials 0)" in text and "also passed the robustness trials" not in text
    assert main(["--hand", "leap_2220", *base, "--resume"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split(":")[0] for ln in lines if " solves, " in ln] == ["leap_2220"]
    assert lines[-1].endswith("also holds leap_3303 from earlier runs (ohra data info " + str(out) + " sums the folder)")
