"""Rotation policy training (SB3 PPO): settings, the adaptive learning rate, train -> resume -> evaluate."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ohra.errors import CheckpointError
from ohra.learn.rl.config import PPOSettings, RLConfigError

sb3 = pytest.importorskip("stable_baselines3", reason="rotation training needs the rl extra (stable-baselines3)")
pytest.importorskip("gymnasium", reason="rotation training needs the rl extra (gymnasium)")

from ohra.learn.rl.train import adapt_learning_rate, train_rotation, truncate_progress, with_budget  # noqa: E402
from ohra.sim.rotation.config import RotationConfig  # noqa: E402


def test_ppo_settings_reject_unknown_keys_and_ragged_batches():
    with pytest.raises(RLConfigError, match="gama"):
        PPOSettings.from_dict({"gama": 0.9})
    with pytest.raises(RLConfigError, match="multiple of batch_size"):
        PPOSettings(n_envs=2, n_steps=100, batch_size=64)
    s = PPOSettings()
    assert PPOSettings.from_dict(json.loads(json.dumps(s.to_dict()))) == s
    assert (s.gamma, s.gae_lambda, s.clip_range, s.n_epochs, s.kl_target, s.net_arch) == (0.99, 0.95, 0.2, 5, 0.02, (512, 256, 128))


@pytest.mark.parametrize("kl, expected", [(0.041, 1e-3 / 1.5), (0.039, 1e-3), (0.011, 1e-3), (0.009, 1.5e-3)])
def test_adaptive_learning_rate_on_both_sides_of_each_threshold(kl, expected):
    assert adapt_learning_rate(1e-3, kl, 0.02, (1e-6, 1e-2)) == pytest.approx(expected)


def test_adaptive_learning_rate_stays_within_bounds():
    assert adapt_learning_rate(1e-6, 1.0, 0.02, (1e-6, 1e-2)) == 1e-6
    assert adapt_learning_rate(1e-2, 0.0, 0.02, (1e-6, 1e-2)) == 1e-2


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    env_cfg = RotationConfig(grasp_count=4, episode_steps=24)
    ppo = PPOSettings(total_steps=48, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(32, 32),
                      checkpoint_every=24)
    return env_cfg, ppo, tmp_path / "run"


@pytest.mark.slow  # ~15-50 s: PPO start-up, 4 updates, 2 evaluations, a rendered episode
def test_train_resume_evaluate_and_plot_a_tiny_run(tiny):
    from ohra.learn.rl.evaluate import Policy, evaluate_run, record_episode
    from ohra.learn.rl.plots import read_progress, reward_curves

    env_cfg, ppo, run = tiny
    train_rotation(env_cfg, ppo, run)
    first = read_progress(run)["timesteps"]
    assert first[-1] == 48 and (run / "checkpoints" / "last.zip").is_file()
    with pytest.raises(RLConfigError, match="already holds a run"):
        train_rotation(env_cfg, ppo, run)
    with pytest.raises(RLConfigError, match=r"environment config differs.*friction: run 1\.0, now 2\.0"):
        train_rotation(env_cfg.with_overrides(friction=2.0), with_budget(ppo, 96), run, resume=True)
    # a run made before a setting existed resumes: the missing setting counts at its default
    cfg_file = run / "config.json"
    saved = json.loads(cfg_file.read_text())
    del saved["env"]["inertials"]
    cfg_file.write_text(json.dumps(saved))
    with open(run / "progress.csv", "a") as fh:  # a rollout an interrupted session logged after its checkpoint
        fh.write("60,1.0,1,-1.0,24.0,0.0,0.0003,0.01,0.5,0.1\n")
    train_rotation(env_cfg, with_budget(ppo, total_steps=96), run, resume=True)
    prog = read_progress(run)
    assert list(prog["timesteps"]) == [24, 48, 72, 96]  # appended, continuing the step count
    assert json.loads((run / "checkpoints" / "last.json").read_text())["timesteps"] == 96
    from ohra.learn.rl.train import load_run

    assert load_run(run)[1].total_steps == 96  # the resume's budget is the run's now
    with pytest.warns(UserWarning, match="already at 96 of 96 steps: nothing to train"):
        train_rotation(env_cfg, load_run(run)[1], run, resume=True)
    before = (run / "model.zip").read_bytes()
    with pytest.warns(UserWarning, match="already at 96 of 48 steps: nothing to train"):
        train_rotation(env_cfg, with_budget(ppo, total_steps=48), run, resume=True)
    assert load_run(run)[1].total_steps == 96 and (run / "model.zip").read_bytes() == before  # left as it was

    res = evaluate_run(run, episodes=2, seed=10)
    assert len(res.steps_to_fall) == 2 and all(0 < s <= 24 for s in res.steps_to_fall)
    assert json.loads((run / "eval.json").read_text())["summary"]["steps_to_fall_mean"] == pytest.approx(
        np.mean(res.steps_to_fall))
    again = evaluate_run(run, episodes=2, seed=10, write=False)
    assert again.cumulative_rotation == res.cumulative_rotation  # seeded, deterministic actions

    ep = record_episode(run, run / "episode", seed=10, every=6, size=64)
    assert (run / "episode" / "rollout.gif").stat().st_size > 0 and (run / "episode" / "strip.png").is_file()
    from ohra.sim.rotation.task import resolve

    assert np.load(ep["trajectory"])["q"].shape == (ep["steps"] + 1, len(resolve(env_cfg).hand.joints))
    assert Policy(run)._policy.action_space.shape == (22,)
    png = reward_curves({"a": [run], "b": [run, run]}, run / "curve.png")
    assert png.stat().st_size > 0

    from ohra.learn.rl.evaluate import export_policy

    (run.parent / "export").mkdir()
    (run.parent / "export" / "eval.json").write_text("{}")  # an earlier export's evaluation, of another policy
    (run / "eval.json").unlink()
    small = export_policy(run, run.parent / "export")
    assert not list(small.glob("*.pkl")) and (small / "grasps.npz").is_file()
    assert not (small / "eval.json").exists()  # the stale evaluation is gone, not shipped beside this policy
    assert json.loads((small / "trained.json").read_text())["timesteps"] == 96
    shipped = evaluate_run(small, episodes=2, seed=10, write=False)
    assert shipped.cumulative_rotation == res.cumulative_rotation  # same weights, stats and starting states

    # the canonical-URDF policy on the original URDF, through the action map (its own cached starts)
    moved = evaluate_run(run, episodes=1, seed=10, urdf="original")
    assert (run / "eval_on_original.json").is_file() and 0 < moved.steps_to_fall[0] <= 24
    ep = record_episode(run, run / "episode_on_original", seed=10, every=6, size=64, urdf="original")
    assert np.load(ep["trajectory"])["q"].shape[1] == 16  # the original LEAP's driven joints


def test_a_canonical_space_policy_moves_to_the_other_urdf_through_the_action_map():
    """``on_urdf``: same hand and settings, the other URDF, actions and observations in the canonical
    joint space; an original URDF starts from the canonical holding pose (the pose the policy knows)."""
    from ohra.errors import CheckpointError
    from ohra.learn.rl.evaluate import on_urdf

    canon = RotationConfig(hand="leap_hand_right", friction=0.8, grasp_hold="own")  # as older runs read back
    orig = on_urdf(canon, "original")
    assert (orig.urdf, orig.resolved_space, orig.grasp_hold, orig.friction) == ("original", "canonical", "canonical", 0.8)
    assert on_urdf(canon, None) is canon and on_urdf(canon, "canonical") is canon
    back = on_urdf(orig, "canonical")
    assert (back.urdf, back.resolved_space) == ("canonical", "canonical")
    # an old run's original URDF policy trained in canonical space, started from its own pose
    own = RotationConfig(urdf="original", space="canonical", grasp_hold="own")
    assert on_urdf(own, "canonical").urdf == "canonical"
    native = RotationConfig(urdf="original")  # acts in the original LEAP's 16 own joints
    with pytest.raises(CheckpointError, match="own joints.*space 'native'.*canonical joint space"):
        on_urdf(native, "canonical")


def test_resume_reads_an_older_run_with_current_defaults_and_names_real_differences(tmp_path):
    """A run saved before a setting existed (here ``inertials``) resumes with that setting at its
    default; a changed setting is refused with its name and both values."""
    from ohra.learn.rl.train import _check_resume

    env_cfg, ppo = RotationConfig(hand="leap_hand_right"), PPOSettings()
    saved = {"env": json.loads(json.dumps(env_cfg.to_dict())), "ppo": json.loads(json.dumps(ppo.to_dict()))}
    del saved["env"]["inertials"]
    (tmp_path / "config.json").write_text(json.dumps(saved))
    _check_resume(tmp_path, env_cfg, ppo)
    with pytest.raises(RLConfigError, match=r"inertials: run 'capsule', now 'original'"):
        _check_resume(tmp_path, env_cfg.with_overrides(inertials="original"), ppo)
    with pytest.raises(RLConfigError, match=r"PPO settings \['gamma'\]"):
        _check_resume(tmp_path, env_cfg, PPOSettings(gamma=0.9))


def test_resume_drops_progress_rows_logged_after_the_checkpoint(tmp_path):
    path = tmp_path / "progress.csv"
    rows = ["timesteps,wall_s,episodes,ep_reward_mean,ep_length_mean,rotation_mean,learning_rate,approx_kl,"
            "explained_variance,value_loss"] + [f"{t},{t / 10},1,-1.0,400.0,0.1,0.0003,0.02,0.5,0.1" for t in (2048, 4096, 6144)]
    path.write_text("\n".join(rows) + "\n")
    assert truncate_progress(path, 6144) == 0 and path.read_text().count("\n") == 4  # nothing past it: untouched
    assert truncate_progress(path, 4096) == 1
    lines = path.read_text().splitlines()
    assert lines[0] == rows[0] and [ln.split(",")[0] for ln in lines[1:]] == ["2048", "4096"]
    assert truncate_progress(tmp_path / "absent.csv", 0) == 0


@pytest.mark.e2e  # ~4 s of sb3-contrib training and evaluation (stop 57: out of the default suite)
def test_a_recurrent_policy_trains_resumes_and_carries_its_state_within_an_episode_only(tiny):
    """``policy="lstm"`` (sb3-contrib RecurrentPPO): trains and resumes like the MLP; the evaluated policy
    feeds its LSTM state from step to step and starts every episode blank, so a seeded evaluation repeats
    whatever state the policy was left in; an export reloads as the same recurrent policy."""
    pytest.importorskip("sb3_contrib", reason="the recurrent policy needs sb3-contrib (rl extra)")
    from dataclasses import replace

    from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy

    from ohra.learn.rl.evaluate import Policy, evaluate_policy, export_policy
    from ohra.learn.rl.plots import read_progress

    env_cfg, ppo, run = tiny
    ppo = replace(ppo, policy="lstm", lstm_hidden=16, total_steps=24)
    train_rotation(env_cfg, ppo, run, tensorboard=True)
    train_rotation(env_cfg, with_budget(ppo, total_steps=48), run, resume=True, tensorboard=True)
    assert list(read_progress(run)["timesteps"]) == [24, 48]
    # TensorBoard: one event stream continued by the resume, SB3's scalars and the rotation per episode
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    assert [p.name for p in (run / "tensorboard").iterdir()] == ["ppo_0"]
    steps = {}
    for f in sorted((run / "tensorboard" / "ppo_0").glob("events.*")):
        acc = EventAccumulator(str(f))
        acc.Reload()
        for tag in ("rollout/rotation_mean", "rollout/ep_rew_mean"):
            steps.setdefault(tag, []).extend(e.step for e in acc.Scalars(tag))
    assert steps["rollout/rotation_mean"] == [24, 48] and steps["rollout/ep_rew_mean"] == [24, 48]
    pol = Policy(run)
    assert pol.recurrent and isinstance(pol._policy, RecurrentActorCriticPolicy)
    assert pol._policy.lstm_actor.hidden_size == 16

    env = pol.make_env()
    obs, _ = env.reset(seed=10)
    env.close()
    first, second = pol(obs), pol(obs)
    pol.reset()
    assert not np.allclose(first, second)  # the second call saw the state the first one left
    np.testing.assert_array_equal(pol(obs), first)  # reset: blank again

    blank = evaluate_policy(Policy(run), env_cfg, episodes=2, seed=10)
    for _ in range(5):
        pol(obs)  # a state left over from elsewhere
    again = evaluate_policy(pol, env_cfg, episodes=2, seed=10)
    assert again.cumulative_rotation == blank.cumulative_rotation and again.steps_to_fall == blank.steps_to_fall
    small = Policy(export_policy(run, run.parent / "export"))
    assert small.recurrent and evaluate_policy(small, env_cfg, episodes=2, seed=10).cumulative_rotation == blank.cumulative_rotation


def test_the_recurrent_option_is_a_checked_setting():
    with pytest.raises(RLConfigError, match=r"policy must be one of \('mlp', 'lstm'\), got 'gru'"):
        PPOSettings(policy="gru")
    with pytest.raises(RLConfigError, match="lstm_hidden must be >= 1"):
        PPOSettings(policy="lstm", lstm_hidden=0)
    with pytest.raises(RLConfigError, match="lstm_critic must be true or false, got 'no'"):
        PPOSettings(policy="lstm", lstm_critic="no")
    old = PPOSettings().to_dict()
    del old["policy"], old["lstm_hidden"], old["lstm_critic"]  # a run saved before the option reads back as an MLP run
    assert PPOSettings.from_dict(old).policy == "mlp" and PPOSettings.from_dict(old).lstm_critic


def test_a_recurrent_policy_without_a_critic_lstm_trains_and_reloads_as_such(tiny):
    pytest.importorskip("sb3_contrib", reason="the recurrent policy needs sb3-contrib (rl extra)")
    from dataclasses import replace

    from ohra.learn.rl.evaluate import Policy, export_policy

    env_cfg, ppo, run = tiny
    train_rotation(env_cfg, replace(ppo, policy="lstm", lstm_hidden=8, lstm_critic=False, total_steps=24), run)
    for pol in (Policy(run), Policy(export_policy(run, run.parent / "export"))):
        assert pol._policy.lstm_critic is None and pol._policy.lstm_actor.hidden_size == 8


def test_a_run_started_in_the_folder_meanwhile_is_not_overwritten_and_torch_threads_are_restored(tmp_path, monkeypatch):
    """The "already holds a run" check is repeated under the folder lock: another process may have
    started a run there while this one generated its starting states. torch's thread count is the
    caller's again afterwards, however training ends."""
    import torch

    import ohra.sim.rotation.grasps as grasps

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    run = tmp_path / "run"

    def another_run_starts(*args, **kwargs):  # ... and reaches its first checkpoint
        (run / "checkpoints").mkdir(parents=True, exist_ok=True)
        (run / "config.json").write_text("{}")
        (run / "checkpoints" / "last.zip").write_bytes(b"weights")

    monkeypatch.setattr(grasps, "load_or_generate", another_run_starts)
    before = torch.get_num_threads()
    want = 2 if before != 2 else 1
    torch.set_num_threads(want)
    try:
        with pytest.raises(RLConfigError, match="already holds a run"):
            train_rotation(RotationConfig(grasp_count=2, episode_steps=24),
                           PPOSettings(total_steps=24, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(16, 16),
                                       checkpoint_every=24, threads=3 if want != 3 else 4), run)
        assert torch.get_num_threads() == want
    finally:
        torch.set_num_threads(before)
    assert (run / "config.json").read_text() == "{}"


# -- runs trained without observation normalisation, exports, bad arguments and bad config files -----
@pytest.fixture(scope="module")
def raw_obs_run(tmp_path_factory):
    """A 24-step run trained with ``normalize_obs=False`` (~5 s), its cache folder, and its export."""
    root = tmp_path_factory.mktemp("raw_obs")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("OHRA_CACHE_DIR", str(root / "cache"))
        env_cfg = RotationConfig(grasp_count=2, episode_steps=24)
        ppo = PPOSettings(total_steps=24, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(16, 16),
                          checkpoint_every=24, normalize_obs=False)
        train_rotation(env_cfg, ppo, root / "run")
        from ohra.learn.rl.evaluate import export_policy

        export_policy(root / "run", root / "export")
    return root / "run", root / "cache", root / "export"


@pytest.fixture
def interruptible(raw_obs_run, monkeypatch, terminal_sigint):
    """A three-update run (72 steps of one env) with no periodic checkpoint before its end, on raw_obs_run's cached
    starting states, and Python's own Ctrl-C handler."""
    monkeypatch.setenv("OHRA_CACHE_DIR", str(raw_obs_run[1]))
    return (RotationConfig(grasp_count=2, episode_steps=24),
            PPOSettings(total_steps=72, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(16, 16),
                        checkpoint_every=1000, normalize_obs=False))


def test_ctrl_c_checkpoints_the_last_update_and_the_run_resumes_from_it(interruptible, tmp_path, monkeypatch):
    """Ctrl-C in the second rollout, long before the first periodic checkpoint: the run stops at once (the
    rollout is dropped), saves the weights of its one finished update counted as 24 steps, and resumes."""
    import os
    import signal

    from ohra.sim.rotation.env import InHandRotateEnv

    env_cfg, ppo = interruptible
    calls, real_step = [], InHandRotateEnv.step

    def step(self, action):
        calls.append(1)
        if len(calls) == 30:  # 6 steps into the second rollout
            os.kill(os.getpid(), signal.SIGINT)
        return real_step(self, action)

    monkeypatch.setattr(InHandRotateEnv, "step", step)
    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_rotation(env_cfg, ppo, run)
    assert len(calls) == 30  # stopped at the step the signal came in, not at the end of the run
    assert json.loads((run / "checkpoints" / "last.json").read_text())["timesteps"] == 24
    assert (run / "checkpoints" / "last.zip").is_file() and not (run / "model.zip").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    monkeypatch.setattr(InHandRotateEnv, "step", real_step)
    train_rotation(env_cfg, ppo, run, resume=True)
    assert json.loads((run / "checkpoints" / "last.json").read_text())["timesteps"] == 72
    assert (run / "model.zip").is_file()


def test_ctrl_c_in_the_last_update_keeps_the_finished_run_and_still_stops(interruptible, tmp_path, monkeypatch):
    """The signal came during the last PPO update: the weights hold it, so the run is complete. It was wound back
    one rollout, and the resume ran a 4th update where an uninterrupted run has 3."""
    import os
    import signal

    from stable_baselines3 import PPO

    env_cfg, ppo = interruptible
    updates, real_train = [], PPO.train

    def train(self):
        updates.append(1)
        if len(updates) == 3:
            os.kill(os.getpid(), signal.SIGINT)
        return real_train(self)

    monkeypatch.setattr(PPO, "train", train)
    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_rotation(env_cfg, ppo, run)
    assert json.loads((run / "checkpoints" / "last.json").read_text())["timesteps"] == 72 and (run / "model.zip").is_file()
    train_rotation(env_cfg, ppo, run, resume=True)  # nothing left to train
    assert len(updates) == 3


def test_only_subprocess_env_workers_ignore_ctrl_c(raw_obs_run, monkeypatch, terminal_sigint):
    """The trainer itself may run in a multiprocessing child (a user's Pool): with one in-process env it set
    SIGINT ignored there for good, and Ctrl-C could no longer stop it."""
    import signal

    from ohra.learn.rl.train import _make_env

    _, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    import multiprocessing

    monkeypatch.setattr(multiprocessing, "parent_process", lambda: object())  # as in a Pool worker that trains
    cfg = RotationConfig(grasp_count=2, episode_steps=24).to_dict()
    _make_env(cfg, 0).close()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    _make_env(cfg, 0, worker=True).close()
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_a_run_trained_without_observation_normalisation_exports_and_reads_back_unnormalised(raw_obs_run, tmp_path,
                                                                                             monkeypatch):
    """The export says ``norm_obs=False`` (no pickled None) and its policy acts on raw observations as the
    run's does; a run without any ``vecnormalize.pkl`` exports the same way; an export made before the
    flag (statistics only) still reads its statistics."""
    import shutil

    from ohra.learn.rl.evaluate import Policy, export_policy

    run, cache, export = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    with np.load(export / "obs_stats.npz", allow_pickle=False) as st:
        assert st.files == ["norm_obs"] and not st["norm_obs"]
    mine, theirs = Policy(run), Policy(export)
    assert mine._mean is None and theirs._mean is None
    obs = np.linspace(-3.0, 3.0, mine._policy.observation_space.shape[0])
    assert theirs.normalize(obs) is obs
    np.testing.assert_array_equal(theirs(obs), mine(obs))

    bare = tmp_path / "bare"  # a run with no observation statistics at all
    shutil.copytree(run, bare, ignore=shutil.ignore_patterns("*vecnormalize.pkl"))
    again = tmp_path / "again"
    again.mkdir()
    np.savez(again / "obs_stats.npz", mean=np.zeros(3), var=np.ones(3), clip=5.0, eps=1e-8)  # a stale file: replaced
    export_policy(bare, again)
    assert Policy(again)._mean is None
    np.testing.assert_array_equal(Policy(again)(obs), mine(obs))

    old = tmp_path / "old"  # an export written before norm_obs existed: mean, var, clip, eps
    shutil.copytree(export, old)
    n = obs.shape[0]
    np.savez(old / "obs_stats.npz", mean=np.full(n, 1.0), var=np.full(n, 4.0), clip=2.0, eps=0.0)
    np.testing.assert_allclose(Policy(old).normalize(obs), np.clip((obs - 1.0) / 2.0, -2.0, 2.0))
    (old / "obs_stats.npz").unlink()
    with pytest.raises(CheckpointError, match=r"obs_stats\.npz does not exist"):
        Policy(old)


def test_which_must_be_model_or_last_for_a_run_and_for_an_export(raw_obs_run):
    from ohra.learn.rl.evaluate import Policy

    run, _, export = raw_obs_run
    for folder in (run, export):
        with pytest.raises(CheckpointError, match=r"which must be 'model' or 'last', got 'best'"):
            Policy(folder, which="best")
    assert Policy(export, which="last")._policy is not None  # an export has one policy: either name means it


@pytest.mark.parametrize("kw, name", [({"every": 0}, "every"), ({"every": -2}, "every"), ({"every": 1.5}, "every"),
                                      ({"strip_frames": 0}, "strip_frames")])
def test_record_episode_needs_every_and_strip_frames_of_at_least_one(raw_obs_run, tmp_path, monkeypatch, kw, name):
    from ohra.learn.rl.evaluate import record_episode
    from ohra.sim.rotation.config import RotationConfigError

    run, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    with pytest.raises(RotationConfigError, match=rf"{name} must be an integer >= 1, got {list(kw.values())[0]}"):
        record_episode(run, tmp_path / "episode", seed=10, size=32, **kw)
    assert not (tmp_path / "episode").exists()


@pytest.mark.parametrize("text, problem", [
    ('{"env": {', r"config\.json is not valid JSON"),
    ("[1, 2]", r"config\.json: expected a JSON object with 'env' and 'ppo', got list"),
    ('{"ppo": {}}', r"config\.json: no 'env' settings"),
    ('{"env": {}}', r"config\.json: no 'ppo' settings"),
    ('{"env": {}, "ppo": 3}', r"config\.json: 'ppo' must be a JSON object of settings, got int"),
])
def test_a_malformed_run_config_is_a_checkpoint_error_naming_the_file_on_load_and_on_resume(tmp_path, text, problem):
    from ohra.learn.rl.train import _check_resume, load_run

    (tmp_path / "config.json").write_text(text)
    with pytest.raises(CheckpointError, match=problem):
        load_run(tmp_path)
    with pytest.raises(CheckpointError, match=problem):
        _check_resume(tmp_path, RotationConfig(), PPOSettings())


def test_a_run_stopped_before_its_first_checkpoint_can_be_started_again_not_resumed(tmp_path, monkeypatch):
    """Only its config and a few progress rows exist: nothing trained to lose, so a fresh start may replace them."""
    import ohra.learn.rl.train as rl_train

    run = tmp_path / "run"
    run.mkdir()
    env_cfg, ppo = RotationConfig(), PPOSettings(total_steps=2048)
    rl_train._write_config(run, env_cfg, ppo)
    (run / "progress.csv").write_text("timesteps,wall_s\n1024,3.0\n")
    with pytest.raises(RLConfigError, match="stopped before its first checkpoint: start it again without resume"):
        train_rotation(env_cfg, ppo, run, resume=True)

    class Started(Exception):
        pass

    def started(*args, **kwargs):
        raise Started

    monkeypatch.setattr("ohra.sim.rotation.grasps.load_or_generate", started)
    with pytest.raises(Started):  # past the "already holds a run" check, to the starting states
        train_rotation(env_cfg, ppo, run)
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "last.zip").write_bytes(b"weights")
    with pytest.raises(RLConfigError, match="already holds a run"):
        train_rotation(env_cfg, ppo, run)


def test_a_resume_budget_is_saved_for_the_next_plain_resume(tmp_path):
    import ohra.learn.rl.train as rl_train

    run = tmp_path / "run"
    run.mkdir()
    rl_train._write_config(run, RotationConfig(), PPOSettings(total_steps=2048))
    rl_train._save_budget(run, with_budget(PPOSettings(total_steps=2048), 4096, 90.0))
    _, ppo = rl_train.load_run(run)
    assert ppo.total_steps == 4096 and ppo.max_minutes == 90.0


# -- a new run started from another run's weights (a fine-tune) ------------------------------------------
def test_a_run_started_from_another_gets_its_weights_and_statistics_and_records_where_from(raw_obs_run, tmp_path,
                                                                                           monkeypatch):
    """``init_from``: a new run whose network and observation statistics begin as the source's, not a
    random start; config.json names the source, its budget and the settings that differ; another network
    or a resume are refused by name."""
    import torch

    import ohra.learn.rl.train as rl_train
    from ohra.learn.rl.train import load_run

    src, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    env_cfg, ppo = load_run(src)
    fine = env_cfg.with_overrides(weights={"fall": -25.0})
    captured = {}
    real_load = rl_train._load_init

    def spy(model, venv, zip_path, stats, source):  # the network right after loading, before any update
        real_load(model, venv, zip_path, stats, source)
        captured["start"] = {k: v.clone() for k, v in model.policy.state_dict().items()}

    monkeypatch.setattr(rl_train, "_load_init", spy)
    train_rotation(fine, ppo, tmp_path / "fine", init_from=src)
    theirs = sb3.PPO.load(src / "checkpoints" / "last.zip", device="cpu").policy.state_dict()
    assert captured["start"].keys() == theirs.keys()
    assert all(torch.equal(captured["start"][k], theirs[k]) for k in theirs)
    rec = json.loads((tmp_path / "fine" / "config.json").read_text())["init_from"]
    assert rec["run"] == str(src) and rec["file"] == "checkpoints/last.zip" and rec["timesteps"] == 24
    assert rec["env_changes"] == {"weights": {"source": env_cfg.weights.as_dict(), "now": fine.weights.as_dict()}}
    assert load_run(tmp_path / "fine")[0].weights.fall == -25.0

    with pytest.raises(RLConfigError, match=r"network must be the source run's \(net_arch: source \[16, 16\], now \[32, 32\]\)"):
        train_rotation(fine, PPOSettings(**{**ppo.to_dict(), "net_arch": (32, 32)}), tmp_path / "other", init_from=src)
    with pytest.raises(RLConfigError, match="init_from starts a new run"):
        train_rotation(fine, ppo, tmp_path / "fine", resume=True, init_from=src)
    with pytest.raises(RLConfigError, match="holds no trained policy"):
        train_rotation(fine, ppo, tmp_path / "x", init_from=tmp_path / "nothing")
    assert not (tmp_path / "other").exists() and not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def normalised_run(tmp_path_factory):
    """A 24-step run with observation normalisation (~5 s) and its cache folder."""
    root = tmp_path_factory.mktemp("norm_obs")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("OHRA_CACHE_DIR", str(root / "cache"))
        ppo = PPOSettings(total_steps=24, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(16, 16),
                          checkpoint_every=24)
        train_rotation(RotationConfig(grasp_count=2, episode_steps=24), ppo, root / "run")
    return root / "run", root / "cache"


def test_a_run_started_from_another_begins_with_its_observation_and_return_statistics(normalised_run, tmp_path,
                                                                                       monkeypatch):
    import pickle

    import ohra.learn.rl.train as rl_train
    from ohra.learn.rl.train import load_run

    src, cache = normalised_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    env_cfg, ppo = load_run(src)
    captured = {}
    real_load = rl_train._load_init

    def spy(model, venv, zip_path, stats, source):
        real_load(model, venv, zip_path, stats, source)
        captured.update(mean=venv.obs_rms.mean.copy(), var=venv.obs_rms.var.copy(), ret=venv.ret_rms.var.copy())

    monkeypatch.setattr(rl_train, "_load_init", spy)
    train_rotation(env_cfg, ppo, tmp_path / "fine", init_from=src)
    with open(src / "vecnormalize.pkl", "rb") as fh:
        theirs = pickle.load(fh).__dict__
    assert theirs["obs_rms"].count > 1  # the source saw observations: its statistics are not the initial ones
    np.testing.assert_array_equal(captured["mean"], theirs["obs_rms"].mean)
    np.testing.assert_array_equal(captured["var"], theirs["obs_rms"].var)
    np.testing.assert_array_equal(captured["ret"], theirs["ret_rms"].var)


def test_a_run_started_from_another_of_another_size_is_refused(raw_obs_run, tmp_path, monkeypatch):
    from ohra.learn.rl.train import load_run

    src, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    env_cfg, ppo = load_run(src)
    other = env_cfg.with_overrides(urdf="original")  # the original LEAP acts in its 16 own joints, not 22
    with pytest.raises(RLConfigError, match="do not fit this run's spaces.*size mismatch"):
        train_rotation(other, ppo, tmp_path / "o", init_from=src)
    assert not (tmp_path / "o").exists()  # no half-made run, not even the folder this call made


def test_a_run_started_from_another_takes_its_newest_policy_and_that_policys_budget(raw_obs_run, tmp_path):
    """A run resumed and interrupted keeps an older model.zip beside a newer checkpoint: start from the checkpoint."""
    import shutil

    from ohra.learn.rl.train import init_source

    src, _, _ = raw_obs_run
    copy = tmp_path / "src"
    shutil.copytree(src, copy)
    (copy / "checkpoints" / "last.json").write_text('{"timesteps": 48, "wall_s": 9.0}')  # a newer checkpoint
    zip_path, stats, budget = init_source(copy)
    assert zip_path == copy / "checkpoints" / "last.zip" and budget == {"timesteps": 48, "wall_s": 9.0}
    shutil.rmtree(copy / "checkpoints")
    zip_path, _, budget = init_source(copy)
    assert zip_path == copy / "model.zip" and budget == {"timesteps": None, "wall_s": None}  # unknown, not another's


def test_a_run_started_from_an_exported_policy_gets_its_weights_and_observation_statistics(normalised_run, tmp_path,
                                                                                           monkeypatch):
    """An export (what ``ohra/learn/models/rotate_*`` ship) carries no optimizer or return statistics,
    but its weights and observation statistics start the new run."""
    import torch

    import ohra.learn.rl.train as rl_train
    from ohra.learn.rl.evaluate import Policy, export_policy
    from ohra.learn.rl.train import load_run

    src, cache = normalised_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    export = export_policy(src, tmp_path / "export")
    env_cfg, ppo = load_run(export)
    captured = {}
    real_load = rl_train._load_init

    def spy(model, venv, zip_path, stats, source):
        real_load(model, venv, zip_path, stats, source)
        captured.update(weights={k: v.clone() for k, v in model.policy.state_dict().items()},
                        mean=venv.obs_rms.mean.copy(), var=venv.obs_rms.var.copy(), count=venv.obs_rms.count)

    monkeypatch.setattr(rl_train, "_load_init", spy)
    train_rotation(env_cfg, ppo, tmp_path / "fine", init_from=export)
    theirs = Policy(export)
    want = theirs._policy.state_dict()
    assert all(torch.equal(captured["weights"][k], want[k]) for k in want)
    np.testing.assert_allclose(captured["mean"], theirs._mean)
    np.testing.assert_allclose(captured["var"], theirs._var)
    assert captured["count"] == 24  # the observations the source saw (trained.json), not a fresh start
    rec = json.loads((tmp_path / "fine" / "config.json").read_text())["init_from"]
    assert rec["file"] == "policy.pth" and rec["timesteps"] == 24 and rec["env_changes"] == {}
    # a run started from that fine-tune keeps the chain of budgets
    train_rotation(env_cfg, ppo, tmp_path / "again", init_from=tmp_path / "fine")
    chain = json.loads((tmp_path / "again" / "config.json").read_text())["init_from"]
    assert chain["source_init_from"]["file"] == "policy.pth" and chain["source_init_from"]["timesteps"] == 24


def test_a_run_keeps_its_own_copy_of_a_params_file_hand_and_an_absolute_object_path(tmp_path, monkeypatch):
    """A hand given as a params file is copied into the run and config.json names the copy: evaluating from
    another folder, or after the file changed or vanished, uses the hand the policy was trained on (it used
    the path as typed: 'params file not found' elsewhere, or silently another hand)."""
    import dataclasses

    import trimesh

    from ohra.hands import get_hand
    from ohra.learn.rl.evaluate import Policy, export_policy
    from ohra.learn.rl.train import load_run, read_config

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    p = get_hand("leap_3303")
    (work / "my_leap.json").write_text(json.dumps(p.to_dict()))
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(work / "block.obj")
    env_cfg = RotationConfig(hand="my_leap.json", object="block.obj", grasp_count=2, episode_steps=24)
    ppo = PPOSettings(total_steps=24, n_envs=1, n_steps=24, batch_size=24, n_epochs=1, net_arch=(16, 16),
                      checkpoint_every=24)
    train_rotation(env_cfg, ppo, "run")
    saved = read_config(work / "run")
    assert saved["env"]["hand"] == "my_leap.json" and saved["hand_source"] == str(work / "my_leap.json")
    assert saved["env"]["object"] == str(work / "block.obj")
    trained = (work / "run" / "my_leap.json").read_text()
    assert trained == (work / "my_leap.json").read_text()

    train_rotation(env_cfg, dataclasses.replace(ppo, total_steps=36), "run", resume=True)  # the same file: same hand
    other = dataclasses.replace(p, palm_radius=p.palm_radius * 1.3)  # the user's file changes afterwards
    (work / "my_leap.json").write_text(json.dumps(other.to_dict()))
    monkeypatch.chdir(tmp_path)
    cfg, _ = load_run(work / "run")
    assert cfg.hand == str(work / "run" / "my_leap.json") and get_hand(cfg.hand).palm_radius == p.palm_radius
    assert cfg.resolved_grasp_noise == 0.25  # the copy keeps the file's name, so its LEAP start-pose noise
    with pytest.raises(RLConfigError, match="hand: run"):  # the changed file is another hand
        train_rotation(env_cfg.with_overrides(hand=str(work / "my_leap.json"), object=str(work / "block.obj")), ppo,
                       work / "run", resume=True)
    train_rotation(cfg, dataclasses.replace(ppo, total_steps=72), work / "run", resume=True)  # the run's own
    export_policy(work / "run", tmp_path / "export")
    assert (tmp_path / "export" / "my_leap.json").read_text() == trained
    (work / "run" / "my_leap.json").unlink()
    assert Policy(tmp_path / "export").env_cfg.hand == str(tmp_path / "export" / "my_leap.json")


@pytest.mark.parametrize("damaged", ["model.zip", "vecnormalize.pkl", "checkpoints/last.zip",
                                     "checkpoints/last_vecnormalize.pkl"])
def test_a_damaged_policy_or_statistics_file_is_a_checkpoint_error_naming_it(raw_obs_run, tmp_path, monkeypatch,
                                                                               damaged):
    """Evaluating, resuming or starting from a run whose zip or pickle is damaged names the file (it was a
    zipfile or pickle traceback); the CLI prints it on one line and exits 2."""
    import shutil

    from ohra.cli import main
    from ohra.learn.rl.evaluate import Policy
    from ohra.learn.rl.train import load_run

    run, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    bad = tmp_path / "run"
    shutil.copytree(run, bad)
    if not (bad / "vecnormalize.pkl").exists():  # trained without normalisation: the pickle is optional
        (bad / "vecnormalize.pkl").write_bytes(b"")
        (bad / "checkpoints" / "last_vecnormalize.pkl").write_bytes(b"")
    (bad / damaged).write_bytes(b"not a policy\n")
    name = damaged.rsplit("/", 1)[-1].replace(".", r"\.")
    which = "last" if damaged.startswith("checkpoints") else "model"
    with pytest.raises(CheckpointError, match=rf"{name} is not a readable SB3"):
        Policy(bad, which)
    if which == "last":
        env_cfg, ppo = load_run(bad)
        with pytest.raises(CheckpointError, match=rf"{name} is not a readable SB3"):
            train_rotation(env_cfg, with_budget(ppo, total_steps=48), bad, resume=True)
        assert main(["rotate", "train", "-o", str(bad), "--resume", "--steps", "48"]) == 2
        with pytest.raises(CheckpointError, match=rf"{name}"):  # a new run starts from the last checkpoint
            train_rotation(env_cfg, ppo, tmp_path / "fine", init_from=bad)
        assert not (tmp_path / "fine" / "config.json").exists()
    else:
        assert main(["rotate", "eval", str(bad), "--episodes", "1"]) == 2


class _RecordingVis:
    """A meshcat Visualizer stand-in keeping each path's static transform and what set_animation saw."""

    def __init__(self, path=None, shared=None):
        from meshcat.path import Path as MPath

        self.path = path or MPath(("meshcat",))
        self.shared = shared if shared is not None else {"static": {}, "at_animation": None,
                                                         "window": type("Window", (), {})()}
        self.window = self.shared["window"]

    def __getitem__(self, name):
        return _RecordingVis(self.path.append(name), self.shared)

    def set_object(self, *args, **kw):
        pass

    def set_transform(self, T):
        self.shared["static"][self.path.lower()] = np.array(T)

    def set_animation(self, anim, play=True):
        self.shared["at_animation"] = dict(self.shared["static"])

    def static_html(self) -> str:
        return "<html><body><script>var viewer;</script></body></html>"


def test_a_replay_page_opens_on_the_episodes_first_frame(raw_obs_run, tmp_path, monkeypatch):
    """Every hand link and the object are posed at frame 0 before the animation is attached: the page opened
    with every link piled at the origin and the object in the palm until played."""
    from ohra.learn.rl.evaluate import Policy, record_episode, replay_html

    run, cache, _ = raw_obs_run
    monkeypatch.setenv("OHRA_CACHE_DIR", str(cache))
    ep = record_episode(run, tmp_path / "ep", seed=0, every=100, strip_frames=1, size=64)
    vis = _RecordingVis()
    replay_html(Policy(run).env_cfg, ep["trajectory"], tmp_path / "replay.html", vis=vis)
    static = vis.shared["at_animation"]
    links = {k: T for k, T in static.items() if "/replay/hand/" in k}
    assert links and all(not np.allclose(T, np.eye(4)) for T in links.values())
    traj = dict(np.load(ep["trajectory"]))
    np.testing.assert_allclose(static["/meshcat/replay/object"][:3, 3], traj["obj_pos"][0])
    # the camera frames what the page opens on: every link and the object where frame 0 has them
    from ohra.viz import scene_bounds

    lo, hi = scene_bounds(vis)
    for T in list(links.values()) + [static["/meshcat/replay/object"]]:
        assert np.all(T[:3, 3] >= lo - 1e-9) and np.all(T[:3, 3] <= hi + 1e-9)


def test_a_run_records_the_form_of_the_hand_it_trains_on(tmp_path):
    """config.json said form: null both for a registered hand (trained on its extended form) and for a spec
    path (its base form): two runs with one config trained different hands."""
    from ohra.learn.rl.train import _write_config

    from ohra.hands import get_hand

    base_file = tmp_path / "my_hand.json"
    get_hand("shadow_hand_right", "base").to_json(base_file)
    for k, (hand, form) in enumerate((("leap_hand_right", "extended"), (str(base_file), "base"))):
        run = tmp_path / f"run{k}"
        run.mkdir()
        _write_config(run, RotationConfig(hand=hand), PPOSettings(total_steps=48))
        saved = json.loads((run / "config.json").read_text())
        assert saved["env"]["form"] is None and saved["hand_form"] == form


def test_a_run_is_loaded_and_resumed_in_the_form_it_recorded_not_the_hands_default_now(tmp_path):
    """A run recorded with form null trained the hand's default form then (``hand_form``): evaluating it builds that
    form, and resuming it onto a hand whose default form has since changed is refused, naming both forms."""
    from ohra.learn.rl.train import _check_resume, load_run

    env_cfg, ppo = RotationConfig(hand="shadow_hand_right"), PPOSettings()  # the default now: its extended form
    saved = {"env": json.loads(json.dumps(env_cfg.to_dict())), "ppo": json.loads(json.dumps(ppo.to_dict()))}
    for recorded, loaded in (("base", "base"), ("extended", "extended"), (None, None)):
        d = dict(saved, **({"hand_form": recorded} if recorded else {}))
        (tmp_path / "config.json").write_text(json.dumps(d))
        assert load_run(tmp_path)[0].form == loaded
        if recorded == "base":  # planted: the run trained the base form; null now resolves to extended
            with pytest.raises(RLConfigError, match=r"form: run 'base', now 'extended'"):
                _check_resume(tmp_path, env_cfg, ppo)
            _check_resume(tmp_path, env_cfg.with_overrides(form="base"), ppo)
        else:  # null and the form it stands for are one setting, either way round
            _check_resume(tmp_path, env_cfg, ppo)
            _check_resume(tmp_path, env_cfg.with_overrides(form="extended"), ppo)


def test_every_checkpoint_holds_the_updates_of_all_its_steps(tiny, monkeypatch):
    """Saved on a rollout's last step, before PPO used that rollout, a checkpoint at N steps lacked one update, and a
    resume from it never made that update (a resumed run trailed an uninterrupted one by an update per interruption)."""
    import ohra.learn.rl.train as rl_train

    env_cfg, ppo, run = tiny
    seen, real = [], rl_train.save_checkpoint

    def recording(model, run_dir, wall_s):
        seen.append((int(model.num_timesteps), int(model._n_updates)))
        real(model, run_dir, wall_s)

    monkeypatch.setattr(rl_train, "save_checkpoint", recording)
    train_rotation(env_cfg, ppo, run)
    assert [t for t, _ in seen][:2] == [24, 48]
    for steps, updates in seen:
        assert updates == steps // ppo.n_steps * ppo.n_epochs, seen


def test_a_finished_runs_torn_files_are_mended_on_resume_and_never_evaluated_half(tiny):
    """The final model.zip and vecnormalize.pkl were written in place one after the other: a kill could leave a torn
    policy (which --resume then reported as written) or a policy without its observation statistics (evaluated on raw
    observations without a word). A row torn from progress.csv was kept and merged with the next one."""
    from ohra.learn.rl.evaluate import Policy
    from ohra.learn.rl.plots import read_progress

    env_cfg, ppo, run = tiny
    ppo = with_budget(ppo, total_steps=24)
    train_rotation(env_cfg, ppo, run)
    whole = (run / "model.zip").read_bytes()
    (run / "model.zip").write_bytes(whole[:1000])  # torn
    with pytest.warns(UserWarning, match="nothing to train"):
        train_rotation(env_cfg, ppo, run, resume=True)
    Policy(run)  # whole again, from the checkpoint
    (run / "vecnormalize.pkl").unlink()
    with pytest.raises(CheckpointError, match="vecnormalize.pkl does not exist, and the run normalised its observations"):
        Policy(run)
    with open(run / "progress.csv", "a") as fh:
        fh.write("2")  # a row torn by a kill mid-append
    assert list(read_progress(run)["timesteps"]) == [24]  # the torn row is left out, not a crash
    train_rotation(env_cfg, with_budget(ppo, total_steps=48), run, resume=True)
    assert list(read_progress(run)["timesteps"]) == [24, 48]
    Policy(run)


def test_curves_start_where_every_run_has_data_and_one_seed_twice_is_not_two_seeds(tmp_path):
    """`ohra rotate plot mine=RUN,RUN_RESUMED` said "2 seeds" of one seed, and drew each curve flat from step 0 to
    the first finished episode (np.interp holds the first value)."""
    import json

    from ohra.learn.rl.plots import _runs_label, mean_std_curve

    def run(name: str, seed: int, first: int) -> Path:
        d = tmp_path / name
        d.mkdir()
        (d / "config.json").write_text(json.dumps({"env": {}, "ppo": {"seed": seed}}))
        rows = ["timesteps,ep_reward_mean"] + [f"{t},{'' if t < first else t / 1000}" for t in range(0, 4097, 256)]
        (d / "progress.csv").write_text("\n".join(rows) + "\n")
        return d

    a, b, c = run("a", 0, 512), run("b", 0, 768), run("c", 1, 512)
    grid, mean, _ = mean_std_curve([a, b], window=1)
    assert grid[0] == 768 and grid[-1] == 4096 and mean[0] == pytest.approx(0.768)
    assert _runs_label([a]) == "1 seed" and _runs_label([a, c]) == "2 seeds" and _runs_label([a, b]) == "2 runs, seed 0"
    assert _runs_label([a, b, c]) == "3 runs, seeds 0, 1"
