"""The in-hand rotation environment: Gymnasium contract, determinism, termination, reward sign, joint spaces."""

from __future__ import annotations

import sys
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

gym = pytest.importorskip("gymnasium", reason="the rotation env needs the rl extra (gymnasium)")

import ohra.sim.rotation as R  # noqa: E402
from ohra.sim.rotation.config import RotationConfig, RotationConfigError  # noqa: E402
from ohra.sim.rotation.env import InHandRotateEnv  # noqa: E402
from ohra.sim.rotation.grasps import generate  # noqa: E402
from ohra.sim.rotation.task import resolve  # noqa: E402

CFG = RotationConfig(grasp_count=6)  # LEAP, canonical, cube: a handful of starting states is enough here


@pytest.fixture(scope="module")
def grasps():
    return generate(resolve(CFG))


@pytest.fixture
def env(grasps):
    e = InHandRotateEnv(CFG, grasps=grasps)
    yield e
    e.close()


def _rollout(env: InHandRotateEnv, seed: int, steps: int = 30) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(7)
    out = [obs]
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape))
        out.append(obs)
    return np.array(out)


def test_env_passes_gymnasium_env_checker_without_warnings(grasps):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(R.ENV_ID, config=CFG, grasps=grasps)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []
    env.close()


def test_make_takes_the_hand_by_name_as_the_readme_spells_it(grasps):
    """``gymnasium.make(ENV_ID, hand=NAME, urdf=...)``: ``hand`` is the config's hand name (a SimHand
    to simulate instead goes to ``sim_hand``)."""
    env = gym.make(R.ENV_ID, hand="leap_hand_right", urdf="canonical", grasp_count=CFG.grasp_count, grasps=grasps)
    try:
        assert env.unwrapped.cfg == CFG and env.unwrapped.task.hand.canonical
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
    finally:
        env.close()


def test_same_seed_same_trajectory_and_other_seeds_differ(grasps):
    a, b = InHandRotateEnv(CFG, grasps=grasps), InHandRotateEnv(CFG, grasps=grasps)
    try:
        ta = _rollout(a, seed=3)
        assert np.array_equal(ta, _rollout(b, seed=3))
        _rollout(a, seed=5)  # whatever ran before, a reset with seed 3 replays the same trajectory
        assert np.array_equal(ta, _rollout(a, seed=3))
        starts = {int(a.reset(seed=s)[1]["grasp"]) for s in range(12)}
        assert len(starts) > 1
    finally:
        a.close()
        b.close()


@pytest.mark.parametrize("seed", [2, 3])
def test_the_first_episode_after_construction_replays_exactly_later(grasps, seed):
    """An episode's outcome depends on its seed, not on its place in an evaluation: the first episode of a fresh
    env drifted ~1e-10 from the same seed and actions replayed later (seed 2 here from step 17 on; chaos then
    grew it), until the env stepped PyBullet once at construction."""
    def rollout(env, s):
        obs, _ = env.reset(seed=s)
        rng, out = np.random.default_rng(s), [obs]
        for _ in range(80):
            obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
            out.append(obs)
        return np.array(out)

    env = InHandRotateEnv(CFG, grasps=grasps)
    try:
        first = rollout(env, seed)
        rollout(env, seed + 1)
        assert np.array_equal(first, rollout(env, seed))
    finally:
        env.close()


def test_observation_layout_matches_the_space(env):
    obs, _ = env.reset(seed=0)
    assert sum(env.observation_structure.values()) == obs.shape[0] == 3 * env.space.dim + 14
    assert env.observation_space.contains(obs)


def _move_object(env: InHandRotateEnv, offset, angvel=(0.0, 0.0, 0.0)) -> None:
    c, b = env.scene.client, env.scene.obj_body
    pos, orn = pb.getBasePositionAndOrientation(b, physicsClientId=c)
    pb.resetBasePositionAndOrientation(b, (np.asarray(pos) + offset).tolist(), orn, physicsClientId=c)
    pb.resetBaseVelocity(b, [0, 0, 0], list(angvel), physicsClientId=c)


def test_episode_terminates_when_the_object_is_dropped_below_the_hand(env):
    env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert not terminated and info["termination"] is None
    _move_object(env, (0.0, 0.0, -2 * CFG.fall_height))
    _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert terminated and not truncated and info["termination"] == "fell"


def test_episode_terminates_when_the_object_leaves_the_hand_sideways(env):
    env.reset(seed=0)
    _move_object(env, (0.0, 0.3, 0.1))
    _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape))
    assert terminated and info["termination"] == "left"


@pytest.mark.parametrize("shift, why", [((0.0, 0.0, -2 * CFG.fall_height), "fell"), ((0.0, 0.3, 0.1), "left")])
def test_fall_weight_is_paid_once_on_the_step_the_object_is_lost(grasps, shift, why):
    """``weights.fall`` (default 0: the paper's reward) adds its weight on the terminating step only."""
    cfg = CFG.with_overrides(weights={"fall": -25.0})
    twice = CFG.with_overrides(weights={"pose": -0.1}).with_overrides(weights={"fall": -1.0})
    assert (twice.weights.pose, twice.weights.fall) == (-0.1, -1.0)  # an override changes only the terms it names
    rewards = {}
    for name, c in (("off", CFG), ("on", cfg)):
        env = InHandRotateEnv(c, grasps=grasps)
        try:
            env.reset(seed=0)
            held = env.step(np.zeros(env.action_space.shape))
            _move_object(env, shift)
            lost = env.step(np.zeros(env.action_space.shape))
        finally:
            env.close()
        rewards[name] = (held, lost)
    (held_off, lost_off), (held_on, lost_on) = rewards["off"], rewards["on"]
    assert held_on[1] == held_off[1] and held_on[4]["reward/fall"] == 0.0  # held: nothing paid
    assert lost_on[2] and lost_on[4]["termination"] == why and lost_on[4]["reward/fall"] == 1.0
    assert lost_on[1] == pytest.approx(lost_off[1] - 25.0, abs=1e-9)


def test_zero_actions_hold_a_starting_grasp_until_truncation(grasps):
    env = InHandRotateEnv(CFG.with_overrides(episode_steps=40), grasps=grasps)
    try:
        env.reset(seed=1)
        for _ in range(40):
            _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
            if terminated or truncated:
                break
        assert truncated and not terminated and info["steps"] == 40
    finally:
        env.close()


@pytest.mark.parametrize("spin, sign", [(+2.0, +1.0), (-2.0, -1.0)])
def test_rotation_reward_is_positive_for_turns_about_plus_z_only(grasps, spin, sign):
    """A free object spun about +z earns +clip; spun about -z, -clip (gravity off, lifted off the hand)."""
    env = InHandRotateEnv(CFG.with_overrides(gravity=0.0), grasps=grasps)
    try:
        env.reset(seed=0)
        _move_object(env, (0.0, 0.0, 0.075), angvel=(0.0, 0.0, spin))  # clear of every finger, within 8 cm
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
        assert np.sign(info["delta_yaw"]) == sign
        assert info["reward/rotation"] == pytest.approx(sign * CFG.angvel_clip)
        assert info["cumulative_rotation"] == pytest.approx(info["delta_yaw"])
    finally:
        env.close()


def test_canonical_and_original_action_spaces(hands_dir):
    leap_c = resolve(RotationConfig(urdf="canonical"))
    leap_o = resolve(RotationConfig(urdf="original"))
    leap_oc = resolve(RotationConfig(urdf="original", space="canonical"))
    shadow_o = resolve(RotationConfig(hand="shadow_hand_right", urdf="original"))
    assert (leap_c.space.dim, leap_o.space.dim, leap_oc.space.dim, shadow_o.space.dim) == (22, 16, 22, 22)
    assert leap_o.space.names == leap_o.hand.joints and leap_c.space.names[0] == "thumb_joint1"
    # the canonical space drives the original URDF through its action map
    x = np.clip(np.linspace(-1, 1, 22), leap_oc.space.lower, leap_oc.space.upper)
    assert np.allclose(leap_oc.space.to_sim(x), np.clip(leap_oc.hand.to_sim(x), leap_oc.hand.lower, leap_oc.hand.upper))
    m = leap_oc.space.movable
    assert np.allclose(leap_oc.space.from_sim(leap_oc.space.to_sim(x))[m], x[m])


def test_the_original_urdf_of_a_hand_given_by_its_spec_file(hands_dir, tmp_path):
    """urdf='original' refused a spec path even with its folder registered ("needs a registered hand"), so a run
    trained from a spec could never be evaluated on its original URDF; a params JSON without its spec says why."""
    from ohra.errors import HandNotFoundError
    from ohra.hands import get_hand
    from ohra.hands.registry import spec_path

    by_spec = resolve(RotationConfig(hand=str(spec_path("shadow_hand_right")), urdf="original", form="extended"))
    by_name = resolve(RotationConfig(hand="shadow_hand_right", urdf="original", form="extended"))
    assert not by_spec.hand.canonical and by_spec.hand.joints == by_name.hand.joints and by_spec.hand.urdf == by_name.hand.urdf
    lone = tmp_path / "lone.json"
    get_hand("shadow_hand_right", "extended").to_json(lone)
    with pytest.raises(HandNotFoundError, match=r"urdf='original' needs the original hand, which is unknown"):
        resolve(RotationConfig(hand=str(lone), urdf="original"))


def test_canonical_space_ignores_actions_of_absent_joints(env):
    env.reset(seed=0)
    dead = ~env.space.movable
    assert dead.sum() == 6  # LEAP: ring finger, thumb_joint3, little_joint0
    before = env._target.copy()
    a = np.zeros(env.action_space.shape)
    a[dead] = 1.0
    env.step(a)
    assert np.array_equal(env._target, before)


def test_unknown_setting_is_rejected_by_name():
    with pytest.raises(RotationConfigError, match="frobnicate"):
        RotationConfig.from_dict({"frobnicate": 1})
    with pytest.raises(RotationConfigError, match="whole number"):
        RotationConfig(sim_dt=0.007)
    with pytest.raises(RotationConfigError, match="canonical URDF"):
        RotationConfig(urdf="canonical", space="native")


def test_canonical_hand_can_carry_the_original_finger_masses(hands_dir):
    """inertials='original': same canonical geometry and joints, the original URDF's finger masses."""
    light = resolve(RotationConfig(urdf="canonical"))
    heavy = resolve(RotationConfig(urdf="canonical", inertials="original"))
    orig = resolve(RotationConfig(urdf="original"))
    np.testing.assert_allclose(heavy.hand.finger_masses, orig.hand.finger_masses, rtol=1e-12)
    assert np.all(light.hand.finger_masses[heavy.hand.finger_masses > 0] < heavy.hand.finger_masses[heavy.hand.finger_masses > 0])
    assert heavy.hand.joints == light.hand.joints and heavy.space.names == light.space.names
    with pytest.raises(RotationConfigError, match="inertials"):
        RotationConfig(urdf="original", inertials="original")
    with pytest.raises(RotationConfigError, match="inertials"):
        RotationConfig(inertials="steel")


def test_evaluation_splits_each_episode_return_into_its_weighted_reward_terms(grasps):
    from ohra.learn.rl.evaluate import evaluate_policy
    from ohra.sim.rotation.rewards import TERMS

    cfg = CFG.with_overrides(episode_steps=25)

    def policy(obs):  # deterministic in the observation, so a second rollout repeats it
        return np.sin(3.0 * obs[:22])

    res = evaluate_policy(policy, cfg, episodes=2, seed=4, grasps=grasps)
    env = InHandRotateEnv(cfg, grasps=grasps)
    totals = []
    try:
        for i in range(2):
            obs, _ = env.reset(seed=4 + i)
            total = 0.0
            while True:
                obs, r, term, trunc, _ = env.step(policy(obs))
                total += r
                if term or trunc:
                    break
            totals.append(total)
            assert sum(res.returns[k][i] for k in TERMS) == pytest.approx(total, abs=1e-9)
    finally:
        env.close()
    summary = res.return_summary()
    assert set(summary) == set(TERMS) | {"total"}
    assert summary["total"] == pytest.approx(np.mean(totals), abs=1e-9)
    assert all(summary[k] <= 0.0 for k in TERMS if k != "rotation")  # penalties only subtract
    assert summary["pose"] < 0.0  # the policy moves the joints away from the start pose


def test_urdf_joint_damping_is_dropped_unless_asked_for(hands_dir):
    """PyBullet applies URDF damping explicitly, which made the original Shadow's light links chatter."""
    from ohra.sim.rotation.scene import RotationScene

    def speed_after_a_free_step(cfg, joint="FFJ1"):
        """Speed of a fingertip joint one sub-step after it starts at 1 rad/s (motors off, no gravity)."""
        task = resolve(cfg)
        scene = RotationScene(task.hand, task.obj, cfg, task.palm_radius)
        c, b, h = scene.client, scene.body, task.hand
        try:
            pb.setGravity(0, 0, 0, physicsClientId=c)
            pb.setJointMotorControlArray(b, scene.jidx, pb.VELOCITY_CONTROL, forces=[0.0] * len(scene.jidx),
                                         physicsClientId=c)
            for k, j in enumerate(scene.jidx):
                pb.resetJointState(b, j, 0.5 * (h.lower[k] + h.upper[k]), float(h.joints[k] == joint), physicsClientId=c)
            pb.stepSimulation(physicsClientId=c)
            return pb.getJointState(b, scene.jidx[h.joints.index(joint)], physicsClientId=c)[1]
        finally:
            scene.close()

    shadow = RotationConfig(hand="shadow_hand_right", urdf="original", self_collision=False)
    assert abs(speed_after_a_free_step(shadow.with_overrides(joint_damping=True))) > 10.0  # explicit damping overshoots
    assert speed_after_a_free_step(shadow) == pytest.approx(1.0, abs=0.2)  # no damping: it keeps turning


def test_work_penalty_uses_the_joint_motion_over_the_control_step(env):
    env.reset(seed=1)
    before = env.scene.read()
    a = np.zeros(env.action_space.shape)
    a[env.space.movable] = 1.0  # close every finger: the joints move and the motors work
    _, _, _, _, info = env.step(a)
    after = env.scene.read()
    step_velocity = (after.q - before.q) / env.cfg.control_dt
    assert info["reward/work"] > 0.0
    assert info["reward/work"] == pytest.approx(float(after.tau @ step_velocity) ** 2, rel=1e-12)
    assert info["reward/work"] != pytest.approx(float(after.tau @ after.dq) ** 2, rel=1e-3)


def test_configs_saved_before_a_setting_existed_read_back_as_they_ran():
    saved = {k: v for k, v in RotationConfig().to_dict().items() if k not in R.config.SAVED_BEFORE}
    old = RotationConfig.from_saved(saved)
    assert (old.joint_damping, old.work_velocity, old.grasp_hold) == (True, "instant", "own")
    assert RotationConfig().grasp_hold == "canonical"
    with pytest.raises(RotationConfigError, match="grasp_hold"):
        RotationConfig(grasp_hold="mine")
    assert (RotationConfig.from_dict(saved).joint_damping, RotationConfig().work_velocity) == (False, "step")
    assert RotationConfig.from_saved(RotationConfig().to_dict()) == RotationConfig()
    with pytest.raises(RotationConfigError, match="work_velocity"):
        RotationConfig(work_velocity="mean")


def test_env_simulates_a_hand_given_to_it_and_refuses_a_mismatched_kind(grasps):
    """``sim_hand=``: the task simulates that SimHand (here the canonical LEAP with 0.2 kg index finger
    links), not the one the config names; a canonical hand under ``urdf='original'`` is refused."""
    base = resolve(CFG).hand
    masses = np.array(base.finger_masses, dtype=float)
    masses[1] = 0.2
    heavy = base.with_finger_masses(masses)
    e = InHandRotateEnv(CFG, grasps=grasps, sim_hand=heavy)
    try:
        sc = e.scene
        index = [j for j, name in sc.links if sc.link_finger[j] == 1]
        total = sum(pb.getDynamicsInfo(sc.body, j, physicsClientId=sc.client)[0] for j in index)
        assert e.task.hand is heavy and total == pytest.approx(0.2, rel=1e-6)
    finally:
        e.close()
    with pytest.raises(RotationConfigError, match="canonical hand but the config says urdf='original'"):
        resolve(RotationConfig(urdf="original"), sim_hand=base)


def test_settled_start_targets_hold_the_joints_where_the_starting_state_left_them(grasps):
    """``start_targets="settled"`` (HORA's reset): the first targets are the settled joint angles, so a
    finger the object blocks no longer presses; "perturbed" keeps the pose it settled under."""
    pressed = int(np.argmax(np.abs(grasps.target - grasps.q).max(axis=1)))
    assert np.abs(grasps.target[pressed] - grasps.q[pressed]).max() > 0.02  # a start that squeezes
    tau = {}
    for start in ("perturbed", "settled"):
        e = InHandRotateEnv(CFG.with_overrides(start_targets=start), grasps=grasps)
        try:
            e.reset(options={"grasp": pressed})
            want = grasps.q[pressed] if start == "settled" else grasps.target[pressed]
            assert np.allclose(e.space.to_sim(e._target), np.clip(want, e.task.hand.lower, e.task.hand.upper))
            _, _, _, _, info = e.step(np.zeros(e.action_space.shape))
            tau[start] = info["reward/torque"]
        finally:
            e.close()
    assert tau["settled"] < 0.5 * tau["perturbed"]
    with pytest.raises(RotationConfigError, match="start_targets"):
        RotationConfig(start_targets="relaxed")


def test_original_urdf_with_canonical_collisions_is_the_hybrid_hand(hands_dir):
    """``collisions="canonical"`` simulates the original URDF carrying the canonical collision shapes
    (capsules, no meshes or boxes), same driven joints; the canonical URDF refuses the setting."""
    own = resolve(RotationConfig(urdf="original"))
    hyb = resolve(RotationConfig(urdf="original", collisions="canonical"))
    assert hyb.hand.joints == own.hand.joints and not hyb.hand.canonical
    shapes = {g.tag for c in ET.fromstring(hyb.hand.urdf).iter("collision") for g in c.find("geometry")}
    own_shapes = {g.tag for c in ET.fromstring(own.hand.urdf).iter("collision") for g in c.find("geometry")}
    assert "capsule" in shapes and not shapes & {"mesh", "box"} and own_shapes & {"mesh", "box"}
    with pytest.raises(RotationConfigError, match="collisions"):
        RotationConfig(collisions="canonical")


def test_generating_starting_states_shows_progress_on_a_terminal_only(monkeypatch):
    """gym.make on a hand without cached states generates them (minutes): a terminal sees a bar, a log does not."""
    import io

    from ohra.sim.rotation import grasps

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stderr", Terminal())
    bar = grasps._bar(3, "grasps x", None)
    bar.update(1)
    bar.close()
    assert "grasps x (first use; cached)" in sys.stderr.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    grasps._bar(3, "grasps x", None).update(1)
    assert sys.stderr.getvalue() == ""


def test_a_long_or_short_generation_is_forecast_once_and_a_quick_one_is_not(monkeypatch):
    """A hand keeping 4 % of its perturbed grasps on its original URDF (DG-5F) took ~1.5 h to end short of its 1,000
    states with no word off a terminal; after 50 attempts one sentence says where it ends and when."""
    from ohra.sim.rotation import grasps

    short = grasps.forecast(2, 50, 14.0, 50, 1000, 20000)
    assert short.startswith("2 of 50 perturbed grasps kept so far (4 %, 0.28 s each)")
    assert "limit of 20000 attempts with about 800 of 1000 starting states, in about 93 more minutes" in short
    long = grasps.forecast(20, 50, 14.0, 50, 1000, 20000)
    assert long.endswith("the 1000 starting states take about 11 more minutes (cached for later uses)")
    assert grasps.forecast(20, 50, 12.5, 50, 1000, 20000) is not None  # 2,450 attempts at 0.25 s: 10.2 min, said
    assert grasps.forecast(20, 50, 12.0, 50, 1000, 20000) is None  # 9.8 min: not said
    # a continued generation: its earlier attempts count for the rate, this run's for the time per attempt
    assert "about 1000 of 1000" not in grasps.forecast(400, 10000, 50.0, 50, 1000, 20000)
    assert grasps.forecast(0, 50, 5.0, 50, 1000, 20000) == ("0 of 50 perturbed grasps kept so far (0 %, 0.10 s each): if none "
                                                           "holds, the generation fails after its limit of 20000 attempts, "
                                                           "in about 33 more minutes")
    # generate() says it once, after FORECAST_AFTER attempts of its own
    monkeypatch.setattr(grasps, "FORECAST_AFTER", 2)
    monkeypatch.setattr(grasps, "FORECAST_SECONDS", 0.0)
    with pytest.warns(UserWarning, match=r"leap_hand_right:canonical with cube, starting states \(first use\): \d+ of 2 perturbed") as rec:
        generate(resolve(RotationConfig(grasp_count=4)))
    assert sum("starting states (first use)" in str(w.message) for w in rec) == 1


def test_start_pose_noise_follows_the_hand_not_the_folders_its_file_lies_in():
    """LEAP hands take the reference's +-0.25 rad, others Shadow's 0.1: an Allegro params file in a folder
    named for LEAP is not a LEAP hand (it got 0.25 and other starting states when the path was matched)."""
    noise = lambda hand: RotationConfig(hand=hand).resolved_grasp_noise  # noqa: E731
    assert noise("leap_hand_right") == noise("leap_2211") == noise("runs/my_leap_3303.json") == 0.25
    assert noise("shadow_hand_right") == noise("allegro_hand_left") == 0.1
    assert noise("/data/leap_runs/allegro_mod.json") == noise("leap_exp\\allegro.yaml") == 0.1
    assert RotationConfig(hand="leap_hand_right", grasp_noise=0.05).resolved_grasp_noise == 0.05


def test_an_original_urdf_without_a_palm_collision_shape_names_the_hybrid_way_out(hands_dir, tmp_path, monkeypatch):
    """Gaia's palm mesh is missing from its original URDF: the palm-up scene has nothing to rest the object on.
    That was a bare RuntimeError (a traceback from ohra rotate); it is an ohra error naming the hybrid hand, which
    works."""
    from ohra.cli.main import main

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    with pytest.raises(R.SceneError, match=r"gaia_hand_right:original: the ray down the palm centre hits no .*"
                                           r"collisions=\"canonical\""):
        InHandRotateEnv(hand="gaia_hand_right", urdf="original", grasp_count=2)
    assert main(["rotate", "grasps", "--hand", "gaia_hand_right", "--urdf", "original", "--grasps", "2"]) == 2
    env = InHandRotateEnv(hand="gaia_hand_right", urdf="original", collisions="canonical", grasp_count=2)
    env.reset(seed=0)
    env.close()


def test_a_nan_action_is_refused_and_leaves_the_env_as_it_was(env):
    """np.clip keeps NaN: one NaN action reached the motors, PyBullet's joint state stayed NaN, and every later
    episode ended at once as "broken" while its observations (NaN read as 0) looked valid."""
    from ohra.sim.rotation import RotationActionError

    n = env.action_space.shape[0]
    env.reset(seed=0)
    bad = np.zeros(n)
    bad[3] = np.nan
    with pytest.raises(RotationActionError, match=r"NaN or infinity at \[3\]"):
        env.step(bad)
    with pytest.raises(RotationActionError, match=rf"expected shape \({n},\)"):
        env.step(np.zeros(5))
    with pytest.raises(RotationActionError, match="starting state index"):
        env.reset(options={"grasp": len(env.grasps.q)})
    env.reset(seed=1)
    for _ in range(5):
        _, _, terminated, _, info = env.step(np.zeros(n))
    assert info["termination"] != "broken" and np.all(np.isfinite(env.scene.read().q))


@pytest.mark.parametrize("action, said", [
    (lambda n: np.ones((2, n // 2)), "expected shape"),  # was reshaped to (n,) and taken
    (lambda n: np.ones((1, n)), "expected shape"),
    (lambda n: np.ones(n, complex), "real numbers, got ndarray of complex128"),  # the imaginary part was dropped
    (lambda n: np.ones(n, bool), "real numbers, got ndarray of bool"),
    (lambda n: ["a"] * n, "real numbers"),
])
def test_an_action_of_another_shape_or_kind_is_refused(env, action, said):
    from ohra.sim.rotation import RotationActionError

    n = env.action_space.shape[0]
    env.reset(seed=0)
    with pytest.raises(RotationActionError, match=said):
        env.step(action(n))
    obs, *_ = env.step([0.0] * n)  # a list of numbers is fine
    assert env.observation_space.contains(obs)


def test_step_before_reset_and_any_call_after_close_are_named_gymnasium_errors(grasps):
    import gymnasium

    e = InHandRotateEnv(CFG, grasps=grasps)
    n = e.action_space.shape[0]
    with pytest.raises(gymnasium.error.ResetNeeded, match="call reset"):  # was AttributeError: no '_target'
        e.step(np.zeros(n, np.float32))
    e.reset(seed=0)
    e.close()
    e.close()  # twice is fine
    for call in (lambda: e.step(np.zeros(n, np.float32)), lambda: e.reset(seed=0)):  # were AttributeErrors on None
        with pytest.raises(gymnasium.error.ClosedEnvironmentError, match="closed environment"):
            call()


def test_an_empty_object_name_is_not_the_current_folder_and_hidden_folders_are_not_objects(tmp_path):
    """``object=""`` loaded the current folder, whose first sub-folder was ``.ci``; a folder of objects listed its
    hidden folders (.git, .ipynb_checkpoints) as objects."""
    import trimesh

    from ohra.errors import ObjectError
    from ohra.objects.resolve import resolve_objects

    with pytest.raises(ObjectError, match="unknown rotation object ''"):
        InHandRotateEnv(CFG, object="")
    with pytest.raises(ObjectError, match="object spec ''"):
        resolve_objects([""])
    (tmp_path / ".hidden").mkdir()
    (tmp_path / ".hidden" / "x.obj").write_text("v 0 0 0\n")
    (tmp_path / "box").mkdir()
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(tmp_path / "box" / "box.obj")
    assert [o.name for o in resolve_objects(str(tmp_path))] == ["box"]


def test_a_number_of_starting_states_given_as_grasps_is_named_before_any_reset(grasps):
    """`gym.make(..., grasps=20)` was taken, then the first reset died in an AttributeError ('int' object has no
    attribute 'q'); the count is grasp_count."""
    import gymnasium as gym

    with pytest.raises(RotationConfigError, match=r"grasps: expected starting states \(a GraspSet\) or None, got int; the "
                                                  r"number of starting states is grasp_count"):
        gym.make("ohra/InHandRotate-v0", grasps=20)
    with pytest.raises(RotationConfigError, match=r"render_mode must be None or one of \['rgb_array'\], got 'human'"):
        InHandRotateEnv(CFG, grasps=grasps, render_mode="human")
