"""Reconstruction metrics of a morphology VAE: encoding-level (presence, axes, per-parameter RMSE)
and hand-level (thumb mounting rotation, fingertips at q = 0)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ohra.learn.encoding import Standardizer
from ohra.learn.encodings import Encoding, get_encoding
from ohra.learn.geometry import geodesic, tips_q0
from ohra.learn.sampler import LOWERS, THUMB_RPY, UPPERS
from ohra.transforms import rpy_to_matrix


@torch.no_grad()
def reconstruct(model, standardizer: Standardizer, x_raw: np.ndarray, batch: int = 8192) -> np.ndarray:
    """Encode with the mean latent and decode (eval mode): raw encodings (N, D) -> (N, D).

    Output: continuous part in raw units, axis groups as one-hot, presence flags as 0/1.
    """
    enc = get_encoding(model.config.encoding)
    was_training = model.training
    model.eval()
    outs = []
    for i in range(0, len(x_raw), batch):
        xb = np.array(x_raw[i : i + batch], dtype=float, copy=True)
        xb[:, enc.cont] = standardizer.transform(xb[:, enc.cont])
        mu, _ = model.encode(torch.from_numpy(xb.astype(np.float32)))
        o = model.decode(mu)
        y = np.zeros((len(xb), enc.dim))
        y[:, enc.cont] = standardizer.inverse(o["cont"].double().numpy())
        rows = np.arange(len(xb))
        y[rows, enc.axis1.start + o["axis1"].argmax(dim=1).numpy()] = 1.0
        y[rows, enc.axis2.start + o["axis2"].argmax(dim=1).numpy()] = 1.0
        y[:, enc.binary] = (o["presence"] > 0).double().numpy()
        outs.append(y)
    model.train(was_training)
    return np.concatenate(outs) if outs else np.zeros((0, enc.dim))


def reconstruction_metrics(x_raw: np.ndarray, y: np.ndarray, encoding: Encoding | str = "reference66") -> dict[str, Any]:
    """Accuracy and RMSE of reconstructions ``y`` of raw encodings ``x_raw`` (both (N, D)).

    ``presence_accuracy``: fraction of the 22N flags right; ``presence_exact``: fraction of hands
    with all 22 right. ``axis_accuracy``: thumb axes of present (movable) thumb joints 1/2;
    ``axis_accuracy_all``: both axis slots of every hand (absent axes encode as +x).
    RMSE per parameter group in metres / radians (rot6d: unitless), over the values of the present
    parts (non-zero targets; the rot6d encoding's stand-ins for absent parts count too).
    """
    enc = get_encoding(encoding)
    flags_t, flags_y = x_raw[:, enc.flags] > 0.5, y[:, enc.flags] > 0.5
    a_t = np.stack([x_raw[:, enc.axis1].argmax(1), x_raw[:, enc.axis2].argmax(1)], axis=1)
    a_y = np.stack([y[:, enc.axis1].argmax(1), y[:, enc.axis2].argmax(1)], axis=1)
    present_axes = flags_t[:, :2]
    err = y[:, enc.cont] - x_raw[:, enc.cont]
    rmse = {}
    for name, (sl, unit) in enc.groups().items():
        e = err[:, sl]
        mask = x_raw[:, enc.cont][:, sl] != 0.0  # zeros mark parts that are absent in this hand
        rmse[f"{name}_{unit}"] = float(np.sqrt(np.mean(e[mask] ** 2))) if mask.any() else 0.0
    out = {
        "n": int(len(x_raw)),
        "presence_accuracy": float(np.mean(flags_t == flags_y)),
        "presence_exact": float(np.mean(np.all(flags_t == flags_y, axis=1))),
        "axis_accuracy": float(np.mean((a_t == a_y)[present_axes])) if present_axes.any() else 1.0,
        "axis_accuracy_all": float(np.mean(a_t == a_y)),
        "rmse": rmse,
    }
    if enc.left is not None:
        out["handedness_accuracy"] = float(np.mean((x_raw[:, enc.left] > 0.5) == (y[:, enc.left] > 0.5)))
    return out


def shape_errors(v_true: np.ndarray, v_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per hand: thumb mounting rotation error [rad] (N,) and q = 0 fingertip errors [m] (N, 5),
    NaN where a finger is absent in either hand. Both (N, 82); ``v_hat`` decoded with the true limits."""
    g = geodesic(rpy_to_matrix(v_true[:, THUMB_RPY]), rpy_to_matrix(v_hat[:, THUMB_RPY]))
    return g, np.linalg.norm(tips_q0(v_true) - tips_q0(v_hat), axis=-1)


def shape_metrics(v_true: np.ndarray, v_hat: np.ndarray) -> dict[str, float]:
    """Thumb rotation RMSE / mean [rad] and q = 0 fingertip error means [mm] (thumb, other fingers,
    all) of reconstructions ``v_hat`` (decoded with the true limits) of base vectors ``v_true``."""
    g, e = shape_errors(v_true, v_hat)
    mm = 1e3 * e
    return {
        "thumb_rotation_rmse_rad": float(np.sqrt(np.mean(g ** 2))),
        "thumb_rotation_mean_rad": float(np.mean(g)),
        "thumb_tip_mean_mm": float(np.nanmean(mm[:, 0])),
        "finger_tip_mean_mm": float(np.nanmean(mm[:, 1:])),
        "tip_mean_mm": float(np.nanmean(mm)),
    }


def reconstruct_vectors(model, standardizer: Standardizer, v82: np.ndarray) -> np.ndarray:
    """Encode base vectors (N, 82), decode the mean latents, and return valid base vectors with the
    hands' own joint limits (N, 82)."""
    enc = get_encoding(model.config.encoding)
    y = reconstruct(model, standardizer, enc.encode_vectors(v82, warn=False))
    return enc.decode_vectors(y, limits=(v82[:, LOWERS], v82[:, UPPERS]))
