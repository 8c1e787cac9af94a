"""Evaluate rotation policies: Steps-to-Fall and Cumulative Rotation, rendered episodes, meshcat replays.

Metrics (the paper's Table 3), over N episodes with seeds ``seed, seed+1, ...`` (each seed picks
the starting state), deterministic actions:

* Steps-to-Fall: control steps until the episode terminates (object fell, left the hand, or the
  simulation diverged); an episode that survives counts ``episode_steps`` (400 = 20 s).
* Cumulative Rotation: radians the object turned about world +z over the episode (signed sum of
  the per-step turns; positive is the commanded direction).
"""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ohra.errors import CheckpointError
from ohra.learn.rl.files import load_checked, load_pickle
from ohra.learn.rl.config import RLConfigError
from ohra.sim.rotation.config import RotationConfig, RotationConfigError

WHICH = ("model", "last")  # a run's final policy, or its last checkpoint


@dataclass
class EvalResult:
    """Per-episode metrics and their summary (control steps; radians about +z)."""

    run: str
    episodes: int
    seed: int
    steps_to_fall: list[int]
    cumulative_rotation: list[float]
    termination: list[str | None]
    episode_steps: int
    returns: dict[str, list[float]] | None = None  # per reward term: weighted sum over each episode

    def return_summary(self) -> dict[str, float]:
        """Mean episode return per reward term (weighted, as the policy was trained on) and in total."""
        if not self.returns:
            return {}
        out = {k: float(np.mean(v)) for k, v in self.returns.items()}
        return {**out, "total": sum(out.values())}

    def summary(self) -> dict[str, float]:
        s, r = np.asarray(self.steps_to_fall, float), np.asarray(self.cumulative_rotation, float)
        return {"steps_to_fall_mean": float(s.mean()), "steps_to_fall_std": float(s.std()),
                "rotation_mean": float(r.mean()), "rotation_std": float(r.std()),
                "survived": float(np.mean([t is None for t in self.termination]))}

    def to_dict(self) -> dict:
        return {**asdict(self), "summary": self.summary(), "return_summary": self.return_summary()}

    def __repr__(self) -> str:  # the dataclass default prints every episode and reward term
        s = self.summary()
        return (f"EvalResult({self.run!r}, {self.episodes} episodes: Steps-to-Fall {s['steps_to_fall_mean']:.1f} +- "
                f"{s['steps_to_fall_std']:.1f}, rotation {s['rotation_mean']:.2f} +- {s['rotation_std']:.2f} rad, "
                f"{100 * s['survived']:.0f} % survive)")


def shipped(name: str) -> Path:
    """Folder of a policy shipped with the package (``ohra/learn/models/<name>``, an :func:`export_policy`)."""
    from importlib import resources

    path = Path(str(resources.files("ohra.learn").joinpath("models", name)))
    if not (path / "policy.pth").is_file():
        known = sorted(p.parent.name for p in path.parent.glob("rotate_*/policy.pth"))
        raise CheckpointError(f"no shipped rotation policy {name!r}; shipped: {', '.join(known) or 'none'}")
    return path


def models_dir() -> Path:
    """The package's folder of shipped models (read-only where the package is installed)."""
    from importlib import resources

    return Path(str(resources.files("ohra.learn").joinpath("models")))


def policy_dir(run: str | Path) -> Path:
    """The folder of a run, an exported policy, or a shipped policy.

    Args:
        run: a path with a folder part, or a bare name whose folder has ``config.json``: returned as
            given (not checked further); else a shipped policy's name (``rotate_leap_canonical`` or just
            ``leap_canonical``).

    Returns:
        The folder.

    Raises:
        CheckpointError: a bare name that is neither a run folder nor a shipped policy.
    """
    path = Path(run)
    # a bare name's folder may be where an earlier evaluation of that shipped policy wrote its results
    if path.name != str(run) or (path / "config.json").is_file():
        return path
    for name in (str(run), f"rotate_{run}"):
        if (models_dir() / name / "policy.pth").is_file():
            return models_dir() / name
    known = sorted(p.parent.name for p in models_dir().glob("rotate_*/policy.pth"))
    raise CheckpointError(f"{run!r} is neither a run directory nor a shipped rotation policy (shipped: {', '.join(known)})")


def is_shipped(path: str | Path) -> bool:
    """Whether ``path`` is one of the package's shipped models (which evaluation must not write into)."""
    return Path(path).resolve().parent == models_dir().resolve()


class Policy:
    """A trained policy as a function of raw observations (observation statistics applied).

    ``run_dir`` is a training run (``model.zip`` + ``vecnormalize.pkl``, or with ``which="last"`` the
    last checkpoint) or an exported policy (:func:`export_policy`: ``policy.pth`` + ``obs_stats.npz``,
    no optimizer state, no pickles). ``grasps`` holds the starting states shipped with an export. A run
    trained without observation normalisation (no ``vecnormalize.pkl``, or its ``norm_obs`` off; an export
    whose ``obs_stats.npz`` says ``norm_obs=False``) gets the raw observations.

    A recurrent policy (``PPOSettings.policy="lstm"``) carries its LSTM state from call to call;
    :meth:`reset` clears it at the start of each episode (:func:`run_episode` does).

    Raises:
        CheckpointError: ``which`` not ``"model"`` or ``"last"`` (for an export too, where either means
            the exported policy); no ``config.json``; no trained policy file; an export's
            ``obs_stats.npz`` missing, unreadable or without its statistics.
        RotationConfigError, RLConfigError: an unknown or invalid setting in the run's ``config.json``.
    """

    def __init__(self, run_dir: str | Path, which: str = "model"):
        from ohra.learn.rl.train import load_run

        if which not in WHICH:
            raise CheckpointError(f"which must be 'model' or 'last', got {which!r}")
        run = Path(run_dir)
        self.env_cfg, self.ppo = load_run(run)
        self.grasps = None
        self._mean = self._var = self._clip = self._eps = None  # no observation normalisation unless set below
        self.reset()
        if (run / "policy.pth").is_file():
            from ohra.sim.rotation.grasps import GraspSet

            if self.recurrent:
                from ohra.learn.rl.lstm_policy import LstmPolicy as policy_class
            else:
                from stable_baselines3.common.policies import ActorCriticPolicy as policy_class

            self._policy = load_checked(run / "policy.pth", "exported policy (policy.pth)",
                                        lambda: policy_class.load(str(run / "policy.pth"), device="cpu"))
            self._read_obs_stats(run / "obs_stats.npz")
            if (run / "grasps.npz").is_file():
                self.grasps = load_checked(run / "grasps.npz", "starting-state file (grasps.npz)",
                                           lambda: GraspSet.load(run / "grasps.npz"))
            return
        zip_path, stats = {"model": (run / "model.zip", run / "vecnormalize.pkl"),
                           "last": (run / "checkpoints" / "last.zip", run / "checkpoints" / "last_vecnormalize.pkl")}[which]
        if not zip_path.is_file():
            last = which == "model" and (run / "checkpoints" / "last.zip").is_file()
            raise CheckpointError(f"no trained policy at {zip_path}" + (
                " (the run stopped before its end: its last checkpoint is evaluated with --checkpoint last, "
                "which='last' in Python; --resume finishes it)" if last else ""))
        from ohra.learn.rl.train import ppo_class

        self._policy = load_checked(zip_path, "SB3 policy (.zip)",
                                    lambda: ppo_class(self.ppo.policy).load(zip_path, device="cpu").policy)
        if not stats.is_file() and self.ppo.normalize_obs:
            # evaluated on raw observations, a policy trained on normalised ones turns the object the wrong way
            raise CheckpointError(f"{stats} does not exist, and the run normalised its observations (config.json: "
                                  f"normalize_obs true): its policy cannot be evaluated without them"
                                  + ("; --resume writes them again from the last checkpoint" if which == "model" else ""))
        if stats.is_file():
            vn = load_pickle(stats, "SB3 VecNormalize statistics (.pkl)")
            if not hasattr(vn, "norm_obs"):
                raise CheckpointError(f"{stats} holds a {type(vn).__name__}, not SB3 VecNormalize statistics")
            if vn.norm_obs:
                self._mean, self._var, self._clip, self._eps = vn.obs_rms.mean, vn.obs_rms.var, vn.clip_obs, vn.epsilon

    def _read_obs_stats(self, path: Path) -> None:
        """An export's observation statistics: ``norm_obs`` (False: the policy sees raw observations;
        exports made before the flag have none and always hold statistics) and ``mean``, ``var``,
        ``clip``, ``eps``."""
        if not path.is_file():
            raise CheckpointError(f"{path} does not exist: an exported policy needs its observation statistics "
                                  "(export it again with export_policy)")
        try:
            with np.load(path) as st:
                stats = {k: st[k] for k in st.files}
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise CheckpointError(f"{path} is not a readable observation statistics file: {exc}") from None
        if not bool(stats.get("norm_obs", True)):
            return
        missing = [k for k in ("mean", "var", "clip", "eps") if k not in stats]
        if missing:
            raise CheckpointError(f"{path}: observation statistics {missing} are missing (has {sorted(stats)})")
        self._mean, self._var, self._clip, self._eps = stats["mean"], stats["var"], float(stats["clip"]), float(stats["eps"])

    @property
    def recurrent(self) -> bool:
        return self.ppo.policy != "mlp"

    def reset(self) -> None:
        """Forget the recurrent state (a new episode starts); nothing to do for an MLP policy."""
        self._state, self._start = None, True

    @property
    def space_dim(self) -> int:
        """Size of the policy's action vector."""
        return int(self._policy.action_space.shape[0])

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self._mean is None:
            return obs
        return np.clip((obs - self._mean) / np.sqrt(self._var + self._eps), -self._clip, self._clip)

    def __call__(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        x = self.normalize(obs).astype(np.float32)
        if not self.recurrent:
            return self._policy.predict(x, deterministic=deterministic)[0]
        action, self._state = self._policy.predict(x, state=self._state, episode_start=np.array([self._start]),
                                                   deterministic=deterministic)
        self._start = False
        return action

    def make_env(self, render_mode: str | None = None, urdf: str | None = None):
        """The environment the policy was trained in (with the shipped starting states, if any), or with
        ``urdf`` the hand's other URDF (:func:`on_urdf`; that URDF's cached starting states)."""
        from ohra.sim.rotation.env import InHandRotateEnv

        cfg = on_urdf(self.env_cfg, urdf)
        return InHandRotateEnv(cfg, render_mode=render_mode, grasps=self.grasps if cfg is self.env_cfg else None)


def export_policy(run_dir: str | Path, out_dir: str | Path, which: str = "model") -> Path:
    """A small, pickle-free copy of a run for committing: ``config.json``, ``policy.pth`` (actor and
    critic weights, no optimizer), ``obs_stats.npz`` (``norm_obs`` and, when it is true, the observation
    ``mean``, ``var``, ``clip`` and ``eps``; false for a run trained without observation normalisation),
    the starting states ``grasps.npz``, the run's ``progress.csv`` / ``eval.json`` when present (a stale
    ``eval.json`` of an earlier export is removed), and ``trained.json`` (PPO steps and wall seconds trained).

    Args:
        run_dir: a training run (or an exported policy).
        out_dir: the export folder (created if missing; files in it are overwritten).
        which: ``"model"`` (the final policy) or ``"last"`` (the last checkpoint).

    Returns:
        ``out_dir``.

    Raises:
        CheckpointError: no ``config.json``; ``which`` not ``"model"`` or ``"last"``; no trained policy
            file for it.
        RotationConfigError, RLConfigError: an unknown or invalid setting in the run's ``config.json``.
    """
    import shutil

    from ohra.sim.rotation.grasps import load_or_generate
    from ohra.sim.rotation.task import resolve

    run, out = Path(run_dir), Path(out_dir)
    pol = Policy(run, which)
    out.mkdir(parents=True, exist_ok=True)
    pol._policy.save(str(out / "policy.pth"))
    if pol._mean is None:  # trained without observation normalisation: the policy reads raw observations
        np.savez(out / "obs_stats.npz", norm_obs=False)
    else:
        np.savez(out / "obs_stats.npz", norm_obs=True, mean=pol._mean, var=pol._var, clip=pol._clip, eps=pol._eps)
    load_or_generate(resolve(pol.env_cfg)).save(out / "grasps.npz")
    hand = Path(pol.env_cfg.hand)
    if hand.is_file() and hand.parent.resolve() == run.resolve() and run.resolve() != out.resolve():
        shutil.copy(hand, out / hand.name)  # the run's own copy of a params-file hand (config.json names it)
    for name in ("config.json", "progress.csv", "eval.json"):
        if (run / name).is_file():
            shutil.copy(run / name, out / name)
        elif name == "eval.json":  # an earlier export's evaluation is not this policy's
            (out / name).unlink(missing_ok=True)
    if (run / "checkpoints" / "last.json").is_file():  # steps and wall seconds it was trained for
        shutil.copy(run / "checkpoints" / "last.json", out / "trained.json")
    elif (run / "trained.json").is_file() and run.resolve() != out.resolve():  # an export of an export
        shutil.copy(run / "trained.json", out / "trained.json")
    return out


def run_episode(env, policy, seed: int, frames_every: int = 0, render=None) -> dict:
    """One episode; returns steps, rotation, termination, the weighted return of each reward term, the
    trajectory and, every ``frames_every`` steps, a frame from ``render()`` (default ``env.render()``)."""
    from ohra.sim.rotation.rewards import TERMS

    render = render or env.render
    weights = {k: getattr(env.cfg.weights, k) for k in TERMS}
    returns = dict.fromkeys(TERMS, 0.0)
    obs, info = env.reset(seed=seed)
    if hasattr(policy, "reset"):  # a recurrent policy starts each episode from a blank state
        policy.reset()
    frames, traj = [], {"q": [env.scene.read().q], "obj_pos": [env.scene.read().obj_pos],
                        "obj_quat": [env.scene.read().obj_quat]}
    if frames_every:
        frames.append(render())
    while True:
        obs, _, term, trunc, info = env.step(policy(obs))
        for k in TERMS:
            returns[k] += weights[k] * info[f"reward/{k}"]
        s = env.scene.read()
        traj["q"].append(s.q)
        traj["obj_pos"].append(s.obj_pos)
        traj["obj_quat"].append(s.obj_quat)
        if frames_every and info["steps"] % frames_every == 0:
            frames.append(render())
        if term or trunc:
            break
    return {"steps": int(info["steps"]), "rotation": float(info["cumulative_rotation"]),
            "termination": info["termination"], "returns": returns, "frames": frames, "trajectory": {k: np.array(v) for k, v in traj.items()}}


def evaluate_policy(policy, env_cfg: RotationConfig, episodes: int = 20, seed: int = 0, run: str = "",
                    grasps=None, hand=None) -> EvalResult:
    """Steps-to-Fall and Cumulative Rotation of ``policy`` over seeded episodes (module docstring).

    Args:
        policy: raw observation (obs_dim,) -> action (action_dim,) in [-1, 1] (e.g. a :class:`Policy`,
            which applies the observation statistics); its ``reset()``, if any, is called per episode.
        env_cfg: the environment.
        episodes: number of episodes; episode ``i`` is reset with seed ``seed + i``.
        seed: first episode seed.
        run: label stored in the result.
        grasps: starting states, as :class:`ohra.sim.rotation.env.InHandRotateEnv` takes them (None:
            the cached ones of ``env_cfg``).
        hand: a :class:`~ohra.sim.hands.SimHand` to simulate (the env's ``sim_hand``).

    Returns:
        :class:`EvalResult`: per episode the control steps until termination (``episode_steps`` if it
        survived), the rotation [rad] about world +z (positive: the commanded direction), the
        termination reason (None if it survived), and the weighted return of each reward term.

    Raises:
        RLConfigError: ``episodes`` not a whole number >= 1.
    """
    from ohra.sim.rotation.env import InHandRotateEnv

    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise RLConfigError(f"episodes must be a whole number >= 1, got {episodes!r}")
    env = InHandRotateEnv(env_cfg, grasps=grasps, sim_hand=hand)
    try:
        eps = [run_episode(env, policy, seed + i) for i in range(episodes)]
    finally:
        env.close()
    return EvalResult(run, episodes, seed, [e["steps"] for e in eps], [e["rotation"] for e in eps],
                      [e["termination"] for e in eps], env_cfg.episode_steps,
                      {k: [e["returns"][k] for e in eps] for k in eps[0]["returns"]} if eps else None)


def on_urdf(env_cfg: RotationConfig, urdf: str | None) -> RotationConfig:
    """The environment of ``env_cfg`` with the same hand's other URDF, driven and observed in the
    canonical 22-D joint space (an original URDF through its action map, starting from the canonical
    holding pose), so a policy trained in the canonical joint space on one URDF can be run on the other.

    Args:
        env_cfg: the run's environment.
        urdf: ``"canonical"``, ``"original"`` or None.

    Returns:
        ``env_cfg`` itself for None or the run's own URDF, else a changed copy.

    Raises:
        CheckpointError: the policy acts in an original URDF's own joints (``space`` "native": its
            actions mean nothing to another URDF).
        RotationConfigError: ``urdf`` is not ``"canonical"``, ``"original"`` or None.
    """
    import dataclasses

    if urdf is None or urdf == env_cfg.urdf:
        return env_cfg
    if env_cfg.resolved_space != "canonical":
        raise CheckpointError(
            f"the policy acts in the {env_cfg.urdf} URDF's own joints (space {env_cfg.resolved_space!r}); running it on "
            f"the {urdf} URDF needs a policy trained in the canonical joint space (ohra rotate train --space canonical)")
    if urdf == "original":
        return dataclasses.replace(env_cfg, urdf="original", space="canonical", grasp_hold="canonical",
                                   inertials="capsule")
    return dataclasses.replace(env_cfg, urdf=urdf, space=None, collisions="own")


def output_suffix(env_cfg: RotationConfig, urdf: str | None) -> str:
    """Suffix of the file names a run's evaluation writes: "" on its own URDF, "_on_<urdf>" on the other."""
    return "" if on_urdf(env_cfg, urdf) is env_cfg else f"_on_{urdf}"


def evaluate_run(run_dir: str | Path, episodes: int = 20, seed: int = 1000, which: str = "model",
                 write: bool = True, urdf: str | None = None, out_dir: str | Path | None = None) -> EvalResult:
    """Evaluate a trained run with :func:`evaluate_policy` and write ``eval.json``.

    Args:
        run_dir: a run, an exported policy or a shipped policy's name (:func:`policy_dir`).
        episodes: number of episodes.
        seed: first episode seed (1000 by default: training used 0..n_envs).
        which: ``"model"`` (the final policy) or ``"last"`` (the last checkpoint) of a training run.
        write: write the result as JSON (atomically).
        urdf: run the policy on the hand's other URDF (:func:`on_urdf`; starting states from that URDF's
            own cache) and write ``eval_on_<urdf>.json`` instead.
        out_dir: where to write (created if missing); default the run itself. A shipped policy needs one.

    Returns:
        :class:`EvalResult` (steps in control steps, rotations [rad] about world +z).

    Raises:
        CheckpointError: no such run or shipped policy; a shipped policy with ``write`` and no
            ``out_dir``; no ``config.json``; ``which`` not ``"model"`` or ``"last"``; no trained policy
            file; ``urdf`` names the other URDF for a policy in a native joint space.
        RotationConfigError: an unknown or invalid environment setting in the run's ``config.json``;
            ``urdf`` not ``"canonical"``, ``"original"`` or None.
        RLConfigError: an unknown or invalid PPO setting in the run's ``config.json``; ``episodes`` < 1
            (checked before anything is written).
    """
    run_dir = policy_dir(run_dir)
    if write and out_dir is None and is_shipped(run_dir):
        raise CheckpointError(f"{run_dir.name} is a shipped policy: give out_dir (ohra rotate eval -o DIR) to write its "
                              "evaluation elsewhere than the package, or write=False")
    pol = Policy(run_dir, which)
    cfg = on_urdf(pol.env_cfg, urdf)
    res = evaluate_policy(pol, cfg, episodes, seed, str(run_dir), grasps=pol.grasps if cfg is pol.env_cfg else None)
    if write:
        out = Path(out_dir) if out_dir is not None else run_dir
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"eval{output_suffix(pol.env_cfg, urdf)}.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(res.to_dict(), indent=2) + "\n")
        os.replace(tmp, path)
    return res


def record_episode(run_dir: str | Path, out_dir: str | Path, seed: int = 1000, every: int = 2, strip_frames: int = 8,
                   which: str = "model", size: int = 240, urdf: str | None = None) -> dict:
    """Render one episode of a run into ``out_dir`` (created if missing): ``rollout.gif`` (every
    ``every``-th control step), ``strip.png`` (evenly spaced frames), ``trajectory.npz`` (for
    :func:`replay_html`): ``q`` (T+1, n_joints) simulated joint positions [rad] in ``SimHand.joints``
    order, ``obj_pos`` (T+1, 3) [m] and ``obj_quat`` (T+1, 4) xyzw, the object frame in the world frame.

    Args:
        run_dir: a run, an exported policy or a shipped policy's name (:func:`policy_dir`).
        out_dir: the output folder.
        seed: the episode's seed.
        every: render every ``every``-th control step (>= 1).
        strip_frames: frames in the strip (at most; >= 1).
        which: ``"model"`` or ``"last"`` (see :func:`evaluate_run`).
        size: frame width and height [px].
        urdf: on the hand's other URDF (:func:`on_urdf`).

    Returns:
        dict with ``steps``, ``rotation`` [rad] about world +z, ``termination`` (None if it survived),
        and the paths ``gif``, ``strip``, ``trajectory``.

    Raises:
        CheckpointError, RotationConfigError, RLConfigError: as in :func:`evaluate_run`, less the
            shipped-policy write check.
        RotationConfigError: ``every`` or ``strip_frames`` not an integer >= 1 (checked before the policy loads).
    """
    for name, value in (("every", every), ("strip_frames", strip_frames)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise RotationConfigError(f"record_episode: {name} must be an integer >= 1, got {value!r}")
    from ohra.sim.render import write_png
    from ohra.sim.rotation.render import render, strip, write_gif

    pol = Policy(policy_dir(run_dir), which)
    env = pol.make_env(render_mode="rgb_array", urdf=urdf)
    try:
        ep = run_episode(env, pol, seed, frames_every=every, render=lambda: render(env.scene, size))
    finally:
        env.close()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frames = ep["frames"]
    write_gif(frames, out / "rollout.gif", fps=pol.env_cfg.control_hz / every)
    pick = np.linspace(0, len(frames) - 1, min(strip_frames, len(frames))).round().astype(int)
    write_png(strip([frames[i] for i in pick]), out / "strip.png")
    np.savez_compressed(out / "trajectory.npz", **ep["trajectory"])
    return {"steps": ep["steps"], "rotation": ep["rotation"], "termination": ep["termination"],
            "gif": str(out / "rollout.gif"), "strip": str(out / "strip.png"), "trajectory": str(out / "trajectory.npz")}


def replay_html(env_cfg: RotationConfig, trajectory: dict | str | Path, path: str | Path, vis=None) -> Path:
    """A meshcat animation of a recorded episode (hand links and object), saved as a static HTML page."""
    import meshcat.animation

    from ohra.original.urdf import load_urdf
    from ohra.rotations import quat_to_matrix
    from ohra.sim.rotation.scene import T_WORLD_PALM, fill_inertials
    from ohra.sim.rotation.task import resolve
    from ohra.viz import add_mesh, new_visualizer, save_html

    traj = dict(np.load(trajectory)) if isinstance(trajectory, (str, Path)) else trajectory
    task = resolve(env_cfg)
    model = load_urdf(fill_inertials(task.hand.urdf))
    index = {n: i for i, n in enumerate(task.hand.joints)}
    order = [index[n] for n in model.movable_joints]  # hand.joints order -> the URDF's own order
    vis = vis if vis is not None else new_visualizer()
    T0 = T_WORLD_PALM @ task.hand.T_palm_root
    links = [n for n in model.links if model.link_geometry(n, prefer="collision") is not None]
    poses = model.link_poses(np.asarray(traj["q"])[:, order], links)  # (T, L, 4, 4) in the root frame

    def object_pose(t: int) -> np.ndarray:
        To = np.eye(4)
        To[:3, :3] = quat_to_matrix(traj["obj_quat"][t])
        To[:3, 3] = traj["obj_pos"][t]
        return To

    # drawn at the episode's first frame: the page opens on it, and the camera frames the hand and object there
    # (drawn at the origin and moved after, every link counted at the origin and the camera sat inside the hand)
    for k, n in enumerate(links):
        m = model.link_geometry(n, prefer="collision")
        add_mesh(vis, m.vertices, m.faces, T=T0 @ poses[0, k], path=f"replay/hand/{n}", color=0x66BFFF, opacity=0.9)
    add_mesh(vis, task.obj.mesh.vertices, task.obj.mesh.faces, T=object_pose(0), path="replay/object")
    anim = meshcat.animation.Animation(default_framerate=int(env_cfg.control_hz))
    for t in range(len(poses)):
        with anim.at_frame(vis, t) as frame:
            for k, n in enumerate(links):
                frame[f"replay/hand/{n}"].set_transform(T0 @ poses[t, k])
            frame["replay/object"].set_transform(object_pose(t))
    vis.set_animation(anim, play=False)
    return save_html(vis, path)
