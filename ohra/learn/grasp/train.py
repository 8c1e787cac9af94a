"""Training of the grasp model: seeded, deterministic, resumable, with a metrics JSON.

A run directory holds::

    config.json            data directories, model and training settings
    checkpoints/last.pt    network + optimiser + step + loss history + condition + scale (every
                           ``checkpoint_every`` steps and at the end; written atomically)
    model.pt               the trained model (what :func:`load_grasp_model` reads)
    metrics.json           loss history, final and held-out losses, throughput, data summary

Determinism: on CPU with a fixed thread count, the same settings and data give bit-identical
weights. Batch ``s`` and its diffusion noise come from ``(seed, s)`` only and the learning rate is
a function of ``s`` (cosine from ``lr`` to ``lr_min`` over ``steps``), so the checkpoint needs no
random state and a resumed run equals an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch

from ohra.errors import CheckpointError, GraspError, ParamsError
from ohra.learn.grasp.condition import HandCondition
from ohra.learn.grasp.config import GraspConfigError, GraspModelConfig, GraspTrainConfig, RunSpec
from ohra.learn.grasp.contact import FingerCapsules, SDFGrids, contact_gap, penetration
from ohra.learn.grasp.data import TrainingData, make_batch
from ohra.learn.grasp.model import CHECKPOINT_FORMAT, GraspModel, GraspNet
from ohra.interrupts import DeferredStop
from ohra.io import folder_lock, write_text
from ohra.learn.train_vae import _peak_rss_mib, atomic_save, load_torch_file, torch_settings
from ohra.objects.model import ObjectModel

LOSS_TERMS = ("total", "diffusion", "joints")  # plus "penetration" and "contact" when those terms are on
TEST_SEED = 7919  # noise levels of the held-out loss (fixed, so it compares across runs)


@dataclass
class GraspTrainResult:
    model: GraspModel
    metrics: dict[str, Any]
    run_dir: Path | None


def learning_rate(cfg: GraspTrainConfig, step: int) -> float:
    """Cosine annealing from ``lr`` (step 0) to ``lr_min`` (step ``steps``)."""
    return cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1.0 + math.cos(math.pi * min(step, cfg.steps) / cfg.steps))


def _tables(cond: HandCondition, data: TrainingData) -> tuple[torch.Tensor, torch.Tensor]:
    rows = []
    for name, p in zip(data.hands, data.params):
        try:
            rows.append(cond.vector(p))
        except ParamsError as exc:  # the condition's sampling advice does not fit training: name the hand and the option
            raise GraspConfigError(f"training hand {name!r} cannot be {cond.kind}-conditioned ({str(exc).split(';')[0]}); "
                                   "train with condition='params' (--condition params) or hold the hand out") from None
    if cond.kind == "vae":
        _warn_outside_vae(cond, data)
    hand = torch.from_numpy(np.stack(rows).astype(np.float32))
    present = torch.from_numpy(np.stack([p.present_joints for p in data.params]))
    return hand, present


def _warn_outside_vae(cond: HandCondition, data: TrainingData) -> None:
    """Name each training hand outside the VAE's training support (as ``ohra vae encode`` does): its latent, the
    condition the model learns it by, may not tell it from the hands the VAE knows."""
    import warnings

    from ohra.errors import user_stacklevel
    from ohra.learn.encoding import OutOfSupportWarning
    from ohra.learn.sampler import support_violations, violations_text

    for name, p in zip(data.hands, data.params):
        why = support_violations(cond.vae_form(p))
        if why:
            warnings.warn(f"training hand {name!r} lies outside the hands the VAE was trained on ({violations_text(why)}): "
                          "its latent condition may not tell it from them (condition='params', --condition params, "
                          "conditions on the parameters instead)",
                          OutOfSupportWarning, stacklevel=user_stacklevel())


def torch_device(name: str) -> torch.device:
    """The torch device ``name``, or :class:`GraspConfigError` when this machine has none such."""
    try:
        dev = torch.device(name)
    except RuntimeError as exc:
        raise GraspConfigError(f"device {name!r}: {exc}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise GraspConfigError(f"device {name!r}: this torch ({torch.__version__}) sees no CUDA GPU")
    if dev.type == "cuda" and (dev.index or 0) >= torch.cuda.device_count():
        raise GraspConfigError(f"device {name!r}: this machine has {torch.cuda.device_count()} CUDA GPU(s)")
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise GraspConfigError(f"device {name!r}: MPS is not available on this machine")
    return dev


def _check_resume(ckpt: dict[str, Any], spec: RunSpec, digest: str, path: Path) -> None:
    old = ckpt["spec"]
    old_model = {**GraspModelConfig().to_dict(), **old["model"]}  # settings added since the checkpoint: their defaults
    if old_model != spec.model.to_dict():
        new_model = spec.model.to_dict()
        diff = [f"{k}={old_model.get(k)!r}, this run asks for {new_model.get(k)!r}"
                for k in sorted(set(old_model) | set(new_model)) if old_model.get(k) != new_model.get(k)]
        raise CheckpointError(f"{path}: cannot resume, the checkpoint's model was made with {'; '.join(diff)}")
    new_train = spec.train.to_dict()
    defaults = GraspTrainConfig().to_dict()  # settings added since the checkpoint was made: their defaults
    for f in fields(GraspTrainConfig):
        if f.name not in GraspTrainConfig.RESUMABLE_CHANGES and old["train"].get(f.name, defaults[f.name]) != new_train[f.name]:
            raise CheckpointError(f"{path}: cannot resume, the checkpoint was trained with {f.name}="
                                  f"{old['train'].get(f.name)!r}, this run asks for {new_train[f.name]!r}")
    if ckpt.get("data_digest") != digest:
        raise CheckpointError(f"{path}: training data differ from the checkpoint's (digest mismatch)")
    if int(ckpt["step"]) > spec.train.steps:
        raise CheckpointError(f"{path}: checkpoint is at step {ckpt['step']}, beyond the requested {spec.train.steps} steps")


def _payload(model: GraspModel, opt: torch.optim.Optimizer, spec: RunSpec, step: int, history: list, digest: str,
             window: tuple[dict[str, float], int]) -> dict:
    # ``window``: loss sums and count since the last history entry (a checkpoint can fall between two)
    return {**model.payload(), "format": CHECKPOINT_FORMAT, "spec": spec.to_dict(), "optimizer": opt.state_dict(),
            "step": int(step), "history": history, "data_digest": digest,
            "window": {"sums": dict(window[0]), "count": int(window[1])}}


@dataclass
class ContactTerm:
    """The finger-object terms of :mod:`ohra.learn.grasp.contact` (penetration, two-sided contact) for the
    hands and objects of a training set; a term of weight 0 is not computed."""

    caps: FingerCapsules
    sdf: SDFGrids
    weight: float  # penetration
    shift: float  # m
    t_scale: float  # m
    contact_weight: float = 0.0
    contact_form: str = "capped"

    @classmethod
    def for_data(cls, td: TrainingData, cfg: GraspTrainConfig, t_scale: float) -> "ContactTerm":
        return cls(FingerCapsules(td.params, td.hands), SDFGrids.from_objects(td.objects), float(cfg.penetration_weight),
                   float(cfg.penetration_shift), float(t_scale), float(cfg.contact_weight), cfg.contact_form)

    def weights(self) -> dict[str, float]:
        return {k: w for k, w in (("penetration", self.weight), ("contact", self.contact_weight)) if w > 0}

    def __call__(self, net: GraspNet, feats: torch.Tensor, batch) -> dict[str, torch.Tensor]:
        """The terms for the joint network's joints at each row's palm (shifted when ``shift`` > 0; the shift
        is drawn from the batch's generator after the diffusion noise, so runs without it keep theirs)."""
        t_obj, t_in = batch.t_obj, batch.t_norm
        if self.shift > 0:
            delta = torch.randn(t_obj.shape, generator=batch.generator) * self.shift  # object frame [m]
            t_obj = t_obj + delta
            t_in = t_in + torch.einsum("bij,bj->bi", batch.R_cloud, delta) / self.t_scale
        q_hat = net.joints(torch.cat([feats, batch.hand, batch.rot6d, t_in], dim=-1))
        out = {}
        if self.weight > 0:
            out["penetration"] = penetration(self.caps, self.sdf, batch.hand_idx, batch.obj_idx, q_hat, t_obj, batch.R_obj_palm)[0]
        if self.contact_weight > 0:
            out["contact"] = contact_gap(self.caps, self.sdf, batch.hand_idx, batch.obj_idx, q_hat, t_obj, batch.q,
                                         batch.t_obj, batch.R_obj_palm, form=self.contact_form)
        return out


def loss_terms(cfg: GraspTrainConfig) -> tuple[str, ...]:
    """The loss terms a run logs."""
    return (LOSS_TERMS + (("penetration",) if cfg.penetration_weight > 0 else ())
            + (("contact",) if cfg.contact_weight > 0 else ()))


def train_step(net: GraspNet, batch, joint_weight: float, contact: ContactTerm | None = None) -> dict[str, torch.Tensor]:
    """Losses of one batch: each cloud encoded once, its feature shared by the rows that use it."""
    feats = net.encoder(batch.clouds)[batch.cloud_idx]
    terms = net.losses(feats, batch.hand, batch.rot6d, batch.t_norm, batch.q, batch.present, batch.generator)
    terms["total"] = terms["diffusion"] + joint_weight * terms["joints"]
    if contact is not None:
        extra = contact(net, feats, batch)
        for name, w in contact.weights().items():
            terms[name] = extra[name]
            terms["total"] = terms["total"] + w * extra[name]
    return terms


@torch.no_grad()
def heldout_losses(model: GraspModel, data: TrainingData, objects: Mapping[str, ObjectModel]) -> dict[str, dict[str, float]]:
    """Mean losses on the held-out grasps of the training hands (objects never trained on)."""
    out: dict[str, dict[str, float]] = {}
    for (hand, name), g in sorted(data.test_grasps.items()):
        if hand not in data.hands or name not in objects or len(g) == 0:
            continue
        p = data.params[data.hands.index(hand)]
        n = len(g)
        cloud = model.object_cloud(objects[name])
        feat = model.net.encoder(cloud[None]).expand(n, -1)
        hvec = torch.from_numpy(model.condition.vector(p).astype(np.float32)).expand(n, -1)
        f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
        present = torch.from_numpy(np.asarray(p.present_joints)).expand(n, -1)
        terms = model.net.losses(feat, hvec, f32(g[:, 3:9]), f32(g[:, :3] / model.t_scale), f32(g[:, 9:]), present,
                                 torch.Generator().manual_seed(TEST_SEED))
        out[f"{hand}/{name}"] = {k: float(v) for k, v in terms.items()} | {"n": n}
    return out


@dataclass
class _State:
    """Everything a training loop reads and advances."""

    td: TrainingData
    model: GraspModel
    opt: torch.optim.Optimizer
    tables: tuple[torch.Tensor, torch.Tensor]  # hand conditions, presence masks (per training hand)
    step: int = 0
    history: list = field(default_factory=list)
    window: tuple[dict[str, float], int] = ({}, 0)  # loss sums and count since the last history entry
    contact: ContactTerm | None = None


def _prepare(spec: RunSpec, paths: list, ckpt_path: Path | None, resume: bool,
             objects: Mapping[str, ObjectModel] | None, vae_path: str | Path | None) -> _State:
    """Data, condition, network and optimiser; restored from the checkpoint when resuming."""
    cfg, model_cfg = spec.train, spec.model
    device = torch_device(cfg.device)  # a missing device is named before seconds of data loading
    if model_cfg.diffuse_joints and (cfg.penetration_weight > 0 or cfg.contact_weight > 0):
        raise GraspConfigError("the penetration and contact terms act on the joint network, which a diffuse_joints model "
                               "has not: set their weights to 0 or diffuse_joints=False")
    td = TrainingData.load(paths, cfg, objects)
    digest = td.digest()
    ckpt = None
    if resume:
        if ckpt_path is None:
            raise CheckpointError("resume needs a run directory")
        ckpt = load_torch_file(ckpt_path, CHECKPOINT_FORMAT)
        _check_resume(ckpt, spec, digest, ckpt_path)
    cond = HandCondition.from_state(ckpt["condition"]) if ckpt else HandCondition.fit(model_cfg.condition, td.params, vae_path)
    t_scale = float(ckpt["t_scale"]) if ckpt else td.translation_scale()
    torch.manual_seed(cfg.seed)
    tables = _tables(cond, td)
    net = GraspNet(model_cfg, cond.dim)  # initialised on the CPU: same weights on any device
    if model_cfg.diffuse_joints and ckpt is None:
        net.set_joint_statistics(td.q, tables[1].numpy()[td.hand_idx])
    net = net.to(device)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    summary = td.summary()
    # the training hands' own condition vectors: a hand from a params file has no name to resolve later (a model
    # trained on it took it for unseen), and a file named like a registered hand would resolve to that one
    meta = {"hands": td.hands, "data": spec.data, "data_digest": digest,
            **{k: summary[k] for k in ("train_objects", "test_objects", "per_hand")},
            "train_conditions": [[float(v) for v in row] for row in tables[0].numpy()]}
    terms = loss_terms(cfg)
    contact = ContactTerm.for_data(td, cfg, t_scale) if cfg.penetration_weight > 0 or cfg.contact_weight > 0 else None
    state = _State(td, GraspModel(net, cond, t_scale, model_cfg, meta), opt, tables,
                   window=({k: 0.0 for k in terms}, 0), contact=contact)
    if ckpt is not None:
        try:
            net.load_state_dict(ckpt["model"])
            opt.load_state_dict(ckpt["optimizer"])
            state.window = ({k: float(ckpt["window"]["sums"][k]) for k in terms}, int(ckpt["window"]["count"]))
        except (RuntimeError, KeyError, ValueError) as exc:
            raise CheckpointError(f"{ckpt_path}: incompatible checkpoint ({str(exc).splitlines()[0][:160]})") from None
        state.step, state.history = int(ckpt["step"]), list(ckpt["history"])
    return state


def _loop(st: _State, spec: RunSpec, ckpt_path: Path | None, progress: bool,
          on_step: Callable[[int, dict[str, float]], None] | None) -> float:
    """Train from ``st.step`` to ``spec.train.steps``; returns the wall time [s]."""
    from tqdm import tqdm

    cfg, net = spec.train, st.model.net
    elapsed_before = float(st.history[-1]["elapsed_s"]) if st.history else 0.0
    sums, count = st.window
    net.train()
    bar = tqdm(range(st.step, cfg.steps), initial=st.step, total=cfg.steps, desc="train grasp", unit="step",
               disable=not progress, dynamic_ncols=True)
    t_run = time.perf_counter()
    try:
        with DeferredStop("grasp training") as stop:
            _steps(st, spec, ckpt_path, on_step, bar, stop, elapsed_before, t_run, sums, count)
    finally:
        bar.close()
    net.to("cpu")  # the model a run returns and saves samples on the CPU, like every loaded model
    net.eval()
    return time.perf_counter() - t_run


def _steps(st: _State, spec: RunSpec, ckpt_path: Path | None, on_step, bar, stop: DeferredStop, elapsed_before: float,
           t_run: float, sums: dict[str, float], count: int) -> None:
    cfg, net, opt = spec.train, st.model.net, st.opt
    terms_logged = loss_terms(cfg)

    def checkpoint(done: int, window: tuple[dict[str, float], int]) -> None:
        atomic_save(_payload(st.model, opt, spec, done, st.history, st.model.meta["data_digest"], window), ckpt_path)

    for s in bar:
        lr = learning_rate(cfg, s)
        for group in opt.param_groups:
            group["lr"] = lr
        batch = make_batch(st.td, cfg, spec.model.n_points, s, *st.tables, st.model.t_scale).to(cfg.device)
        terms = train_step(net, batch, cfg.joint_loss_weight, st.contact)
        if not torch.isfinite(terms["total"]):  # a diverged run would save a model that samples NaN grasps
            raise GraspError(f"training diverged at step {s + 1}: loss {float(terms['total'])} at lr {lr:.3g}; lower the "
                             "learning rate (no model is written; checkpoints of earlier steps are kept)")
        opt.zero_grad(set_to_none=True)
        terms["total"].backward()
        opt.step()
        vals = {k: float(terms[k].detach()) for k in terms_logged}
        sums, count = {k: sums[k] + vals[k] for k in terms_logged}, count + 1
        done = s + 1
        if done % cfg.log_every == 0 or done == cfg.steps:
            entry = {"step": done, "lr": lr, **{k: sums[k] / count for k in terms_logged},
                     "elapsed_s": elapsed_before + time.perf_counter() - t_run}
            st.history.append(entry)
            bar.set_postfix(diff=f"{entry['diffusion']:.4f}", joints=f"{entry['joints']:.4f}")
            sums, count = {k: 0.0 for k in terms_logged}, 0
        st.step = done
        periodic = ckpt_path is not None and (done % cfg.checkpoint_every == 0 or done == cfg.steps)
        if periodic:
            checkpoint(done, (sums, count))
        if on_step is not None:
            on_step(done, vals)
        if stop.requested:  # batches are seeded by step, so a checkpoint at any step resumes exactly
            if ckpt_path is not None and not periodic:
                checkpoint(done, (sums, count))
            stop.stop()  # a handler that returns (it chose to go on) lets training go on


def train_grasp(data: str | Path | Sequence[str | Path], model_cfg: GraspModelConfig = GraspModelConfig(),
                cfg: GraspTrainConfig = GraspTrainConfig(), run_dir: str | Path | None = None, resume: bool = False,
                progress: bool = True, objects: Mapping[str, ObjectModel] | None = None, vae_path: str | Path | None = None,
                on_step: Callable[[int, dict[str, float]], None] | None = None) -> GraspTrainResult:
    """Train a grasp model on the dataset(s) ``data`` (see the module docstring for the outputs).

    ``objects``: ObjectModels by name for training objects the manifests cannot locate.
    ``vae_path``: the VAE of a ``vae`` condition (default: the shipped one; stored in the model).
    ``resume``: continue ``run_dir/checkpoints/last.pt`` (same settings except ``steps``,
    ``checkpoint_every``, ``log_every``; same data). ``on_step(step, losses)`` runs after every step.
    """
    paths = [data] if isinstance(data, (str, Path)) else list(data)
    # a folder named twice (``--data D D``, ``D ./D/``) is read once by the dataset: record it once too
    firsts: dict[Path, Any] = {}
    for p in paths:
        firsts.setdefault(Path(p).resolve(), p)
    paths = list(firsts.values())
    spec = RunSpec([str(p) for p in paths], model_cfg, cfg)
    run = Path(run_dir) if run_dir is not None else None
    ckpt_path = run / "checkpoints" / "last.pt" if run is not None else None
    t_start = time.perf_counter()
    # one writer per run folder: a second process resuming the same run would interleave checkpoints
    lock = folder_lock(run, "grasp training run") if run is not None else contextlib.nullcontext()
    with lock, torch_settings(cfg.threads):
        if not resume and ckpt_path is not None and ckpt_path.exists():  # it would be trained over from step 0
            raise CheckpointError(f"{run} already holds a training run ({ckpt_path}); resume=True continues it, "
                                  "or choose another run_dir")
        st = _prepare(spec, paths, ckpt_path, resume, objects, vae_path)
        if run is not None:
            write_text(run / "config.json", json.dumps(spec.to_dict(), indent=1) + "\n")
        first = st.step
        before = float(st.history[-1]["elapsed_s"]) if st.history else 0.0  # a resumed run's earlier sessions
        seconds = _loop(st, spec, ckpt_path, progress, on_step)
        n_steps, h = cfg.steps - first, st.history
        metrics: dict[str, Any] = {
            # both to the last step, as the history records it (the final checkpoint's write after it is in neither,
            # so this run's seconds never exceed the total; a resume with no step left adds 0)
            "steps": cfg.steps, "steps_this_run": n_steps,
            "train_seconds_this_run": (float(h[-1]["elapsed_s"]) - before if h else seconds) if n_steps > 0 else 0.0,
            "train_seconds_total": float(h[-1]["elapsed_s"]) if h else before + seconds,
            "steps_per_s": n_steps / seconds if seconds > 0 and n_steps else None,
            "grasps_per_s": n_steps * cfg.batch_size / seconds if seconds > 0 and n_steps else None,
            "final_losses": {k: h[-1][k] for k in loss_terms(cfg)} if h else {},
            "heldout_losses": heldout_losses(st.model, st.td, st.td.test_models),
            "data": st.td.summary(), "translation_scale_m": st.model.t_scale, "condition": model_cfg.condition,
            "encoder": model_cfg.encoder, "threads": cfg.threads, "device": cfg.device, "history": h,
            "wall_seconds": time.perf_counter() - t_start, "peak_rss_mib": _peak_rss_mib(),
        }
        model = st.model
        if run is not None:
            atomic_save(model.payload(), run / "model.pt")
            write_text(run / "metrics.json", json.dumps(metrics, indent=1) + "\n")
            model.path = run / "model.pt"
    return GraspTrainResult(model, metrics, run)


__all__ = ["torch_device", "train_grasp", "GraspTrainResult", "learning_rate", "heldout_losses", "train_step", "ContactTerm", "loss_terms"]
