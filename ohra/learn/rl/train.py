"""Train a rotation policy with Stable-Baselines3 PPO: seeded, vectorised, checkpointed, resumable.

Run directory::

    RUN/config.json                 env (RotationConfig) + PPO settings + library versions
    RUN/<hand>.json                 a hand given as a params file: the run's own copy, which config.json names
    RUN/progress.csv                one row per rollout, appended (survives --resume)
    RUN/checkpoints/last.zip        model, rewritten atomically every ``checkpoint_every`` steps
    RUN/checkpoints/last_vecnormalize.pkl, last.json (steps, wall seconds so far)
    RUN/model.zip, RUN/vecnormalize.pkl   the final policy and its observation statistics
    RUN/tensorboard/ppo_0/events.*  with ``tensorboard=True``: SB3's training scalars and the rotation
                                    per episode, one event file continued by every resume

``resume=True`` continues from ``checkpoints/last.zip`` up to ``total_steps`` (or until the
``max_minutes`` budget, counted over all sessions, is spent); the env config must be the same.

``init_from=RUN`` starts a *new* run (its own steps, budget and settings: a fine-tune, e.g. with
another reward weight) from another run's trained weights and observation/return statistics;
``config.json`` records where they came from (``init_from``: run, file, its PPO steps ``timesteps`` and
wall seconds ``wall_s``, and the environment settings that differ), so a budget is stated as the source's plus the new run's.
"""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import time
from contextlib import contextmanager
from dataclasses import replace
from functools import lru_cache, partial
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ohra.errors import CheckpointError
from ohra.interrupts import DeferredStop
from ohra.io import folder_lock, write_bytes
from ohra.learn.rl.config import POLICIES, PPOSettings, RLConfigError
from ohra.sim.rotation.config import RotationConfig

CSV_FIELDS = ("timesteps", "wall_s", "episodes", "ep_reward_mean", "ep_length_mean", "rotation_mean",
              "learning_rate", "approx_kl", "explained_variance", "value_loss")
RESUMABLE_CHANGES = ("total_steps", "max_minutes", "checkpoint_every")


def _make_env(env_cfg: dict, rank: int, worker: bool = False):
    """Factory for one environment (top level: it is pickled to the subprocess workers; ``worker``: it runs in one)."""
    from stable_baselines3.common.monitor import Monitor

    from ohra.sim.rotation.env import InHandRotateEnv

    if worker:
        # a subprocess env worker: Ctrl-C reaches the whole process group, and the trainer (which saves a checkpoint
        # before it stops) still needs its workers for that
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return Monitor(InHandRotateEnv(RotationConfig.from_dict(env_cfg)), info_keywords=("cumulative_rotation",))


def adapt_learning_rate(lr: float, kl: float, target: float, bounds: tuple[float, float]) -> float:
    """rl_games' adaptive rule: lr / 1.5 when the update's KL exceeded 2 x ``target``, lr x 1.5 when it
    stayed under half of it, else unchanged; kept within ``bounds``."""
    if kl > 2.0 * target:
        return max(lr / 1.5, bounds[0])
    if kl < 0.5 * target:
        return min(lr * 1.5, bounds[1])
    return lr


class _AdaptiveLR:
    """Picklable learning-rate 'schedule' whose value :class:`AdaptiveKLPPO` moves between updates."""

    def __init__(self, lr: float):
        self.lr = float(lr)

    def __call__(self, progress_remaining: float) -> float:
        return self.lr


@lru_cache(maxsize=None)
def ppo_class(policy: str = "mlp"):
    """PPO with rl_games' adaptive learning rate (a factory, so that importing this module needs no SB3):
    SB3's ``PPO`` for ``policy="mlp"``, sb3-contrib's ``RecurrentPPO`` for ``"lstm"``."""
    return _adaptive(_base_class(policy))


def _base_class(policy: str):
    if policy == "mlp":
        from stable_baselines3 import PPO

        return PPO
    if policy == "lstm":
        try:
            from sb3_contrib import RecurrentPPO
        except ImportError:  # pragma: no cover - exercised only without the extra
            from ohra.learn import MissingDependencyError

            raise MissingDependencyError("policy 'lstm' needs sb3-contrib (RecurrentPPO); install it with "
                                         "`pip install ohra[learn,rl]`") from None
        return RecurrentPPO
    raise RLConfigError(f"policy must be one of {POLICIES}, got {policy!r}")


def _adaptive(base):
    class AdaptiveKLPPO(base):
        """After every update: lr / 1.5 if the mean KL exceeded 2 x ``kl_target``, x 1.5 below half of it."""

        def __init__(self, *args, kl_target: float | None = 0.02, lr_bounds=(1e-6, 1e-2), **kwargs):
            self.kl_target, self.lr_bounds = kl_target, tuple(lr_bounds)
            super().__init__(*args, **kwargs)

        def _setup_model(self) -> None:
            loaded = self.__dict__.get("lr_schedule")  # set by load() before it calls this: keep its value
            super()._setup_model()
            self.lr_schedule = loaded if isinstance(loaded, _AdaptiveLR) else _AdaptiveLR(float(self.learning_rate))

        def train(self) -> None:
            super().train()
            kl = self.logger.name_to_value.get("train/approx_kl")
            if self.kl_target is not None and kl is not None:
                self.lr_schedule.lr = adapt_learning_rate(self.lr_schedule.lr, float(kl), self.kl_target, self.lr_bounds)

    AdaptiveKLPPO.__name__ = AdaptiveKLPPO.__qualname__ = f"AdaptiveKL{base.__name__}"
    return AdaptiveKLPPO


def _callback(run_dir: Path, ppo: PPOSettings, wall_before: float, stop: DeferredStop | None = None):
    from stable_baselines3.common.callbacks import BaseCallback

    class RunCallback(BaseCallback):
        """Per-rollout CSV row, atomic checkpoints, the wall-clock budget, and a stop on Ctrl-C / SIGTERM."""

        dropped = False  # a stop request ended the current rollout (its steps were not learned from)

        def _on_training_start(self) -> None:  # once per learn() call: a run that went on after a signal calls it again
            self.t0 = getattr(self, "t0", None) or time.perf_counter()
            self.updated_steps = self.num_timesteps  # the steps every finished PPO update has learned from
            self.ep_r, self.ep_l, self.ep_rot = [], [], []
            self.next_ckpt = (self.num_timesteps // ppo.checkpoint_every + 1) * ppo.checkpoint_every

        def wall(self) -> float:
            return wall_before + time.perf_counter() - self.t0

        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                ep = info.get("episode")
                if ep is not None:
                    self.ep_r.append(ep["r"])
                    self.ep_l.append(ep["l"])
                    self.ep_rot.append(ep.get("cumulative_rotation", np.nan))
            if stop is not None and stop.requested:
                self.dropped = True
                return False  # the rollout is dropped; the checkpoint keeps the last update (see train_rotation)
            return ppo.max_minutes is None or self.wall() < 60.0 * ppo.max_minutes

        def _on_rollout_start(self) -> None:
            self.updated_steps = self.num_timesteps
            # here, not on the rollout's last step: the previous rollout's update has now run, so a checkpoint at
            # N steps holds every update of the first N steps (saved before it, the resume lost one update)
            if self.num_timesteps >= self.next_ckpt:
                save_checkpoint(self.model, run_dir, self.wall())
                self.next_ckpt = (self.num_timesteps // ppo.checkpoint_every + 1) * ppo.checkpoint_every

        def _on_rollout_end(self) -> None:
            if self.ep_rot:  # to TensorBoard too (when on) with SB3's own scalars
                self.logger.record("rollout/rotation_mean", _mean(self.ep_rot))
            log = self.model.logger.name_to_value  # the previous update's values (dumped after this rollout)
            row = {"timesteps": self.num_timesteps, "wall_s": round(self.wall(), 2), "episodes": len(self.ep_r),
                   "ep_reward_mean": _mean(self.ep_r), "ep_length_mean": _mean(self.ep_l),
                   "rotation_mean": _mean(self.ep_rot), "learning_rate": self.model.lr_schedule(1.0),
                   "approx_kl": log.get("train/approx_kl", np.nan),
                   "explained_variance": log.get("train/explained_variance", np.nan),
                   "value_loss": log.get("train/value_loss", np.nan)}
            _append_csv(run_dir / "progress.csv", row)
            self.ep_r, self.ep_l, self.ep_rot = [], [], []

    return RunCallback()


def _close_quietly(venv) -> None:
    """Close the vector env; workers a signal already ended leave nothing to close."""
    if getattr(venv, "closed", False) or getattr(getattr(venv, "venv", None), "closed", False):
        return
    try:
        venv.close()
    except (EOFError, ConnectionError, OSError):
        pass


def _mean(x: list) -> float:
    return float(np.nanmean(x)) if len(x) else float("nan")


def _append_csv(path: Path, row: dict[str, Any]) -> None:
    new = not path.is_file()
    with open(path, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_FIELDS)
        if new:
            w.writeheader()
        w.writerow(row)


def _whole_row(row: dict) -> bool:
    """A progress row with every column present and a whole-number ``timesteps``."""
    if None in row or any(row.get(k) is None for k in CSV_FIELDS):
        return False
    try:
        return float(row["timesteps"]).is_integer()
    except ValueError:
        return False


def truncate_progress(path: Path, timesteps: int) -> int:
    """Drop the rows of ``path`` (progress.csv) logged past ``timesteps`` (atomic rewrite); returns how
    many were dropped. A run interrupted between two checkpoints logged rollouts its resume repeats."""
    if not path.is_file():
        return 0
    with open(path, newline="") as fh:
        text = fh.read()
    rows = list(csv.DictReader(io.StringIO(text)))
    # a row torn by a kill mid-append (no newline, missing cells) is dropped, and so is the merge of it with the
    # next append ("20" + "1152,...": a 201,152-step row)
    keep = [r for r in rows if _whole_row(r) and int(float(r["timesteps"])) <= timesteps]
    if len(keep) == len(rows) and text.endswith("\n"):
        return 0
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_FIELDS, extrasaction="ignore")
        w.writeheader()
        w.writerows(keep)
    os.replace(tmp, path)
    return len(rows) - len(keep)


def save_checkpoint(model, run_dir: Path, wall_s: float) -> None:
    """Write ``checkpoints/last.*`` atomically (model, observation statistics, progress)."""
    d = run_dir / "checkpoints"
    d.mkdir(parents=True, exist_ok=True)
    model.save(d / ".last.tmp.zip")
    os.replace(d / ".last.tmp.zip", d / "last.zip")
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(d / ".last_vecnormalize.tmp.pkl")
        os.replace(d / ".last_vecnormalize.tmp.pkl", d / "last_vecnormalize.pkl")
    tmp = d / ".last.tmp.json"
    tmp.write_text(json.dumps({"timesteps": int(model.num_timesteps), "wall_s": wall_s}))
    os.replace(tmp, d / "last.json")


def save_final(model, run_dir: Path) -> None:
    """Write ``model.zip`` and ``vecnormalize.pkl``: each to a temporary file first, the old policy removed before
    either is replaced and the policy written last, so a kill leaves either the new pair or no ``model.zip`` (a run
    ``--resume`` finishes from its checkpoint), never a policy beside statistics of another."""
    tmp_model, tmp_stats = run_dir / ".model.tmp.zip", run_dir / ".vecnormalize.tmp.pkl"
    model.save(tmp_model)
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(str(tmp_stats))
    (run_dir / "model.zip").unlink(missing_ok=True)
    if venv is not None:
        os.replace(tmp_stats, run_dir / "vecnormalize.pkl")
    os.replace(tmp_model, run_dir / "model.zip")


def _final_intact(run_dir: Path) -> bool:
    """Whether ``model.zip`` is a whole zip archive (and its statistics exist when the run normalises observations)."""
    import zipfile

    path = run_dir / "model.zip"
    try:
        with zipfile.ZipFile(path) as z:
            if z.testzip() is not None:
                return False
    except (OSError, zipfile.BadZipFile):
        return False
    cfg = read_config(run_dir)
    return not bool(cfg.get("ppo", {}).get("normalize_obs", True)) or (run_dir / "vecnormalize.pkl").is_file()


def _vec_env(env_cfg: RotationConfig, ppo: PPOSettings):
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    fns = [partial(_make_env, env_cfg.to_dict(), i, ppo.n_envs > 1) for i in range(ppo.n_envs)]
    return SubprocVecEnv(fns, start_method="forkserver") if ppo.n_envs > 1 else DummyVecEnv(fns)


def _check_resume(run_dir: Path, env_cfg: RotationConfig, ppo: PPOSettings) -> None:
    """Refuse a resume whose environment or (non-budget) PPO settings differ from the run's. The saved
    config is read through the dataclasses, so a setting added to ohra after the run was made counts
    at the value the run had (``SAVED_BEFORE``) or its default instead of failing the comparison."""
    saved = read_config(run_dir)
    theirs_cfg = RotationConfig.from_saved(_saved_env(run_dir, saved), f"{run_dir}/config.json")
    theirs = _plain(theirs_cfg.to_dict())
    mine = _plain(_portable_env(run_dir, env_cfg, copy=False)[0])
    # forms compare as resolved: null and the form it stands for are one setting, and a hand whose default form
    # changed since the run (a spec YAML's `form:` edited) is another hand
    theirs["form"] = theirs.get("form") or _hand_form(theirs_cfg)
    mine["form"] = mine.get("form") or _hand_form(env_cfg)
    diff = sorted(k for k in set(theirs) | set(mine) if theirs.get(k) != mine.get(k))
    if diff:
        raise RLConfigError(f"{run_dir}: the environment config differs from the run being resumed: "
                            + "; ".join(f"{k}: run {theirs.get(k)!r}, now {mine.get(k)!r}" for k in diff))
    theirs, mine = _plain(PPOSettings.from_dict(saved["ppo"]).to_dict()), _plain(ppo.to_dict())
    diff = sorted(k for k in mine if k not in RESUMABLE_CHANGES and mine[k] != theirs.get(k))
    if diff:
        raise RLConfigError(f"{run_dir}: PPO settings {diff} differ from the run being resumed "
                            f"(only {RESUMABLE_CHANGES} may change)")


NETWORK_SETTINGS = ("policy", "net_arch", "activation", "lstm_hidden", "lstm_critic", "normalize_obs")


def init_source(src: str | Path) -> tuple[Path, Path, dict]:
    """The policy file, observation-statistics file and budget of the run ``src`` a new run starts from:
    a training run's last checkpoint (the newest policy, which ``checkpoints/last.json`` describes: a run
    resumed and interrupted keeps an older ``model.zip``), else its final policy (``model.zip`` +
    ``vecnormalize.pkl``); or an exported / shipped policy (``policy.pth`` + ``obs_stats.npz``, budget
    from ``trained.json``; no optimizer state or return statistics travel with an export). A budget
    the source does not record is None.

    Raises:
        RLConfigError: ``src`` holds no trained policy.
    """
    src = Path(src)
    last = src / "checkpoints" / "last.json"
    for zip_path, stats, budget in ((src / "checkpoints" / "last.zip", src / "checkpoints" / "last_vecnormalize.pkl", last),
                                    (src / "model.zip", src / "vecnormalize.pkl", None),
                                    (src / "policy.pth", src / "obs_stats.npz", src / "trained.json")):
        if zip_path.is_file() and stats.is_file():
            done = json.loads(budget.read_text()) if budget is not None and budget.is_file() else {}
            return zip_path, stats, {"timesteps": done.get("timesteps"), "wall_s": done.get("wall_s")}
    raise RLConfigError(f"init_from: {src} holds no trained policy (model.zip or checkpoints/last.zip with its "
                        "observation statistics, or an exported policy.pth with obs_stats.npz)")


def _init_record(src: Path, zip_path: Path, budget: dict, env_cfg: RotationConfig, ppo: PPOSettings) -> dict:
    """What ``config.json`` says about the source of a new run's weights; refuses a different network."""
    theirs_env, theirs_ppo = load_run(src)
    a, b = _plain(theirs_ppo.to_dict()), _plain(ppo.to_dict())
    diff = [f"{k}: source {a.get(k)!r}, now {b[k]!r}" for k in NETWORK_SETTINGS if a.get(k) != b[k]]
    if diff:
        raise RLConfigError(f"init_from {src}: the network must be the source run's ({'; '.join(diff)})")
    a, b = _plain(theirs_env.to_dict()), _plain(env_cfg.to_dict())
    changes = {k: {"source": a.get(k), "now": b[k]} for k in b if a.get(k) != b[k]}
    rec = {"run": str(src), "file": str(zip_path.relative_to(src)), **budget, "env_changes": changes}
    before = read_config(src).get("init_from")  # the source was itself started from another run: keep the chain
    if before:
        rec["source_init_from"] = before
    return rec


def _load_init(model, venv, zip_path: Path, stats: Path, src: Path) -> None:
    """Copy the source's weights into ``model`` and its observation/return statistics into ``venv``."""
    fit = (f"init_from {src}: its weights do not fit this run's spaces (the same observation and action sizes are "
           "needed: the hand's joint space): ")

    def first_mismatch(exc: Exception) -> str:  # torch's first line only says an error occurred
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        return next((ln for ln in lines if "size mismatch" in ln), lines[0] if lines else type(exc).__name__)
    if zip_path.name == "policy.pth":  # an export: weights and observation statistics, no optimizer or returns
        from ohra.learn.rl.evaluate import Policy

        pol = Policy(src)
        try:
            model.policy.load_state_dict(pol._policy.state_dict())
        except RuntimeError as exc:
            raise RLConfigError(fit + first_mismatch(exc)) from None
        if pol._mean is not None and "obs_rms" in venv.__dict__:
            if pol._mean.shape != venv.obs_rms.mean.shape:
                raise RLConfigError(fit + f"observation size {pol._mean.shape[0]}, this run {venv.obs_rms.mean.shape[0]}")
            # counted as the observations the source was trained on, so the first rollouts refine the
            # statistics rather than replace them
            done = json.loads((src / "trained.json").read_text()).get("timesteps") if (src / "trained.json").is_file() else None
            venv.obs_rms.mean, venv.obs_rms.var = pol._mean.astype(np.float64), pol._var.astype(np.float64)
            venv.obs_rms.count = float(done or 1e6)
        return
    import zipfile

    from ohra.learn.rl.files import load_pickle

    if not zipfile.is_zipfile(zip_path):
        raise CheckpointError(f"init_from {src}: {zip_path} is not a readable SB3 policy (.zip)")
    try:
        model.set_parameters(str(zip_path), exact_match=True, device="cpu")
    except (RuntimeError, ValueError) as exc:  # torch's size mismatch: another hand, space or observation layout
        raise RLConfigError(fit + first_mismatch(exc)) from None
    # an unpickled VecNormalize has no venv: read its fields, not attributes
    theirs = load_pickle(stats, "SB3 VecNormalize statistics (.pkl)").__dict__
    mine = venv.__dict__
    if "obs_rms" in theirs and "obs_rms" in mine:  # a run without observation normalisation has none
        venv.obs_rms = theirs["obs_rms"]
    if "ret_rms" in theirs and "ret_rms" in mine:
        venv.ret_rms = theirs["ret_rms"]


def train_rotation(env_cfg: RotationConfig, ppo: PPOSettings, run_dir: str | Path, resume: bool = False,
                   verbose: int = 0, tensorboard: bool = False, init_from: str | Path | None = None) -> Path:
    """Train (or resume) a PPO rotation policy into ``run_dir`` (layout in the module docstring).

    Generates (or loads) the cached starting states first; sets torch's thread count to ``ppo.threads``.

    Args:
        env_cfg: the environment (:class:`RotationConfig`); on resume it must equal the run's.
        ppo: PPO settings; on resume only ``total_steps``, ``max_minutes`` and ``checkpoint_every`` may
            differ from the run's.
        run_dir: the run folder (created if missing).
        resume: continue from ``checkpoints/last.zip`` up to ``ppo.total_steps`` (or the
            ``max_minutes`` budget, counted over all sessions).
        verbose: SB3 verbosity; > 0 also forces a progress bar while starting states are generated
            (else one only when stderr is a terminal).
        tensorboard: also log to ``run_dir/tensorboard`` (needs the ``tensorboard`` package; rl extra).
        init_from: a fresh run only: start from this run's trained weights (:func:`init_source`) and
            observation/return statistics instead of a random network; the network settings
            (``NETWORK_SETTINGS``) must be the source's, the spaces the same size.

    Returns:
        Path of the final policy, ``run_dir/model.zip`` (``vecnormalize.pkl`` beside it).

    Raises:
        RLConfigError: nothing to resume; a fresh run into a folder that holds one; on resume, an
            environment config or non-budget PPO setting that differs from the run's; ``init_from`` with
            ``resume``, without a trained policy, or with another network or space size.
        CheckpointError: on resume, the run's ``config.json`` missing, not valid JSON, or without its
            ``env`` or ``ppo`` object.
        FolderInUseError: another process is training into ``run_dir``.
        MissingDependencyError: ``tensorboard`` without the tensorboard package; ``ppo.policy="lstm"``
            without sb3-contrib.
    """
    import torch
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecNormalize

    from ohra.sim.rotation.grasps import load_or_generate
    from ohra.sim.rotation.task import resolve

    run_dir = Path(run_dir)
    last = run_dir / "checkpoints" / "last.zip"
    record = None  # what config.json says about init_from
    if init_from is not None:
        if resume:
            raise RLConfigError("init_from starts a new run; a resumed run continues from its own checkpoint")
        src = Path(init_from)
        zip_path, stats, budget = init_source(src)
        if src.resolve() == run_dir.resolve():
            raise RLConfigError(f"init_from {src}: the new run needs its own folder")
        record = _init_record(src, zip_path, budget, env_cfg, ppo)
    created = not run_dir.exists()
    _check_start(run_dir, last, resume)  # before the minutes of starting-state generation ...
    tb_dir = str(run_dir / "tensorboard") if tensorboard else None
    if tensorboard:
        _require_tensorboard()
    load_or_generate(resolve(env_cfg), progress=True if verbose > 0 else None)  # once here, not in every worker
    with folder_lock(run_dir, "rotation training run"), _torch_threads(ppo.threads):  # one writer per run folder
        _check_start(run_dir, last, resume)  # ... and again under the lock: another run may have started meanwhile
        if resume:
            _check_resume(run_dir, env_cfg, ppo)
        else:
            # a run stopped before its first checkpoint left only its config and a few progress rows
            (run_dir / "progress.csv").unlink(missing_ok=True)
            _write_config(run_dir, env_cfg, ppo, init_from=record)
        set_random_seed(ppo.seed)
        venv = _vec_env(env_cfg, ppo)
        cls = ppo_class(ppo.policy)
        wall_before = 0.0
        if resume:
            from ohra.learn.rl.files import load_checked

            stats = run_dir / "checkpoints" / "last_vecnormalize.pkl"
            try:
                venv = load_checked(stats, "SB3 VecNormalize statistics (.pkl)", lambda: VecNormalize.load(str(stats), venv))
                model = load_checked(last, "SB3 checkpoint (.zip)",
                                     lambda: cls.load(last, env=venv, device="cpu", tensorboard_log=tb_dir))
            except CheckpointError:
                venv.close()  # no worker processes left behind
                raise
            wall_before = json.loads((run_dir / "checkpoints" / "last.json").read_text())["wall_s"]
            # rows logged after the checkpoint by an interrupted session are redone from it
            truncate_progress(run_dir / "progress.csv", int(model.num_timesteps))
        else:
            venv = VecNormalize(venv, norm_obs=ppo.normalize_obs, norm_reward=ppo.normalize_reward, gamma=ppo.gamma)
            model = _new_model(cls, venv, ppo, verbose, tb_dir)
            if record is not None:
                try:
                    _load_init(model, venv, zip_path, stats, src)
                except (RLConfigError, CheckpointError):  # leave no workers and no half-made run behind
                    venv.close()
                    for name in ("config.json", "progress.csv"):
                        (run_dir / name).unlink(missing_ok=True)
                    if created:
                        import shutil

                        shutil.rmtree(run_dir, ignore_errors=True)  # a folder this call made holds only its lock
                    raise
        stop = DeferredStop("rotation training", at="at its last PPO update")
        try:
            cb = _callback(run_dir, ppo, wall_before, stop)
            remaining = max(0, ppo.total_steps - model.num_timesteps)
            spent = ppo.max_minutes is not None and wall_before >= 60.0 * ppo.max_minutes
            if resume and (remaining == 0 or spent):
                import warnings

                warnings.warn(f"{run_dir}: already at {model.num_timesteps:,} of {ppo.total_steps:,} steps"
                              + (f" and {wall_before / 60:.0f} of {ppo.max_minutes:g} minutes" if ppo.max_minutes else "")
                              + ": nothing to train; give a larger --steps / --minutes to continue", UserWarning, stacklevel=2)
                if not _final_intact(run_dir):  # missing or torn (a kill while writing them): the checkpoint holds them
                    save_final(model, run_dir)
                return run_dir / "model.zip"  # finished: its files and recorded budget stay as they are
            if resume:
                _save_budget(run_dir, ppo)  # a later plain resume continues to this budget
            with stop:
                while True:
                    cb.dropped = False
                    try:
                        model.learn(total_timesteps=max(0, ppo.total_steps - model.num_timesteps), callback=cb,
                                    reset_num_timesteps=False, tb_log_name="ppo")
                    except (EOFError, ConnectionError):  # a signal sent to the whole group also ended the env workers
                        if not stop.requested:
                            raise
                        cb.dropped = True
                    if not cb.dropped:  # finished, or out of minutes (a signal in the last update: handled below)
                        break
                    # the weights are those of the last finished update: count only the steps it learned from, so a
                    # resume collects the dropped rollout again
                    model.num_timesteps = cb.updated_steps
                    save_checkpoint(model, run_dir, cb.wall())
                    truncate_progress(run_dir / "progress.csv", int(model.num_timesteps))
                    stop.stop()  # KeyboardInterrupt, or SIGTERM's own end; a handler that returns lets training go on
                save_checkpoint(model, run_dir, cb.wall())
                save_final(model, run_dir)
                stop.stop()  # a signal during the last update: the run is complete and saved, then it ends as asked
        finally:
            _close_quietly(venv)
        return run_dir / "model.zip"


def _trained(run_dir: Path) -> bool:
    """Whether the folder holds trained weights (a checkpoint or a final policy), which a fresh run must not replace."""
    return (run_dir / "checkpoints" / "last.zip").is_file() or (run_dir / "model.zip").is_file()


def _check_start(run_dir: Path, last: Path, resume: bool) -> None:
    if resume and not last.is_file():
        stopped = (run_dir / "config.json").is_file() and not _trained(run_dir)
        raise RLConfigError(f"nothing to resume: {last} does not exist"
                            + ("; the run stopped before its first checkpoint: start it again without resume (--resume)"
                               if stopped else ""))
    if not resume and _trained(run_dir):
        raise RLConfigError(f"{run_dir} already holds a run; pass --resume (resume=True in Python) to continue it, or choose another folder")


@contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """torch's intra-op thread count set to ``n`` while training, restored afterwards (a library call
    should not change the caller's torch settings)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _require_tensorboard() -> None:
    try:
        from torch.utils.tensorboard import SummaryWriter  # noqa: F401
    except ImportError:  # pragma: no cover - exercised only without the package
        from ohra.learn import MissingDependencyError

        raise MissingDependencyError("TensorBoard logs need the tensorboard package: pip install -e '.[rl]'") from None


def _new_model(cls, venv, ppo: PPOSettings, verbose: int, tensorboard_log: str | None = None):
    import torch.nn as nn

    act = {"elu": nn.ELU, "relu": nn.ReLU, "tanh": nn.Tanh}[ppo.activation]
    arch = list(ppo.net_arch)
    policy_kwargs = {"net_arch": {"pi": arch, "vf": arch}, "activation_fn": act, "log_std_init": ppo.log_std_init}
    policy: Any = "MlpPolicy"
    if ppo.policy == "lstm":
        from ohra.learn.rl.lstm_policy import LstmPolicy

        policy = LstmPolicy
        policy_kwargs.update(lstm_hidden_size=ppo.lstm_hidden, n_lstm_layers=1, shared_lstm=False, enable_critic_lstm=ppo.lstm_critic)
    return cls(policy, venv, learning_rate=ppo.learning_rate, n_steps=ppo.n_steps, batch_size=ppo.batch_size,
               n_epochs=ppo.n_epochs, gamma=ppo.gamma, gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_range,
               ent_coef=ppo.ent_coef, vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm, target_kl=None,
               kl_target=ppo.kl_target, lr_bounds=ppo.lr_bounds, seed=ppo.seed, device="cpu", verbose=verbose,
               policy_kwargs=policy_kwargs, tensorboard_log=tensorboard_log)


def _plain(d: dict) -> dict:
    """``d`` as JSON would round-trip it (tuples as lists), so saved and current settings compare equal."""
    return json.loads(json.dumps(d))


def _save_budget(run_dir: Path, ppo: PPOSettings) -> None:
    """Record a resume's step and time budget in ``config.json`` (the only PPO settings a resume may change)."""
    d = read_config(run_dir)
    d["ppo"].update({k: ppo.to_dict()[k] for k in RESUMABLE_CHANGES})
    _replace_config(run_dir, d)


def _replace_config(run_dir: Path, d: dict) -> None:
    """Write ``run_dir/config.json`` atomically."""
    tmp = run_dir / ".config.tmp.json"
    tmp.write_text(json.dumps(d, indent=2) + "\n")
    os.replace(tmp, run_dir / "config.json")


def _write_config(run_dir: Path, env_cfg: RotationConfig, ppo: PPOSettings, init_from: dict | None = None) -> None:
    import gymnasium
    import pybullet
    import stable_baselines3
    import torch

    env, hand_source = _portable_env(run_dir, env_cfg)
    d = {"env": env, "ppo": ppo.to_dict(),
         "versions": {"stable_baselines3": stable_baselines3.__version__, "gymnasium": gymnasium.__version__,
                      "torch": torch.__version__, "pybullet_api": pybullet.getAPIVersion()}}
    if init_from is not None:
        d["init_from"] = init_from
    if hand_source is not None:
        d["hand_source"] = hand_source  # where the run's copy of its hand file came from
    # env.form may be null (the hand's default; a spec path and a registered name default to different forms):
    # the form it resolved to is what loading the run uses (_saved_env)
    d["hand_form"] = _hand_form(env_cfg)
    _replace_config(run_dir, d)


def _hand_form(env_cfg: RotationConfig) -> str:
    """The canonical form ``env_cfg``'s hand resolves to (its ``form``, else the hand's default)."""
    from ohra.hands import get_hand
    from ohra.sim.rotation.task import canonical_form

    return get_hand(env_cfg.hand, canonical_form(env_cfg.hand, env_cfg.form)).form


HAND_FILE_SUFFIXES = (".json",)  # a params file; a spec YAML names its URDF relative to itself: not copied
SPEC_SUFFIXES = (".yaml", ".yml")  # named by its absolute path instead, so the run evaluates from any folder


def _portable_env(run_dir: Path, env_cfg: RotationConfig, copy: bool = True) -> tuple[dict, str | None]:
    """The env settings as ``config.json`` stores them: a hand given as a params file is copied into the run
    folder under its own name and named by that (the run keeps the hand it was trained on, wherever it is
    evaluated from and whatever later happens to the file); a spec YAML and an object file are named by their
    absolute paths.
    Returns the settings and the absolute path the hand file was copied from (None: no file). ``copy=False``
    (a resume's comparison, against :func:`_saved_env`): the hand is named by the run's copy, as a path, only when
    the file still holds the same hand."""
    d, source = env_cfg.to_dict(), None
    hand = Path(env_cfg.hand)
    if hand.suffix.lower() in HAND_FILE_SUFFIXES and hand.is_file():
        own = Path(run_dir) / hand.name
        if copy:
            source = str(hand.resolve())
            if hand.resolve() != own.resolve():
                write_bytes(own, hand.read_bytes())
            d["hand"] = hand.name
        elif own.is_file() and hand.read_bytes() == own.read_bytes():
            d["hand"] = str(own.resolve())
    elif hand.suffix.lower() in SPEC_SUFFIXES and hand.expanduser().is_file():
        d["hand"] = str(hand.expanduser().resolve())  # its URDF is found relative to it: named where it lies
    if _object_file(env_cfg.object):
        d["object"] = str(Path(env_cfg.object).expanduser().resolve())
    return d, source


def _object_file(obj: str) -> bool:
    """Whether a config's object names a file or folder (not cube/sphere/cylinder, a built-in or procedural one)."""
    from ohra.sim.rotation.objects import SIZED

    s = str(obj)
    return s not in SIZED and not s.startswith(("builtin:", "procedural:")) and Path(s).expanduser().exists()


def _saved_env(run_dir: str | Path, d: dict) -> dict:
    """``d["env"]`` with a hand file stored in the run folder (:func:`_portable_env`) named by its path, and a
    null ``form`` pinned to the form the run recorded (``hand_form``) when it did."""
    env = dict(d["env"])
    if env.get("form") is None and isinstance(d.get("hand_form"), str):
        env["form"] = d["hand_form"]  # the form the run trained in, whatever the hand's default is now
    hand = env.get("hand")
    if isinstance(hand, str) and Path(hand).suffix.lower() in HAND_FILE_SUFFIXES and not Path(hand).is_absolute():
        own = Path(run_dir) / hand
        if own.is_file():
            env["hand"] = str(own.resolve())
    return env


def read_config(run_dir: str | Path) -> dict:
    """The parsed ``run_dir/config.json`` of a run or exported policy (a JSON object with ``env`` and
    ``ppo`` objects; not yet checked setting by setting).

    Raises:
        CheckpointError: the file does not exist, is not valid JSON, is not a JSON object, or lacks the
            ``env`` or ``ppo`` object (the file and the problem named).
    """
    path = Path(run_dir) / "config.json"
    if not path.is_file():
        raise CheckpointError(f"{run_dir} is not a rotation run or exported policy: {path} does not exist")
    try:
        d = json.loads(path.read_text())
    except UnicodeDecodeError as exc:
        raise CheckpointError(f"{path} is not a text file: {exc}") from None
    except json.JSONDecodeError as exc:
        raise CheckpointError(f"{path} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    if not isinstance(d, dict):
        raise CheckpointError(f"{path}: expected a JSON object with 'env' and 'ppo', got {type(d).__name__}")
    for key in ("env", "ppo"):
        if key not in d:
            raise CheckpointError(f"{path}: no {key!r} settings (keys: {sorted(d)}); a run's config.json has 'env' and 'ppo'")
        if not isinstance(d[key], dict):
            raise CheckpointError(f"{path}: {key!r} must be a JSON object of settings, got {type(d[key]).__name__}")
    return d


def load_run(run_dir: str | Path) -> tuple[RotationConfig, PPOSettings]:
    """The env config and PPO settings a run was trained with.

    Args:
        run_dir: a training run or an exported policy (a folder with ``config.json``).

    Returns:
        (env config, PPO settings); settings added to ohra after the run was made take the value the
        run had (:data:`ohra.sim.rotation.config.SAVED_BEFORE`) or their default.

    Raises:
        CheckpointError: ``run_dir/config.json`` does not exist, is not valid JSON, or has no ``env`` or
            ``ppo`` object (:func:`read_config`).
        RotationConfigError: an unknown or invalid environment setting in it.
        RLConfigError: an unknown or invalid PPO setting in it.
    """
    d = read_config(run_dir)
    return RotationConfig.from_saved(_saved_env(run_dir, d), f"{run_dir}/config.json"), PPOSettings.from_dict(d["ppo"])


def with_budget(ppo: PPOSettings, total_steps: int | None = None, max_minutes: float | None = None) -> PPOSettings:
    """``ppo`` with a new step and/or time budget (the settings a resume may change)."""
    kw = {}
    if total_steps is not None:
        kw["total_steps"] = int(total_steps)
    if max_minutes is not None:
        kw["max_minutes"] = float(max_minutes)
    return replace(ppo, **kw)
