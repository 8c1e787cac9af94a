"""The cross-embodiment grasp model: network, sampling, checkpoints.

:class:`GraspNet` (torch module) = object encoder + translation denoiser + joint network.
:class:`GraspModel` wraps a trained net with its hand condition, the translation scale and its
settings, and samples grasps for any canonical hand on any object::

    model = load_grasp_model("runs/grasp")          # or load_grasp_model() for the shipped one
    grasps = model.sample("barrett_hand", ObjectModel.builtin("capsule"), 100, seed=0)   # (100, 31)

A grasp is ``[t (3), rot6d (6), q (22)]``: the canonical palm frame in the object frame [m] and the
canonical joint angles [rad], as in the datasets. The wrist rotation is an input (uniformly random
when none is given); the translation comes from DDIM sampling; joints are clamped to the hand's
limits (absent joints are exactly 0).
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Union

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ohra.canonical.mirror import PALM_MIRROR, mirror_grasps, mirror_params
from ohra.errors import CheckpointError, GraspError, ObjectWarning, OhraError, ParamsError, require_seed, user_stacklevel
from ohra.learn.grasp.condition import HandCondition, HandLike, hand_key, resolve_hand
from ohra.learn.grasp.config import GraspModelConfig
from ohra.learn.grasp.diffusion import DDIMScheduler, Denoiser
from ohra.learn.grasp.encoder import make_encoder
from ohra.learn.grasp.joints import JointNet, clamp_joints
from ohra.learn.grasp.refine import RefineSettings, as_refine_settings, finger_clearance, refine_grasps
from ohra.objects.model import ObjectModel
from ohra.objects.resolve import resolve_object  # noqa: F401  (re-exported: ohra.learn.grasp.model.resolve_object)

MODEL_FORMAT = "ohra-grasp-model"
CHECKPOINT_FORMAT = "ohra-grasp-checkpoint"
DEFAULT_MODEL = "grasp_default"
CLOUD_SEED = 0  # surface sample of an object at inference (fixed: same object, same cloud)
N_JOINTS = 22
_Y_FLIP = np.diag(PALM_MIRROR)  # the reflection through an x-z plane as factors (S = M = diag(1, -1, 1))
ObjectLike = Union[ObjectModel, str, Path]


class GraspNet(nn.Module):
    """Object encoder, translation denoiser (x0 prediction) and joint network."""

    def __init__(self, cfg: GraspModelConfig, hand_dim: int):
        super().__init__()
        self.cfg = cfg
        self.hand_dim = int(hand_dim)
        self.encoder = make_encoder(cfg)
        self.cond_dim = cfg.object_dim + self.hand_dim + 6
        self.diffuse_joints = bool(cfg.diffuse_joints)
        x_dim = 3 + (N_JOINTS if self.diffuse_joints else 0)
        self.denoiser = Denoiser(self.cond_dim, tuple(cfg.denoiser_hidden), cfg.time_embed_dim, x_dim=x_dim)
        self.joints: JointNet | None = None
        if self.diffuse_joints:  # standardisation of the diffused joints (the training data's; in the state dict)
            self.register_buffer("q_mean", torch.zeros(N_JOINTS))
            self.register_buffer("q_std", torch.ones(N_JOINTS))
        else:
            self.joints = JointNet(self.cond_dim + 3, cfg.joint_hidden, cfg.joint_blocks)
        self.scheduler = DDIMScheduler(cfg.train_steps, cfg.inference_steps)

    def set_joint_statistics(self, q: np.ndarray, present: np.ndarray, floor: float = 0.05) -> None:
        """Per-joint mean and spread [rad] of training joints ``q`` (G, 22) over the rows where the joint is
        ``present`` (G, 22); a joint no row has keeps (0, 1), a spread under ``floor`` becomes ``floor``
        (a joint the data never moves would be divided by ~0). Only for ``diffuse_joints`` models."""
        if not self.diffuse_joints:
            raise GraspError("set_joint_statistics: this network has a joint network, not diffused joints")
        q, m = np.asarray(q, dtype=np.float64), np.asarray(present, dtype=bool)
        count = m.sum(axis=0)
        mean = np.where(count > 0, (q * m).sum(axis=0) / np.maximum(count, 1), 0.0)
        var = np.where(count > 0, (((q - mean) * m) ** 2).sum(axis=0) / np.maximum(count, 1), 1.0)
        std = np.where(count > 0, np.maximum(np.sqrt(var), floor), 1.0)
        self.q_mean.copy_(torch.from_numpy(mean.astype(np.float32)))
        self.q_std.copy_(torch.from_numpy(std.astype(np.float32)))

    def losses(self, obj_feat: torch.Tensor, hand: torch.Tensor, rot6d: torch.Tensor, t_norm: torch.Tensor,
               q: torch.Tensor, present: torch.Tensor, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """Training losses of a batch (B rows): SmoothL1 of the x0 estimate (normalised translation)
        at a uniformly random noise level, and SmoothL1 of the joints (present joints only): the joint
        network's [rad] given the true translation, or, with ``diffuse_joints``, the x0 estimate's joints
        in standardised units (the same noise level as the translation's)."""
        cond = torch.cat([obj_feat, hand, rot6d], dim=-1)
        b = len(cond)
        if self.diffuse_joints:  # an absent joint's value is no information: 0 standard units, whatever the data holds
            x_true = torch.cat([t_norm, torch.where(present, (q - self.q_mean) / self.q_std, 0.0)], dim=-1)
        else:
            x_true = t_norm
        # drawn on the CPU generator whatever the device: a batch's noise is the same on every device
        levels = torch.randint(0, self.scheduler.train_steps, (b,), generator=generator).to(t_norm.device)
        noise = torch.randn(x_true.shape, generator=generator).to(t_norm.device)
        x_t = self.scheduler.add_noise(x_true, noise, levels)
        x0 = self.denoiser(x_t, levels, self.denoiser.project_condition(cond))
        l_diff = F.smooth_l1_loss(x0[:, :3], t_norm)
        if self.diffuse_joints:
            err = F.smooth_l1_loss(x0[:, 3:], x_true[:, 3:], reduction="none")
        else:
            err = F.smooth_l1_loss(self.joints(torch.cat([cond, t_norm], dim=-1)), q, reduction="none")
        mask = present.float()
        l_joint = (err * mask).sum() / mask.sum().clamp_min(1.0)
        return {"diffusion": l_diff, "joints": l_joint}

    def sample_grasp(self, cond: torch.Tensor, generator: torch.Generator, lower: torch.Tensor | None = None,
                     upper: torch.Tensor | None = None, present: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, cond_dim) conditions -> (B, 3) normalised translations by DDIM and (B, 22) joints [rad]: the joint
        network's given the sampled translation (unclamped), or the diffused ones.

        Diffused joints: given the hand's limits ``lower``/``upper`` [rad] and ``present`` mask (22,), each step's x0
        estimate of the joints is held within the limits and an absent joint's at 0, its training value (the loss
        never trains those outputs, so left free they would carry untrained values into the next step's input);
        without them the joints are clipped at ``clip_sample`` standard units like the translation."""
        cond_h = self.denoiser.project_condition(cond)
        clip = self.cfg.clip_sample

        def predict(x: torch.Tensor, t: int) -> torch.Tensor:
            return self.denoiser.forward_level(x, t, cond_h)

        if not self.diffuse_joints:
            x = self.scheduler.sample(predict, (len(cond), 3), generator, clip=clip)
            return x, self.joints(torch.cat([cond, x], dim=-1))
        lo = torch.full((N_JOINTS,), -clip, device=self.q_mean.device) if lower is None else (lower - self.q_mean) / self.q_std
        up = torch.full((N_JOINTS,), clip, device=self.q_mean.device) if upper is None else (upper - self.q_mean) / self.q_std
        if present is not None:
            lo, up = torch.where(present, lo, 0.0), torch.where(present, up, 0.0)

        def bounded(x: torch.Tensor, t: int) -> torch.Tensor:
            x0 = predict(x, t)
            return torch.cat([x0[:, :3].clamp(-clip, clip), torch.maximum(torch.minimum(x0[:, 3:], up), lo)], dim=-1)

        x = self.scheduler.sample(bounded, (len(cond), self.denoiser.x_dim), generator)
        return x[:, :3], x[:, 3:] * self.q_std + self.q_mean


CENTRE_WARN = 0.1
"""[m] :meth:`GraspModel.sample` warns about objects whose bounding-box centre lies farther than this
from their mesh frame's origin (the YCB meshes in ``../shared/objects``, some of which the shipped models
trained on, lie 0.8-9.7 cm off; procedural objects 0)."""


SUPPORT_MARGIN = 0.5
"""How far (condition units) a hand's condition may lie outside the training hands' range in any entry before
:meth:`GraspModel.sample` warns that the hand is unseen (:class:`~ohra.learn.encoding.OutOfSupportWarning`).
Units: the VAE latent (prior standard deviation 1) for ``vae`` models, the training hands' spread for ``params``
ones. Measured on the shipped models: mirror twins of training hands and held-out LEAP variants lie 0-0.25 out;
the registered hands neither model trained on 0.56-2.5 (``default``: LEAP 0.56-0.90, Dex3, Gaia, Inspire, Sharpa,
Ability 1.3-2.5) and 4.4-13.6 (``leap``: every non-LEAP-template hand, the parsed LEAP hand included)."""


def object_offset(obj: ObjectModel) -> np.ndarray:
    """(3,) [m] the centre of ``obj``'s mesh bounding box in its mesh frame."""
    b = np.asarray(obj.mesh.bounds, dtype=float)
    return 0.5 * (b[0] + b[1])


def nearest_surface(params: Any, obj: ObjectModel, candidates: np.ndarray) -> np.ndarray:
    """Of grasps (n, k, 31), per row the one whose fingers' smallest signed distance to ``obj``
    (:func:`~ohra.learn.grasp.refine.finger_clearance`) is nearest zero (n, 31): neither sunk into the
    object nor hovering off it."""
    n, k, _ = candidates.shape
    d = finger_clearance(params, obj, candidates.reshape(n * k, -1)).reshape(n, k)
    return candidates[np.arange(n), np.abs(d).argmin(axis=1)]


def as_rotations(rotations: Any, n: int) -> np.ndarray:
    """(n, 3, 3) rotation matrices from matrices (n, 3, 3), rot6d (n, 6) or a scipy ``Rotation`` (for ``n`` = 1
    also one (3, 3) or (6,)). Matrices within 1e-4 of orthonormal are replaced by the nearest rotation (SVD), so the
    grasps' rot6d columns are orthonormal whatever rounding the caller's matrices carry."""
    from scipy.spatial.transform import Rotation

    if isinstance(rotations, Rotation):
        rotations = rotations.as_matrix()
    try:
        r = np.asarray(rotations)
        complex_ = np.iscomplexobj(r)  # float() would drop the imaginary part with only a ComplexWarning
        r = r.real.astype(float) if complex_ else r.astype(float)
    except (TypeError, ValueError):
        raise GraspError(f"rotations: expected numbers, got {type(rotations).__name__}") from None
    if complex_:
        raise GraspError("rotations: expected real numbers, got complex ones")
    given = r.shape  # named in the error as the caller passed it, not as converted below
    if n == 1 and r.shape in ((3, 3), (6,)):  # one rotation for one grasp, as a matrix or as rot6d
        r = r[None]
    if r.ndim == 2 and r.shape[1] == 6:
        from ohra.rotations import rot6d_to_matrix

        if not np.all(np.isfinite(r)):
            raise GraspError("rotations contain NaN or infinity")
        r = rot6d_to_matrix(r)
    if r.ndim != 3 or r.shape[1:] != (3, 3) or len(r) != n:
        raise GraspError(f"rotations: expected shape ({n}, 3, 3) or ({n}, 6), got {given}")
    if not np.all(np.isfinite(r)):
        raise GraspError("rotations contain NaN or infinity")
    err = np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((err > 1e-4) | (np.linalg.det(r) < 0))
    if bad.size:
        raise GraspError(f"rotations[{int(bad[0])}] is not a rotation matrix (orthonormal, det +1)")
    off = np.flatnonzero(err > 1e-12)  # exact ones stay bit for bit (a given rotation reproduces earlier runs)
    if off.size:
        u, _, vt = np.linalg.svd(r[off])  # the nearest rotations: the grasps' rot6d is orthonormal to float precision
        r = r.copy()
        r[off] = u @ vt
    return r


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3, 3) uniformly random rotations (normalised Gaussian quaternions)."""
    from ohra.rotations import quat_to_matrix

    qs = rng.normal(size=(n, 4))
    return quat_to_matrix(qs / np.linalg.norm(qs, axis=1, keepdims=True))




@dataclass
class GraspModel:
    """A trained grasp model ready to sample (eval mode)."""

    net: GraspNet
    condition: HandCondition
    t_scale: float  # m; translations are divided by it before diffusion
    config: GraspModelConfig
    meta: dict[str, Any] = field(default_factory=dict)  # training hands/objects, data digest, ...
    path: Path | None = None
    # torch threads while sampling (then restored): the networks are small, so one thread is as fast
    # as several on an idle machine and far steadier on a busy one (2 threads on a loaded 2-core
    # machine: 50-1500 ms for 100 grasps; 1 thread: 30-60 ms)
    threads: int = 1
    _clouds: dict[str, torch.Tensor] = field(default_factory=dict, repr=False)
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)  # derived: training-hand conditions, mirror decisions and images

    def __post_init__(self) -> None:
        self.net.eval()

    def __repr__(self) -> str:  # the dataclass default would print every layer
        hands = self.meta.get("hands") if isinstance(self.meta, dict) else None
        hands = list(hands or [])
        shown = (f", hands={hands}" if len(hands) <= 4 else f", {len(hands)} hands ({hands[0]} ... {hands[-1]})") if hands else ""
        return (f"GraspModel(condition={self.condition.kind!r}, encoder={self.config.encoder!r}, "
                f"parameters={sum(p.numel() for p in self.net.parameters()):,}{shown}, path={str(self.path) if self.path else None!r})")

    # -- inputs ---------------------------------------------------------------------------------------
    def object_cloud(self, obj: ObjectModel) -> torch.Tensor:
        """(n_points, 3) float32 surface points of ``obj`` (mesh frame), fixed per object."""
        key = obj.mesh_hash
        if key not in self._clouds:
            pts, _ = obj.sample_surface(self.config.n_points, seed=CLOUD_SEED)
            self._clouds[key] = torch.from_numpy(np.asarray(pts, dtype=np.float32))
        return self._clouds[key]

    # -- sampling -------------------------------------------------------------------------------------
    def sample(self, hand: HandLike, obj: ObjectLike, n: int, rotations: Any = None, seed: int = 0,
               timing: dict | None = None, condition_hand: HandLike | None = None,
               refine: bool | RefineSettings = False, centre: bool = False, candidates: int = 1,
               mirror: bool | str = "auto", name: str | None = None) -> np.ndarray:
        """``n`` grasps of ``hand`` on ``obj`` (see the module docstring).

        Args:
            hand: a registered hand or LEAP variant name, a params JSON path, or params. A model with the
                ``vae`` condition needs a hand with a base form.
            obj: the object (:func:`resolve_object`); its mesh frame is the frame of the grasps.
            n: number of grasps, >= 1.
            rotations: wrist rotations ``R_obj_palm`` (palm frame in the object mesh frame): (n, 3, 3)
                matrices, (n, 6) rot6d (orthonormalised), or a scipy ``Rotation``; None draws uniformly
                random ones from ``seed``.
            seed: the same seed (and inputs) gives the same grasps.
            timing: if a dict, receives ``seconds`` (wall time of the sampling itself, rotations to
                joints) and, with ``refine``, ``refine_seconds``.
            condition_hand: condition the model on another hand's parameters while the joints stay
                clamped to ``hand``'s limits (the paper's wrong-condition study, Table 9).
            refine: True (default settings) or :class:`~ohra.learn.grasp.refine.RefineSettings`: open the
                fingers just enough to clear the object (:func:`~ohra.learn.grasp.refine.refine_grasps`).
            centre: sample on the object moved so that its bounding-box centre is at the origin, then move
                the grasps back (they stay in the mesh frame). The network sees surface points in the mesh
                frame, and its training objects lay within :data:`CENTRE_WARN` of their frame's origin; a
                mesh in scene coordinates (its origin far from the object) gets grasps in the wrong place
                unless centred. Off by default (the published numbers were sampled without it); a warning
                names objects farther off than that.
            candidates: draw this many grasps per wrist rotation (other diffusion noise, the same rotation)
                and keep the one whose fingers lie nearest the object's surface: the smallest absolute
                finger-object signed distance (capsule cores sampled as in
                :func:`~ohra.learn.grasp.refine.refine_grasps`), so neither sunk nor hovering. For a
                rotation the model's translations spread by ~1 cm, and sunk fingers fail the test
                (README, *Grasp model*). 1 (default): the first draw, as before the option existed.
            mirror: sample the hand's mirror image on the mirrored object and mirror the grasps back
                (:mod:`ohra.canonical.mirror`; physics is mirror-symmetric, so a right-hand grasp of the
                mirrored object is a left-hand grasp of the object): True, False, or ``"auto"`` (default):
                mirror when the mirror image lies nearer the model's training hands than the hand itself
                (:meth:`mirrors`), so a model trained on right hands grasps with their left twins. Hands
                the model trained on, and hands more like them than their mirror images, are sampled as
                they are. With ``condition_hand`` the decision is made on that hand, and both are mirrored.
            name: how a warning names ``hand`` (default: ``hand`` when it is a name or path); a hand outside the
                model's training hands gets one (:meth:`support_warning`).

        Returns:
            (n, 31) float64 grasps ``[t (3), rot6d (6), q (22)]``: ``t`` the palm-frame origin in the
            object mesh frame [m], ``rot6d`` the first two columns of ``R_obj_palm``, ``q`` the canonical
            joint angles [rad] within ``hand``'s limits (absent joints 0).

        Raises:
            GraspError: ``n`` or ``candidates`` is not a positive integer; ``seed`` not a whole number >= 0;
                ``rotations`` of the wrong shape, non-finite, or not rotations; ``mirror`` none of True, False,
                ``"auto"``.
            ObjectError: ``obj`` cannot be resolved to one object.
            HandNotFoundError: an unknown hand name or a missing params file.
            ParamsError: ``hand`` (or ``condition_hand``) of another type, or without a base form for a
                ``vae``-conditioned model.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise GraspError(f"n must be a positive integer, got {n!r}")
        n = int(n)
        if isinstance(candidates, bool) or not isinstance(candidates, (int, np.integer)) or candidates < 1:
            raise GraspError(f"candidates must be a positive integer, got {candidates!r}")
        k = int(candidates)
        if not isinstance(centre, (bool, np.bool_)):  # "no" would centre the object
            raise GraspError(f"centre must be True or False, got {centre!r}")
        seed = require_seed(seed, GraspError)
        params = resolve_hand(hand)
        obj = resolve_object(obj)
        self.object_warnings(obj, centre)
        offset = object_offset(obj)
        shift = offset if centre else np.zeros(3)
        rng = np.random.default_rng(seed)
        rots = random_rotations(n, rng) if rotations is None else as_rotations(rotations, n)
        t0 = time.perf_counter()
        cond_params = params if condition_hand is None else resolve_hand(condition_hand)
        flip = self.mirrors(cond_params, mirror)
        net_params, signs = params, None
        if flip:  # the networks see the mirror images; the grasps are mirrored back below
            net_params, signs, cond_params = self._mirrored(params, cond_params)
            rots = rots * _Y_FLIP[:, None] * _Y_FLIP  # S R M
            shift = shift * _Y_FLIP
        self.support_warning(cond_params, (hand if name is None else name) if condition_hand is None else condition_hand, flip)
        hand_vec = torch.from_numpy(self.condition.vector(cond_params).astype(np.float32))
        lower = torch.from_numpy(np.asarray(net_params.joint_lowers, dtype=np.float32))
        upper = torch.from_numpy(np.asarray(net_params.joint_uppers, dtype=np.float32))
        r6 = np.concatenate([rots[:, :, 0], rots[:, :, 1]], axis=1)
        if k > 1:  # rotation-major: the candidates of rotation i are rows i*k .. i*k+k-1
            r6 = np.repeat(r6, k, axis=0)
        gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
        old_threads = torch.get_num_threads()
        if self.threads and self.threads != old_threads:
            torch.set_num_threads(int(self.threads))
        try:
            feat, x, q = self._run(obj, hand_vec, r6, lower, upper, gen, shift, mirror=flip,
                                   present=torch.from_numpy(np.asarray(net_params.present_joints, dtype=bool)))
        finally:
            if torch.get_num_threads() != old_threads:
                torch.set_num_threads(old_threads)
        out = np.concatenate([x.double().numpy() * self.t_scale + shift, r6, q.double().numpy()], axis=1)  # in the mesh frame
        if signs is not None:
            out = mirror_grasps(out, signs)
        # clamp again in float64: a float32 limit can lie a hair outside the float64 one
        out[:, 9:] = np.clip(out[:, 9:], params.joint_lowers, params.joint_uppers)
        if k > 1:
            out = nearest_surface(params, obj, out.reshape(n, k, 31))
        if timing is not None:
            timing["seconds"] = time.perf_counter() - t0
        if (settings := as_refine_settings(refine)) is not None:
            t1 = time.perf_counter()
            out = refine_grasps(params, obj, out, settings).grasps
            if timing is not None:
                timing["refine_seconds"] = time.perf_counter() - t1
        return out

    def object_warnings(self, obj: ObjectModel, centre: bool = False) -> None:
        """Warn (:class:`~ohra.errors.ObjectWarning`, once per object and model) when ``obj`` is outside the graspable
        size range (:func:`~ohra.objects.resolve.size_problem`: a mesh in millimetres, say; the warning names the
        scale that fixes it) or, when not ``centre``, lies farther than :data:`CENTRE_WARN` from its mesh frame's origin.
        A mis-scaled mesh gets only the size warning: its offset is in the wrong units too. :meth:`sample` calls it."""
        from ohra.objects.resolve import warn_if_ungraspable

        key = f"warned:{obj.mesh_hash}:{bool(centre)}"
        if key in self._cache:
            return
        self._cache[key] = True
        offset = float(np.linalg.norm(object_offset(obj)))
        if not warn_if_ungraspable(obj) and not centre and offset > CENTRE_WARN:  # a mis-scaled mesh: the size only
            warnings.warn(f"object {obj.name!r}: its bounding-box centre lies {100 * offset:.1f} cm from its "
                          f"mesh frame's origin, over {100 * CENTRE_WARN:g} cm (the shipped models' training objects lie "
                          "within that): grasps sampled in that frame can miss the object; pass centre=True (--centre)", ObjectWarning,
                          stacklevel=user_stacklevel())

    def support(self, hand: HandLike, mirror: bool | str = "auto") -> tuple[float, int] | None:
        """How far ``hand`` (as :meth:`sample` conditions on it: mirrored when ``mirror`` says so) lies outside the
        hands this model trained on: (largest excess over the training conditions' range, in condition units;
        number of entries more than :data:`SUPPORT_MARGIN` out), or None when no training hand resolves here."""
        params = resolve_hand(hand)
        flip = self.mirrors(params, mirror)
        return self._support(self._mirrored(params, params)[2] if flip else params)

    def _support(self, cond_params: Any) -> tuple[float, int] | None:
        train = self._training_conditions()
        if train is None:
            return None
        c = self.condition.vector(cond_params)
        excess = np.maximum(train.min(axis=0) - c, 0.0) + np.maximum(c - train.max(axis=0), 0.0)
        return float(excess.max()), int(np.count_nonzero(excess > SUPPORT_MARGIN))

    def support_warning(self, cond_params: Any, label: Any, flipped: bool = False) -> None:
        """Warn (:class:`~ohra.learn.encoding.OutOfSupportWarning`, once per hand and model) when the condition
        :meth:`sample` gives the networks lies more than :data:`SUPPORT_MARGIN` outside the training hands' range:
        the grasps of such a hand are a zero-shot guess the model's training says little about (README, *Grasp
        model*: the shipped default model on the Ability and SVH hands)."""
        from ohra.learn.encoding import OutOfSupportWarning

        key = "support:" + hand_key(cond_params)
        if key in self._cache:
            return
        self._cache[key] = True
        try:
            found = self._support(cond_params)
        except ParamsError:  # sample() raises it, naming the hand, just after
            return
        if found is None or found[1] == 0:
            return
        worst, count = found
        hands = list(self.meta.get("hands") or [])
        named = ", ".join(hands) if len(hands) <= 4 else f"{len(hands)} hands, {hands[0]} ... {hands[-1]}"
        units = "latent units" if self.condition.kind == "vae" else "training spreads"
        label = label if isinstance(label, (str, Path)) else f"{type(label).__name__}({label.num_fingers} fingers)"
        warnings.warn(f"hand {str(label)!r}{' (as its mirror image)' if flipped else ''} lies outside the hands this grasp "
                      f"model trained on ({named}): {count} of {len(self.condition.vector(cond_params))} condition "
                      f"entries beyond their range, by up to {worst:.2f} {units}; its grasps are a zero-shot guess "
                      "(evaluate them before use)", OutOfSupportWarning, stacklevel=user_stacklevel())

    def _run(self, obj: ObjectModel, hand_vec: torch.Tensor, r6: np.ndarray, lower: torch.Tensor, upper: torch.Tensor,
             gen: torch.Generator, shift: np.ndarray | None = None, mirror: bool = False,
             present: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The networks: object feature, normalised translations (n, 3), clamped joints (n, 22); the
        object's surface points are seen reflected through the mesh frame's x-z plane when ``mirror``, then
        moved by ``-shift`` [m] (translations come out in that frame)."""
        n = len(r6)
        cloud = self.object_cloud(obj)
        if mirror:
            cloud = cloud * torch.tensor(_Y_FLIP, dtype=cloud.dtype)
        if shift is not None and np.any(shift):
            cloud = cloud - torch.from_numpy(np.asarray(shift, dtype=np.float32))
        with torch.inference_mode():
            feat = self.net.encoder(cloud[None])
            cond = torch.cat([feat.expand(n, -1), hand_vec.expand(n, -1), torch.from_numpy(r6.astype(np.float32))], dim=-1)
            x, q = self.net.sample_grasp(cond, gen, lower, upper, present)
            q = clamp_joints(q, lower, upper)
        if not (torch.isfinite(x).all() and torch.isfinite(q).all()):  # clamping passes NaN through
            where = f" ({self.path})" if self.path else ""
            raise CheckpointError(f"the grasp model{where} computes non-finite grasps: its weights hold NaN or infinity "
                                  "(a diverged training run?)")
        return feat, x, q

    # -- handedness -------------------------------------------------------------------------------------
    def mirrors(self, hand: HandLike, mirror: bool | str = "auto") -> bool:
        """Whether :meth:`sample` (``mirror=``) samples ``hand`` as its mirror image.

        ``"auto"``: when the mirror image's condition vector lies strictly nearer (Euclidean) the nearest
        training hand's than the hand's own; never when none of the training hands in ``meta["hands"]``
        resolves here (a hand by a path that is gone) or the mirror image cannot be conditioned on.

        Raises:
            GraspError: ``mirror`` is none of True, False (numpy bools too), ``"auto"``.
        """
        if isinstance(mirror, (bool, np.bool_)) or (isinstance(mirror, np.ndarray) and mirror.shape == ()
                                                     and mirror.dtype == bool):  # e.g. the `mirrored` of a grasp file
            return bool(mirror)
        if not (isinstance(mirror, str) and mirror == "auto"):
            raise GraspError(f"mirror: expected True, False or 'auto', got {mirror!r}")
        train = self._training_conditions()
        if train is None:
            return False
        params = resolve_hand(hand)
        key = "mirrors:" + hand_key(params)  # the decision is a function of the parameters: made once per hand
        if key not in self._cache:
            try:
                own = self.condition.vector(params)
                image = self.condition.vector(self._mirrored(params, params)[2])
            except ParamsError:
                self._cache[key] = False
            else:
                nearest = lambda c: float(np.min(np.linalg.norm(train - c, axis=1)))  # noqa: E731
                self._cache[key] = nearest(image) < nearest(own)
        return self._cache[key]

    def _mirrored(self, params: Any, cond_params: Any) -> tuple[Any, np.ndarray, Any]:
        """Mirror images of the hand and of the condition hand, and the hand's joint signs (cached per pair of
        hands: :meth:`sample` asks on every call). A VAE-conditioned model mirrors the base form when there is
        one: the VAE reads base-form hands, and the mirror image of an extended hand need not have a base form."""
        key = "mirrored:" + hand_key(params) + ":" + hand_key(cond_params)
        if key not in self._cache:
            self._cache[key] = self._mirror_images(params, cond_params)
        return self._cache[key]

    def _mirror_images(self, params: Any, cond_params: Any) -> tuple[Any, np.ndarray, Any]:
        if self.condition.kind == "vae":
            try:
                params = self.condition.vae_form(params)
            except ParamsError:  # told another hand (condition_hand): the true one keeps its own form
                pass
            cond_params = self.condition.vae_form(cond_params)
        image = mirror_params(params)
        return image.params, image.signs, (image.params if cond_params is params else mirror_params(cond_params).params)

    def _training_conditions(self) -> np.ndarray | None:
        """(H, dim) condition vectors of the training hands: as training recorded them (``meta["train_conditions"]``),
        else (models saved before it did) those of the hands named in ``meta["hands"]`` that resolve here."""
        if "_train_conditions" not in self._cache:
            recorded = self.meta.get("train_conditions") if isinstance(self.meta, dict) else None
            if recorded:
                table = np.asarray(recorded, dtype=float)
                if table.ndim == 2 and table.shape[1] == self.condition.dim:
                    self._cache["_train_conditions"] = table
                    return table
            rows = []
            for name in (self.meta.get("hands") or []) if isinstance(self.meta, dict) else []:
                try:
                    rows.append(self.condition.vector(resolve_hand(name)))
                except OhraError:
                    continue
            self._cache["_train_conditions"] = np.stack(rows) if rows else None
        return self._cache["_train_conditions"]

    # -- persistence ----------------------------------------------------------------------------------
    def payload(self) -> dict[str, Any]:
        return {
            "format": MODEL_FORMAT, "version": 1, "model_config": self.config.to_dict(),
            "hand_dim": self.net.hand_dim, "model": self.net.state_dict(), "condition": self.condition.state(),
            "t_scale": float(self.t_scale), "meta": json.dumps(self.meta),
        }

    def save(self, folder: str | Path) -> Path:
        """Write ``model.pt`` (weights, condition, scale) and ``config.json`` into ``folder``."""
        from ohra.io import write_text
        from ohra.learn.train_vae import atomic_save

        folder = Path(folder)
        atomic_save(self.payload(), folder / "model.pt")
        write_text(folder / "config.json", json.dumps({"model": self.config.to_dict(), "meta": self.meta}, indent=1) + "\n")
        return folder / "model.pt"


def model_from_payload(obj: dict[str, Any], where: str) -> GraspModel:
    """A :class:`GraspModel` from a ``model.pt`` or training-checkpoint dict."""
    try:
        cfg = GraspModelConfig.from_dict(obj["model_config"])
        cond = HandCondition.from_state(obj["condition"], where)
        net = GraspNet(cfg, int(obj["hand_dim"]))
        net.load_state_dict(obj["model"])
        meta = json.loads(obj.get("meta", "{}"))
        t_scale = float(obj["t_scale"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{where}: incompatible grasp model ({type(exc).__name__}: {str(exc).splitlines()[0][:160]})") from None
    if cond.dim != net.hand_dim:
        raise CheckpointError(f"{where}: hand condition has {cond.dim} numbers, the network expects {net.hand_dim}")
    return GraspModel(net, cond, t_scale, cfg, meta, Path(where))


SHIPPED_MODELS = {"default": DEFAULT_MODEL, "leap": "grasp_leap"}
"""Grasp models shipped in ``ohra/learn/models``, by the name ``load_grasp_model`` and ``--model`` take:
``default``: the unified model (frozen-VAE condition; Allegro, Barrett, Shadow; base-form hands only);
``leap``: the zero-shot study's all-data model (raw-parameter condition; 66 LEAP variants; any hand)."""


def default_model_dir(name: str = "default") -> Path:
    return Path(str(resources.files("ohra.learn").joinpath("models", SHIPPED_MODELS[name])))


def load_grasp_model(path: str | Path | None = None) -> GraspModel:
    """Load a grasp model, ready to sample (eval mode).

    Args:
        path: a shipped model by name (``None`` or ``"default"``, ``"leap"``: see :data:`SHIPPED_MODELS`;
            an existing folder of that name wins), a run or model directory (its ``model.pt``, else
            ``checkpoints/last.pt``), or a ``.pt`` file (``model.pt`` or a training checkpoint).

    Returns:
        :class:`GraspModel` with its network, hand condition, translation scale ``t_scale`` [m] and
        training metadata ``meta``.

    Raises:
        CheckpointError: ``path`` of another type; the shipped model is missing; no model file there; a corrupt, foreign or
            other-version file; weights or hand condition that do not fit the stored config.
    """
    from ohra.learn.train_vae import load_torch_file

    if path is not None and not isinstance(path, (str, Path)):
        raise CheckpointError(f"a grasp model is a shipped name ({', '.join(SHIPPED_MODELS)}), a folder or a .pt file, "
                              f"got {type(path).__name__}")
    shipped = path is None or (isinstance(path, str) and path in SHIPPED_MODELS and not Path(path).exists())
    p = default_model_dir(path or "default") if shipped else Path(path)
    if shipped and not (p / "model.pt").is_file():
        raise CheckpointError(f"no grasp model is shipped with this ohra ({p / 'model.pt'} is missing); "
                              "train one with `ohra train grasp` and load its run directory")
    f = p
    if p.is_dir():
        f = p / "model.pt"
        if not f.is_file() and (p / "checkpoints" / "last.pt").is_file():
            f = p / "checkpoints" / "last.pt"
    if not f.is_file():
        raise CheckpointError(f"no grasp model at {p} (expected model.pt or checkpoints/last.pt)")
    try:
        obj = load_torch_file(f, MODEL_FORMAT)
    except CheckpointError as first:
        try:
            obj = load_torch_file(f, CHECKPOINT_FORMAT)
        except CheckpointError as second:
            if "expected an" not in str(second):  # corrupt, other version: that message says it all
                raise
            # neither a model nor a checkpoint: name both grasp formats, not only the last one tried
            raise CheckpointError(str(first).replace(f"an {MODEL_FORMAT!r} file",
                                                     f"a grasp model ({MODEL_FORMAT!r} or {CHECKPOINT_FORMAT!r})")) from None
    if obj.get("format") == CHECKPOINT_FORMAT:  # a run without model.pt: stopped, or still training
        steps = (obj.get("spec") or {}).get("train", {}).get("steps")
        if steps is not None and int(obj.get("step", 0)) < int(steps):
            warnings.warn(f"{f}: a training checkpoint at step {int(obj['step'])} of {int(steps)} (the run has not "
                          "finished: resume it with --resume for the trained model)", UserWarning,
                          stacklevel=user_stacklevel())
    return model_from_payload(obj, str(f))


__all__ = ["GraspNet", "GraspModel", "load_grasp_model", "model_from_payload", "as_rotations", "random_rotations",
           "MODEL_FORMAT", "CHECKPOINT_FORMAT"]
