"""Which parts of the hand condition a grasp model listens to (the paper's Fig. 8).

For a hand and an object, ``n`` grasps are sampled with gradients on: the hand condition vector
``c`` enters every one of them, and the Jacobian of each output (the 3 palm-translation
coordinates in metres, from the 10-step DDIM chain, and the 22 joint angles in radians, before
clamping) with respect to ``c`` is taken by autograd. An entry's saliency is the mean over the
grasps of the Euclidean norm of its Jacobian column; a group's is the mean over its entries.

Groups of the ``params`` condition (:func:`ohra.learn.grasp.condition.params_vector`, 196 entries):
``palm`` (palm radius and the LEAP-template flag) and one group per finger (its radius, segment
lengths, joint origins, axes, limits and presence flags), so a model that attends to the fingers a
hand has shows small values for the fingers it lacks. A ``vae`` condition has one group per latent
dimension.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import torch

from ohra.canonical.params import EXT_ROWS_PER_FINGER, JOINTS_PER_FINGER
from ohra.learn.grasp.condition import PARAMS_DIM, resolve_hand
from ohra.learn.grasp.model import GraspModel, random_rotations, resolve_object

FINGERS = ("thumb", "index", "middle", "ring", "little")


def params_groups() -> np.ndarray:
    """(196,) group name of every entry of the ``params`` condition vector."""
    rows = np.repeat(np.arange(5), EXT_ROWS_PER_FINGER)  # joint-origin / axis rows -> finger
    joints = np.repeat(np.arange(5), JOINTS_PER_FINGER)  # joints -> finger
    idx = np.concatenate([
        [-1], np.arange(5), np.repeat(np.arange(5), 3),  # palm radius, finger radii, finger lengths (5, 3)
        np.repeat(rows, 6), np.repeat(rows, 3),  # joint origins (12, 6), joint axes (12, 3)
        joints, joints, joints, [-1],  # lower, upper limits, presence flags, LEAP flag
    ])
    assert len(idx) == PARAMS_DIM
    return np.array(["palm" if i < 0 else FINGERS[i] for i in idx])


def condition_saliency(model: GraspModel, hand: Any, obj: Any, n: int = 64, seed: int = 0) -> dict[str, Any]:
    """Saliency of every condition entry and group for ``hand`` on ``obj`` (see the module doc).

    Returns ``{"entries": (dim,) array, "groups": {name: value}, "n": n}``; deterministic in ``seed``.
    """
    params = resolve_hand(hand)
    obj = resolve_object(obj)
    rng = np.random.default_rng(seed)
    rots = random_rotations(int(n), rng)
    r6 = torch.from_numpy(np.concatenate([rots[:, :, 0], rots[:, :, 1]], axis=1).astype(np.float32))
    c0 = torch.from_numpy(model.condition.vector(params).astype(np.float32))
    net = model.net
    with torch.no_grad():
        feat = net.encoder(model.object_cloud(obj)[None]).expand(len(r6), -1)
    c = c0.expand(len(r6), -1).clone().requires_grad_(True)  # one copy per grasp: per-grasp gradients
    cond = torch.cat([feat, c, r6], dim=-1)
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    with torch.enable_grad():
        x, q = net.sample_grasp(cond, gen)
        y = torch.cat([x * model.t_scale, q], dim=-1)  # (n, 25)
        sq = torch.zeros_like(c)
        for k in range(y.shape[1]):
            (g,) = torch.autograd.grad(y[:, k].sum(), c, retain_graph=k + 1 < y.shape[1])
            sq += g**2
    entries = sq.sqrt().mean(dim=0).double().numpy()
    names = params_groups() if model.condition.kind == "params" else np.array([f"z{i}" for i in range(len(entries))])
    groups = {g: float(entries[names == g].mean()) for g in dict.fromkeys(names)}
    return {"entries": entries, "groups": groups, "n": int(n)}


def mean_condition_saliency(model: GraspModel, hand: Any, objects: Sequence[Any], n: int = 64, seed: int = 0) -> dict[str, Any]:
    """:func:`condition_saliency` averaged over ``objects`` (each with ``n`` rotations and ``seed``):
    one object's saliency reflects that object's grasps as much as the hand. Same return layout, with
    ``"objects"`` (their count) and ``n`` the total number of sampled grasps."""
    rs = [condition_saliency(model, hand, o, n=n, seed=seed) for o in objects]
    if not rs:
        raise ValueError("mean_condition_saliency: no objects")
    return {"entries": np.mean([r["entries"] for r in rs], axis=0),
            "groups": {g: float(np.mean([r["groups"][g] for r in rs])) for g in rs[0]["groups"]},
            "n": int(n) * len(rs), "objects": len(rs)}


def saliency_figure(results: dict[str, dict[str, Any]], path: str, title: str = "condition saliency"):
    """Bar chart of group saliency per hand (``{hand: condition_saliency(...)}``) written to ``path``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1.6 + 1.1 * len(next(iter(results.values()))["groups"]), 3.2))
    ax = fig.add_subplot(1, 1, 1)
    names = list(next(iter(results.values()))["groups"])
    w = 0.8 / len(results)
    for i, (hand, r) in enumerate(results.items()):
        ax.bar(np.arange(len(names)) + i * w - 0.4 + w / 2, [r["groups"][g] for g in names], w, label=hand)
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_ylabel("mean |d output / d condition|")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return fig


__all__ = ["FINGERS", "condition_saliency", "mean_condition_saliency", "params_groups", "saliency_figure"]
