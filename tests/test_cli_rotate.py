"""``ohra rotate ...``: arguments reach the library; bad input is one line on stderr and exit 2."""

from __future__ import annotations

import pytest

pytest.importorskip("gymnasium", reason="ohra rotate needs the rl extra (gymnasium)")

from ohra.cli.rotate import main  # noqa: E402


def test_unknown_config_field_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["grasps", "--set", "frobnicate=1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "frobnicate" in err


def test_eval_of_a_folder_without_a_run_is_one_line_and_exit_2(tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    assert main(["eval", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "config.json" in err


def test_plot_needs_label_equals_runs(tmp_path, capsys):
    assert main(["plot", "nolabel", "-o", str(tmp_path / "x.png")]) == 2
    assert "LABEL=RUN" in capsys.readouterr().err


def test_grasps_command_generates_and_reports_the_cache(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    assert main(["grasps", "--grasps", "3", "--set", "settle_time=1.0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("3 starting states") and str(tmp_path) in out
    assert len(list((tmp_path / "rotation").glob("leap_hand_right_canonical_cube_*.npz"))) == 1


def test_ppo_settings_from_the_command_line_are_checked_and_refused_on_resume(tmp_path, capsys, monkeypatch):
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    import ohra.learn.rl.train as rl_train

    def must_not_train(*args, **kwargs):
        raise AssertionError("bad --ppo settings reached training")

    monkeypatch.setattr(rl_train, "train_rotation", must_not_train)
    out = str(tmp_path / "run")
    assert main(["train", "-o", out, "--ppo", "frobnicate=1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "frobnicate" in err and "kl_target" in err  # names the known settings
    assert main(["train", "-o", out, "--ppo", "kl_target=-0.1"]) == 2
    assert "kl_target" in capsys.readouterr().err
    assert main(["train", "-o", out, "--ppo", "learning_rate=fast"]) == 2
    assert "learning_rate" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_ppo_settings_from_the_command_line_reach_training(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    import ohra.learn.rl.train as rl_train

    seen = {}

    def fake_train(env_cfg, ppo, out, resume=False, verbose=0, tensorboard=False, init_from=None):
        seen.update(ppo=ppo, resume=resume, tensorboard=tensorboard)
        return out

    monkeypatch.setattr(rl_train, "train_rotation", fake_train)
    argv = ["train", "-o", str(tmp_path / "run"), "--steps", "4096", "--ppo", "kl_target=null", "--ppo", "learning_rate=1e-4"]
    assert main(argv) == 0
    ppo = seen["ppo"]
    assert ppo.kl_target is None and ppo.learning_rate == 1e-4
    assert ppo.total_steps == 4096 and ppo.n_epochs == 5  # the rest keeps its flags and defaults
    assert main(argv[:-4]) == 0 and seen["ppo"].kl_target == 0.02 and seen["ppo"].policy == "mlp"
    assert main(argv[:-4] + ["--policy", "lstm"]) == 0 and seen["ppo"].policy == "lstm" and not seen["tensorboard"]
    assert main(argv[:-4] + ["--tensorboard"]) == 0 and seen["tensorboard"]


def test_eval_on_the_other_urdf_refuses_a_policy_of_the_original_joints(capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    from ohra.learn.rl.evaluate import shipped

    run = shipped("rotate_leap_original")  # acts in the original LEAP's 16 own joints
    assert main(["eval", str(run), "--on-urdf", "canonical", "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "canonical joint space" in err and not (run / "eval_on_canonical.json").exists()


def test_ohra_train_rotate_is_ohra_rotate_train(tmp_path, monkeypatch):
    """The issue's spelling, ``ohra train rotate``, beside ``ohra train vae|grasp``: same options, same call."""
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    import ohra.learn.rl.train as rl_train
    from ohra.cli.main import main as ohra_main

    calls = []
    monkeypatch.setattr(rl_train, "train_rotation", lambda env_cfg, ppo, out, resume=False, verbose=0, tensorboard=False, init_from=None:
                        calls.append((env_cfg, ppo, str(out), resume)) or out)
    flags = ["--hand", "shadow_hand_right", "--urdf", "original", "--steps", "4096", "--policy", "lstm", "-o", str(tmp_path / "r")]
    assert ohra_main(["train", "rotate", *flags]) == 0
    assert ohra_main(["rotate", "train", *flags]) == 0
    assert calls[0] == calls[1] and calls[0][0].hand == "shadow_hand_right" and calls[0][1].policy == "lstm"


def test_eval_of_a_shipped_policy_by_name_writes_beside_the_user_not_into_the_package(tmp_path, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    from ohra.learn.rl.evaluate import shipped

    package = shipped("rotate_leap_canonical")
    before = {p.name: p.stat().st_mtime_ns for p in package.iterdir()}
    monkeypatch.chdir(tmp_path)
    assert main(["eval", "leap_canonical", "--episodes", "1"]) == 0
    err = capsys.readouterr().err
    assert (tmp_path / "rotate_leap_canonical" / "eval.json").is_file() and "wrote rotate_leap_canonical/eval.json" in err
    assert {p.name: p.stat().st_mtime_ns for p in package.iterdir()} == before
    assert main(["eval", "rotate_leap_canonical", "--episodes", "1", "-o", "mine"]) == 0
    assert (tmp_path / "mine" / "eval.json").is_file()


def test_eval_of_an_unknown_name_lists_the_shipped_policies(tmp_path, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    monkeypatch.chdir(tmp_path)
    assert main(["eval", "leap_canonicl"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rotate_leap_canonical" in err and "run directory" in err


def test_evaluate_run_refuses_to_write_into_a_shipped_policy():
    pytest.importorskip("stable_baselines3", reason="the rotation policies need the rl extra")
    from ohra.errors import CheckpointError
    from ohra.learn.rl.evaluate import evaluate_run, shipped

    with pytest.raises(CheckpointError, match="shipped policy"):
        evaluate_run(shipped("rotate_shadow_canonical"), episodes=1)


def test_grasps_for_a_mesh_file_object_at_a_given_size(tmp_path, monkeypatch, capsys):
    import trimesh

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    mesh = tmp_path / "my mug.obj"
    trimesh.creation.cylinder(radius=0.04, height=0.1).export(mesh)
    assert main(["grasps", "--object", str(mesh), "--object-size", "0.05", "--grasps", "2", "--set", "settle_time=1.0"]) == 0
    out = capsys.readouterr().out
    assert "+ " + str(mesh) in out and "my-mug" in out
    assert main(["grasps", "--object", "builtin:box", "--object-size", "0.05"]) == 2
    assert "keeps its own size" in capsys.readouterr().err


def _saved_run(tmp_path, **env):
    """A run folder holding only its config.json, as training writes it first."""
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    from ohra.learn.rl.config import PPOSettings
    from ohra.learn.rl.train import _write_config
    from ohra.sim.rotation.config import RotationConfig

    run = tmp_path / "run"
    run.mkdir()
    _write_config(run, RotationConfig(**env), PPOSettings(total_steps=2048))
    return run


def test_resume_refuses_options_that_differ_from_the_run_and_accepts_its_own(tmp_path, capsys, monkeypatch):
    import ohra.learn.rl.train as rl_train

    calls = []
    monkeypatch.setattr(rl_train, "train_rotation", lambda env_cfg, ppo, out, resume=False, verbose=0, tensorboard=False, init_from=None:
                        calls.append((env_cfg, ppo)) or out)
    run = str(_saved_run(tmp_path, hand="shadow_hand_right", joint_damping=True))
    for extra, named in ((["--hand", "allegro_hand_right"], "hand: run 'shadow_hand_right', given 'allegro_hand_right'"),
                         # an option given at its default value is still given (it was read as left out)
                         (["--hand", "leap_hand_right"], "hand: run 'shadow_hand_right', given 'leap_hand_right'"),
                         (["--set", "sim_dt=0.01"], "sim_dt: run 0.0083"), (["--seed", "3"], "seed: run 0, given 3")):
        assert main(["train", "-o", run, "--resume", *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "only --steps, --minutes and --checkpoint-every change on --resume" in err
        assert named in err, err
    for extra, named in ((["--ppo", "kl_target=null"], "kl_target: run 0.02, given None"),
                         (["--policy", "lstm"], "policy: run 'mlp', given 'lstm'"),
                         (["--ppo", "n_epochs=7"], "n_epochs: run 5, given 7")):
        assert main(["train", "-o", run, "--resume", *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err, err
    assert not calls
    # the run's own options repeated (the original command plus --resume) resume it, with the new budget; the
    # checkpoint interval may change (as train_rotation allows)
    assert main(["train", "-o", run, "--resume", "--hand", "shadow_hand_right", "--set", "joint_damping=true",
                 "--policy", "mlp", "--ppo", "n_epochs=5", "--steps", "4096", "--checkpoint-every", "1024"]) == 0
    assert calls[0][0].hand == "shadow_hand_right" and calls[0][1].total_steps == 4096
    assert calls[0][1].checkpoint_every == 1024


@pytest.mark.parametrize("setting, problem", [("sim_dt=abc", "sim_dt must be a finite number, got 'abc'"),
                                              ("self_collision=maybe", "self_collision must be true or false"),
                                              ("episode_steps=1.5", "episode_steps must be a whole number"),
                                              ('grasp_noise="x"', "grasp_noise must be a finite number or None")])
def test_set_values_of_the_wrong_type_are_one_line_and_exit_2(tmp_path, capsys, monkeypatch, setting, problem):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["grasps", "--set", setting]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and problem in err and not (tmp_path / "cache").exists()


def test_eval_of_no_episodes_is_refused_before_anything_is_written(tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    assert main(["eval", "leap_canonical", "--episodes", "0", "-o", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "episodes must be a whole number >= 1, got 0" in err
    assert not (tmp_path / "ev" / "eval.json").exists()


def test_plot_of_a_column_progress_csv_lacks_names_the_columns(tmp_path, capsys):
    run = tmp_path / "r"
    run.mkdir()
    (run / "progress.csv").write_text("timesteps,ep_reward_mean\n100,1.0\n200,2.0\n")
    assert main(["plot", f"a={run}", "-o", str(tmp_path / "p.png"), "--key", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no column 'nope' (columns: timesteps, ep_reward_mean)" in err


def test_plot_takes_shipped_policies_by_name_and_names_a_folder_without_progress_or_a_run_given_twice(tmp_path, capsys):
    png = tmp_path / "p.png"
    assert main(["plot", "canonical=leap_canonical", "original=rotate_leap_original", "-o", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG" and f"wrote {png}" in capsys.readouterr().err
    assert main(["plot", f"a={tmp_path}", "-o", str(png)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{tmp_path} has no progress.csv" in err
    assert main(["plot", "o=leap_original,rotate_leap_original", "-o", str(png)]) == 2  # one run, not two seeds
    assert "names one run twice" in capsys.readouterr().err


@pytest.mark.parametrize("argv, said", [
    (["train", "--envs", "0"], "--envs must be >= 1, got 0"),
    (["train", "--n-steps", "100", "--batch-size", "64"], "--envs x --n-steps = 200 must be a multiple of --batch-size = 64"),
    (["grasps", "--grasps", "0"], "--grasps must be >= 1, got 0"),
    (["train", "--seed", "-1"], "--seed must be a whole number in [0, 2**32), got -1"),  # was a numpy traceback
    (["train", "--set", "episode_steps=0"], "RotationConfig.episode_steps must be >= 1"),  # set by field name: named so
])
def test_setting_errors_name_the_option_the_user_typed(argv, said, tmp_path, capsys):
    """They named the library's fields (``PPOSettings.n_envs``, ``RotationConfig.grasp_count``), not ``--envs``."""
    if argv[0] == "train":
        argv = [*argv, "-o", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err


def test_python_m_ohra_cli_rotate_fails_in_one_line_like_ohra_rotate(tmp_path):
    """It had its own parser and caught only ohra's errors: a missing file or a usage error gave a traceback."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "ohra.cli.rotate", "plot", f"a={tmp_path / 'gone'}", "-o",
                           str(tmp_path / "p.png")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and proc.stderr.startswith("ohra: error:"), proc.stderr
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--hand"])
    assert exit_.value.code == 2


def test_init_from_takes_the_source_runs_settings_and_changes_only_the_options_given(tmp_path, capsys, monkeypatch):
    import ohra.learn.rl.train as rl_train

    calls = []
    monkeypatch.setattr(rl_train, "train_rotation", lambda env_cfg, ppo, out, resume=False, verbose=0, tensorboard=False,
                        init_from=None: calls.append((env_cfg, ppo, init_from)) or out)
    src = str(_saved_run(tmp_path, hand="shadow_hand_right", joint_damping=True, weights={"pose": -0.1}))
    out = str(tmp_path / "fine")
    assert main(["train", "-o", out, "--init-from", src, "--set", 'weights={"fall": -25}', "--minutes", "60"]) == 0
    env_cfg, ppo, init = calls[0]
    assert init == src and env_cfg.hand == "shadow_hand_right" and env_cfg.joint_damping  # the source's settings
    assert (env_cfg.weights.fall, env_cfg.weights.pose) == (-25.0, -0.1)  # only the given term changed
    from ohra.learn.rl.config import PPOSettings

    # the new run's own budget (--steps unset: the default, not the source's 2048); the rest is the source's
    assert ppo.max_minutes == 60.0 and ppo.total_steps == PPOSettings().total_steps and ppo.n_envs == 2
    assert main(["train", "-o", out, "--init-from", src, "--seed", "3"]) == 0 and calls[1][1].seed == 3
    assert main(["train", "-o", out, "--init-from", "leap_canonical"]) == 0  # a shipped policy by name
    assert calls[2][2].endswith("rotate_leap_canonical") and calls[2][0].hand == "leap_hand_right"
    capsys.readouterr()
    assert main(["train", "-o", out, "--resume", "--init-from", src]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--init-from starts a new run" in err and len(calls) == 3


def test_help_defaults_are_the_configs():
    from ohra.cli.rotate import HELP_DEFAULTS
    from ohra.sim.rotation.config import RotationConfig

    assert HELP_DEFAULTS == {k: getattr(RotationConfig(), k) for k in HELP_DEFAULTS}


@pytest.mark.parametrize("weights, problem", [('weights={"fall": NaN}', "must be finite numbers"),
                                              ("weights=null", "are a mapping of term to weight"),
                                              ("weights={fall: -25}", "are a mapping of term to weight")])
def test_reward_weights_that_are_not_a_mapping_of_finite_numbers_are_one_line(tmp_path, capsys, monkeypatch, weights,
                                                                              problem):
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    import ohra.learn.rl.train as rl_train

    monkeypatch.setattr(rl_train, "train_rotation", lambda *a, **k: pytest.fail("bad weights reached training"))
    assert main(["train", "--set", weights, "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and problem in err and not (tmp_path / "r").exists()


def test_steps_zero_is_refused_not_read_as_the_default(tmp_path, capsys, monkeypatch):
    pytest.importorskip("stable_baselines3", reason="ohra rotate train needs stable-baselines3")
    import ohra.learn.rl.train as rl_train

    monkeypatch.setattr(rl_train, "train_rotation", lambda *a, **k: pytest.fail("--steps 0 reached training"))
    assert main(["train", "--steps", "0", "-o", str(tmp_path / "r")]) == 2
    assert "--steps must be >= 1, got 0" in capsys.readouterr().err and not (tmp_path / "r").exists()


def test_outputs_that_are_files_and_runs_without_an_ended_episode_are_one_line(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("")
    assert main(["train", "--hand", "leap_3303", "--steps", "128", "-o", str(afile)]) == 2  # was a traceback
    assert capsys.readouterr().err.count("\n") == 1
    run = tmp_path / "r"
    run.mkdir()
    (run / "progress.csv").write_text("timesteps,ep_reward_mean\n128,\n256,nan\n")  # no episode has ended yet
    assert main(["plot", f"a={run}", "-o", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no value of 'ep_reward_mean' yet (2 rows, all empty" in err
    (run / "progress.csv").write_text("timesteps,ep_reward_mean\n100,1.0\n200,2.0\n")
    assert main(["plot", f"a={run}", "-o", str(afile / "p.png")]) == 2
    assert "is a file" in capsys.readouterr().err
    for groups, named in (([f"a={run},,{run}"], "no empty label or run"), ([f"a={run}", f"a={run}"], "label 'a' is given twice")):
        assert main(["plot", *groups, "-o", str(tmp_path / "p.png")]) == 2
        assert named in capsys.readouterr().err
    assert main(["plot", f"a={run}", "-o", str(tmp_path / "p.png")]) == 0


def test_a_setting_given_twice_or_not_finite_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    for argv, named in ((["--grasps", "5", "--set", "grasp_count=3"], "--set grasp_count=3 and --grasps 5 both set grasp_count"),
                        (["--set", "friction=NaN"], "friction must be a finite number, got nan"),
                        (["--set", "motor_force=Infinity"], "motor_force must be a finite number, got inf")):
        assert main(["grasps", *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err, err
    assert not (tmp_path / "cache").exists()


def test_a_spec_yaml_hand_is_named_by_its_absolute_path_in_the_run(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3", reason="rotation runs need stable-baselines3")
    from ohra.learn.rl.train import _portable_env
    from ohra.sim.rotation.config import RotationConfig

    spec = tmp_path / "specs" / "my_hand.yaml"
    spec.parent.mkdir()
    spec.write_text("name: my_hand\n")  # only its place matters here
    monkeypatch.chdir(spec.parent)
    env, source = _portable_env(tmp_path / "run", RotationConfig(hand="my_hand.yaml"))
    assert env["hand"] == str(spec.resolve()) and source is None  # evaluates from any folder; not copied


def test_eval_of_a_run_stopped_before_its_end_names_its_last_checkpoint(tmp_path, capsys):
    run = _saved_run(tmp_path)
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "last.zip").write_bytes(b"")
    assert main(["eval", str(run), "--episodes", "1", "-o", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no trained policy at" in err and "--checkpoint last" in err


def test_resume_takes_the_params_file_the_run_was_started_with(tmp_path, capsys, monkeypatch):
    """`ohra rotate train --hand hands/mine.json ... --resume`, the command the interruption message asks for, was
    refused: the run names its own copy of the file, so the paths differed. The same hand in the file is the run's."""
    import dataclasses

    import ohra.learn.rl.train as rl_train
    from ohra.hands import get_hand

    calls = []
    monkeypatch.setattr(rl_train, "train_rotation", lambda env_cfg, ppo, out, resume=False, verbose=0, tensorboard=False, init_from=None:
                        calls.append(env_cfg) or out)
    (tmp_path / "hands").mkdir()
    mine = tmp_path / "hands" / "mine.json"
    p = get_hand("leap_3333")
    mine.write_text(p.to_json())
    monkeypatch.chdir(tmp_path)
    run = str(_saved_run(tmp_path, hand="hands/mine.json"))
    assert main(["train", "-o", run, "--resume", "--hand", "hands/mine.json", "--steps", "4096"]) == 0, capsys.readouterr().err
    assert main(["train", "-o", run, "--resume", "--hand", str(mine), "--steps", "4096"]) == 0
    other = tmp_path / "hands" / "other" / "mine.json"
    other.parent.mkdir()
    other.write_text(dataclasses.replace(p, palm_radius=p.palm_radius * 1.1).to_json())
    assert main(["train", "-o", run, "--resume", "--hand", str(other), "--steps", "4096"]) == 2
    assert "hand: run " in capsys.readouterr().err and len(calls) == 2
