"""``InHandRotateEnv``: rotate the object in a palm-up hand about world +z (Gymnasium API).

Action: ``Box(-1, 1, (n,), float32)``, relative joint targets: ``target += action_scale * a``,
clipped into the joint limits, sent to the position motors, held for one control step (20 Hz).
``n`` = 22 in the canonical joint space (immovable slots ignore their action) or the original
URDF's driven joints (``space="native"``). Observation: see :mod:`ohra.sim.rotation.observations`
(``observation_structure`` gives the layout). Reward: see :mod:`ohra.sim.rotation.rewards`; each
term is in ``info["reward/<term>"]``. Termination: the object's centre of mass fell ``fall_height`` below
or moved ``max_distance`` from its start, or the simulation diverged; truncation after ``episode_steps``.
``info`` also carries ``delta_yaw`` (rad turned about +z this step), ``cumulative_rotation`` (rad
since reset), ``steps`` and ``termination`` (None, "fell", "left" or "broken").

Randomness comes only from ``self.np_random`` (which starting state ``reset`` picks), so
``reset(seed=s)`` followed by the same actions gives the same trajectory.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ohra.errors import OhraError
from ohra.sim.hands import SimHand
from ohra.sim.rotation import observations as obs_terms
from ohra.sim.rotation import rewards, termination
from ohra.sim.rotation.config import RotationConfig, RotationConfigError
from ohra.sim.rotation.grasps import GraspSet, load_or_generate
from ohra.sim.rotation.scene import RotationScene
from ohra.sim.rotation.task import resolve


class RotationActionError(OhraError, ValueError):
    """An action or reset option the rotation env cannot take (wrong size, NaN or infinity, no such starting state)."""


class RotationResetNeeded(OhraError, gym.error.ResetNeeded):
    """``step`` before the first ``reset`` (``gymnasium.make``'s order check raises its own ResetNeeded)."""


class RotationEnvClosed(OhraError, gym.error.ClosedEnvironmentError):
    """``reset``, ``step`` or ``render`` after ``close``."""


class InHandRotateEnv(gym.Env):
    """In-hand rotation about world +z for any canonical hand or a registered hand's original URDF.

    Args:
        config: a :class:`RotationConfig` or a plain dict of its fields (default: LEAP, canonical, cube).
        render_mode: None or "rgb_array" (PyBullet TinyRenderer; keeps the URDF's visual shapes).
        grasps: starting states to use instead of the cached ones for this config.
        sim_hand: a :class:`ohra.sim.hands.SimHand` to simulate instead of the one the config names
            (:func:`ohra.sim.rotation.task.resolve`); pass ``grasps`` made for it.
        **overrides: config fields, e.g. ``hand="shadow_hand_right", urdf="original"`` (``hand`` is
            the config's hand name, as in ``gymnasium.make(ENV_ID, hand=..., urdf=...)``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20.0}  # an instance's: its control rate [Hz]

    def __init__(self, config: RotationConfig | dict | None = None, render_mode: str | None = None,
                 grasps: GraspSet | None = None, sim_hand: SimHand | None = None, **overrides: Any):
        if isinstance(config, dict):
            config = RotationConfig.from_dict(config)
        cfg = (config or RotationConfig()).with_overrides(**overrides) if overrides else (config or RotationConfig())
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise RotationConfigError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if grasps is not None and not isinstance(grasps, GraspSet):  # an int here failed at the first reset
            raise RotationConfigError(f"grasps: expected starting states (a GraspSet) or None, got {type(grasps).__name__}"
                                      + ("; the number of starting states is grasp_count" if isinstance(grasps, int) else ""))
        self.cfg, self.render_mode = cfg, render_mode
        self.metadata = {**self.metadata, "render_fps": cfg.control_hz}
        self.task = resolve(cfg, sim_hand)
        self.space = self.task.space
        self.grasps = grasps if grasps is not None else load_or_generate(self.task)
        self.scene = RotationScene(self.task.hand, self.task.obj, cfg, self.task.palm_radius,
                                   visual=render_mode is not None)
        # PyBullet's first step sets up state that later steps reuse: without this step (hand alone, before any
        # object) the first episode after construction drifted ~1e-10 from the same seed and actions replayed later
        self.scene.step()
        n = self.space.dim
        self.action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_structure = obs_terms.sizes(n)
        low, high = obs_terms.bounds(n)
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        self._lo, self._hi = self.space.lower, self.space.upper
        self._observer = obs_terms.Observer(self._lo, self._hi, cfg.phase_period)
        self._steps = 0

    # -- Gymnasium API ----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Start from a cached starting state: ``options={"grasp": i}`` picks one, else ``np_random`` does."""
        self._require_open("reset")
        super().reset(seed=seed)
        g = self.grasps
        if options and "grasp" in options:
            i = options["grasp"]
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= int(i) < len(g.q):
                raise RotationActionError(f"options['grasp'] must be a starting state index 0-{len(g.q) - 1}, got {i!r}")
            i = int(i)
        else:
            i = int(self.np_random.integers(len(g.q)))
        self.scene.set_hand(g.q[i])
        # "perturbed": the motors continue the settled state exactly; "settled": they hold the joints where they are
        target = g.target[i] if self.cfg.start_targets == "perturbed" else g.q[i]
        self.scene.drive(target)
        self.scene.new_object(g.obj_pos[i], g.obj_quat[i])
        self._target = np.clip(self.space.from_sim(target), self._lo, self._hi)
        self._q_start = self.space.from_sim(g.q[i])
        self._obj_start = self.scene.com_world(g.obj_pos[i], g.obj_quat[i])  # centre of mass
        self._quat = np.asarray(g.obj_quat[i], dtype=float).copy()
        self._steps, self._rotation = 0, 0.0
        self._snap = snap = self.scene.read()
        return self._observe(snap), {"grasp": i, "cumulative_rotation": 0.0, "steps": 0}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        cfg = self.cfg
        self._require_open("step")
        if not hasattr(self, "_target"):
            raise RotationResetNeeded("call reset() before step()")
        n = self.action_space.shape[0]
        try:
            raw = np.asarray(action)
            a = raw.astype(float) if raw.dtype.kind in "iuf" else None  # not bool, complex, strings or objects
        except (TypeError, ValueError):
            a = None
        if a is None:
            raise RotationActionError(f"action: expected {n} real numbers, got {type(action).__name__}"
                                      + (f" of {raw.dtype}" if isinstance(action, np.ndarray) else "")) from None
        if a.shape != (n,):  # a (2, 11) or (1, 22) array was reshaped and taken
            raise RotationActionError(f"action: expected shape ({n},) (one value per driven joint), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            # clipping keeps NaN: it reached the motors, and PyBullet's joint state stayed NaN for every later episode
            raise RotationActionError(f"action holds NaN or infinity at {np.flatnonzero(~np.isfinite(a.ravel())).tolist()} "
                                      "(a diverged policy?)")
        a = np.clip(a, -1.0, 1.0)
        self._target = np.clip(self._target + cfg.action_scale * a, self._lo, self._hi)
        self.scene.drive(self.space.to_sim(self._target))
        self.scene.step()
        prev, self._snap = self._snap, (snap := self.scene.read())
        self._steps += 1
        why = termination.reason(snap.obj_com, self._obj_start, cfg.fall_height, cfg.max_distance, snap.obj_quat,
                                 snap.q, snap.dq, snap.tau, snap.obj_linvel, snap.obj_angvel)
        if why == "broken":
            terms = {k: 0.0 for k in rewards.TERMS}
            dyaw = 0.0
        else:
            dyaw = rewards.delta_yaw(self._quat, snap.obj_quat)
            self._quat = snap.obj_quat
            terms = self._terms(snap, prev, dyaw)
            terms["fall"] = rewards.fall(why)
        self._rotation += dyaw
        reward = rewards.total(terms, cfg.weights)
        terminated = why is not None
        truncated = not terminated and self._steps >= cfg.episode_steps
        info = {f"reward/{k}": v for k, v in terms.items()}
        info.update(delta_yaw=dyaw, cumulative_rotation=self._rotation, steps=self._steps, termination=why)
        return self._observe(snap), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        self._require_open("render")
        from ohra.sim.rotation.render import render

        return render(self.scene)

    def close(self) -> None:
        if getattr(self, "scene", None) is not None:
            self.scene.close()
            self.scene = None

    def _require_open(self, call: str) -> None:
        if getattr(self, "scene", None) is None:
            raise RotationEnvClosed(f"{call}() on a closed environment: make a new one")

    # -- pieces -----------------------------------------------------------------------------------
    def _terms(self, snap, prev, dyaw: float) -> dict[str, float]:
        """Unweighted reward terms of this step (see :mod:`ohra.sim.rotation.rewards`); ``prev`` is the
        snapshot before it."""
        cfg = self.cfg
        dq = (snap.q - prev.q) / cfg.control_dt if cfg.work_velocity == "step" else snap.dq
        q = self.space.from_sim(snap.q)
        return {"rotation": rewards.rotation(dyaw, cfg.control_dt, cfg.angvel_clip),
                "drift": rewards.drift(snap.obj_com, self._obj_start),
                "pose": rewards.pose(q, self._q_start),
                "torque": rewards.torque(snap.tau),
                "work": rewards.work(snap.tau, dq),
                "linvel": rewards.linvel(snap.obj_linvel)}

    def _observe(self, snap) -> np.ndarray:
        o = obs_terms.ObsInput(q=self.space.from_sim(snap.q), target=self._target,
                               dq=self.space.velocity_from_sim(snap.dq), lower=self._lo, upper=self._hi,
                               obj_pos=snap.obj_com, obj_start=self._obj_start, obj_quat=snap.obj_quat,
                               obj_linvel=snap.obj_linvel, obj_angvel=snap.obj_angvel,
                               time=self._steps * self.cfg.control_dt, phase_period=self.cfg.phase_period)
        out = self._observer(o)
        return out if np.isfinite(out).all() else np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)
