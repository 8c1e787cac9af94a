"""Where the reference (66-D, paper-setting) morphology VAE loses shape: per-parameter reconstruction
error, thumb rotation, sampler support, the loss balance, and the registered hands.

Run: python benchmarks/diagnose_vae.py [--model DIR] [--n N]  -> benchmarks/results/vae_diagnosis.{json,md}
(default model: the kept reference model ``ohra/learn/models/vae_reference66``, evaluated on hands of
the sampler it was trained on, ``ohra.learn.sampler_reference``).
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

import ohra  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402
from ohra.errors import OhraError  # noqa: E402
from ohra.learn import geometry as geo  # noqa: E402
from ohra.learn.morph import load_vae, reference_model_dir  # noqa: E402
from ohra.learn.sampler import THUMB_RPY, support_violations  # noqa: E402
from ohra.learn.sampler_reference import sample_reference_vectors  # noqa: E402
from ohra.learn.vae_metrics import reconstruct, reconstruct_vectors, shape_errors  # noqa: E402

SEED = 2_000_003


def per_parameter(vae, x: np.ndarray) -> dict:
    """RMSE per continuous value, raw units and standardised (z) units, over present parts."""
    enc = vae.encoding
    y = reconstruct(vae.model, vae.standardizer, x)
    e = (y - x)[:, enc.cont]
    z = e / vae.standardizer.std
    mask = x[:, enc.cont] != 0
    rows = {}
    for i, name in enumerate(enc.cont_names):
        m = mask[:, i]
        if m.any():
            rows[name] = {"std": float(vae.standardizer.std[i]), "rmse": float(np.sqrt(np.mean(e[m, i] ** 2))),
                          "rmse_z": float(np.sqrt(np.mean(z[m, i] ** 2)))}
    return rows


def latent_usage(vae, x: np.ndarray) -> dict:
    """Mean KL per latent dimension [nats] over hands, and the loss balance it implies."""
    mu, logvar = vae.encode_encodings(x)
    kl = 0.5 * (mu ** 2 + np.exp(logvar) - 1.0 - logvar)
    per_dim = kl.mean(axis=0)
    cfg = vae.model.config
    # A Gaussian decoder with variance s^2 has loss sum(e^2) / (2 s^2) + KL; the VAE minimises
    # cont_weight * mean(e^2) + beta * KL, i.e. the same with s^2 = beta * C / (2 cont_weight).
    sigma = math.sqrt(cfg.beta * vae.encoding.cont_dim / (2.0 * cfg.cont_weight))
    return {"kl_per_dim": per_dim.tolist(), "kl_total": float(per_dim.sum()), "active_dims_kl_gt_0.1": int((per_dim > 0.1).sum()),
            "implied_decoder_sigma_z": sigma}


def thumb_rotation(vae, v: np.ndarray) -> dict:
    """Geodesic error of the thumb mount, overall and by Euler region."""
    g, _ = shape_errors(v, reconstruct_vectors(vae.model, vae.standardizer, v))
    rpy = v[:, THUMB_RPY]
    pitch = np.abs(rpy[:, 1])
    near_wrap = np.max(np.abs(np.abs(rpy[:, [0, 2]]) - math.pi) < 0.3, axis=1)
    rms = lambda a: float(np.sqrt(np.mean(a ** 2))) if a.size else float("nan")  # noqa: E731
    return {"rmse_rad": rms(g), "mean_rad": float(g.mean()), "median_rad": float(np.median(g)),
            "rmse_pitch_within_0.15_of_pi_2": rms(g[np.abs(pitch - math.pi / 2) < 0.15]),
            "rmse_roll_or_yaw_within_0.3_of_pi": rms(g[near_wrap]), "rmse_elsewhere": rms(g[~near_wrap]),
            "fraction_pitch_beyond_pi_2": float(np.mean(pitch > math.pi / 2))}


def sampler_plausibility(v: np.ndarray, n_coal: int = 300) -> dict:
    """Fractions of sampled hands breaking the plausibility rules (Coal at q = 0 on a subset)."""
    coll = [HandModel.from_params(BaseParams.from_vector(row)).self_collision(np.zeros(22)) for row in v[:n_coal]]
    return {"thumb_into_palm": float(geo.thumb_into_palm(v).mean()),
            "finger_base_inside_palm": float(geo.knuckles_inside_palm(v).any(axis=1).mean()),
            "fingers_intersect_q0_coal": float(np.mean(coll)), "coal_subset": n_coal}


def registered(vae) -> list[dict]:
    rows = []
    std = vae.standardizer
    for name in ohra.list_hands():
        try:
            p = ohra.get_hand(name, "base")
        except OhraError:
            continue
        v = p.to_vector()[None]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            x = vae.encoding.encode_vectors(v)
        z = (x[0, vae.encoding.cont] - std.mean) / std.std
        worst = int(np.argmax(np.abs(z)))
        rec = reconstruct_vectors(vae.model, std, v)
        g, e = shape_errors(v, rec)
        fixed = rec.copy()
        fixed[:, THUMB_RPY] = v[:, THUMB_RPY]  # the true thumb mount in the reconstruction
        _, e_fixed = shape_errors(v, fixed)
        rpy = v[0, THUMB_RPY]
        rows.append({"hand": name, "tip_mean_mm": float(1e3 * np.nanmean(e)), "tip_mean_true_thumb_mount_mm": float(1e3 * np.nanmean(e_fixed)),
                     "thumb_rotation_error_rad": float(g[0]), "max_abs_z": float(abs(z[worst])), "max_z_value": vae.encoding.cont_names[worst],
                     "rpy_outside_pi": bool(np.any(np.abs(rpy) > math.pi)), "pitch_near_pi_2": bool(abs(abs(rpy[1]) - math.pi / 2) < 0.15),
                     "violations_of_new_sampler": support_violations(p)})
    return rows


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--model", help="model directory (default: the kept reference model)")
    ap.add_argument("--n", type=int, default=4096, help="held-out hands")
    args = ap.parse_args()
    torch.set_num_threads(1)
    vae = load_vae(args.model or reference_model_dir())
    v = sample_reference_vectors(args.n, SEED)
    x = vae.encoding.encode_vectors(v, warn=False)
    data = {"model": str(vae.path), "n": args.n, "per_parameter": per_parameter(vae, x), "latent": latent_usage(vae, x),
            "thumb_rotation": thumb_rotation(vae, v), "reference_sampler": sampler_plausibility(v), "registered": registered(vae)}
    pp, lat, th, sp = data["per_parameter"], data["latent"], data["thumb_rotation"], data["reference_sampler"]
    lines = ["| diagnosis of the reference VAE (its own sampler, held-out) | value |", "|---|---|"]
    zs = np.array([r["rmse_z"] for r in pp.values()])
    lines.append(f"| RMSE of the continuous values in standard deviations: median / min / max | {np.median(zs):.2f} / {zs.min():.2f} / {zs.max():.2f} |")
    lines.append(f"| decoder noise implied by beta = {vae.model.config.beta:g} on a mean MSE over {vae.encoding.cont_dim} values | {lat['implied_decoder_sigma_z']:.2f} std |")
    lines.append(f"| KL: total / latent dimensions above 0.1 nat | {lat['kl_total']:.1f} nats / {lat['active_dims_kl_gt_0.1']} of {len(lat['kl_per_dim'])} |")
    lines.append(f"| thumb mounting rotation error (geodesic): RMSE / median | {th['rmse_rad']:.2f} / {th['median_rad']:.2f} rad |")
    lines.append(f"| ... with roll or yaw within 0.3 rad of +-pi / elsewhere | {th['rmse_roll_or_yaw_within_0.3_of_pi']:.2f} / {th['rmse_elsewhere']:.2f} rad |")
    lines.append(f"| ... with pitch within 0.15 rad of +-pi/2 (gimbal lock) | {th['rmse_pitch_within_0.15_of_pi_2']:.2f} rad |")
    lines.append(f"| sampled thumbs with pitch beyond +-pi/2 (second Euler cover of each rotation) | {100 * th['fraction_pitch_beyond_pi_2']:.0f} % |")
    lines.append(f"| sampled hands: thumb into the palm / finger base inside the palm / fingers intersecting at q=0 (Coal, {sp['coal_subset']}) | "
                 f"{100 * sp['thumb_into_palm']:.0f} % / {100 * sp['finger_base_inside_palm']:.1f} % / {100 * sp['fingers_intersect_q0_coal']:.1f} % |")
    lines += ["", "| registered hand | tip error q=0 [mm] | ... with the true thumb mount | thumb rotation error [rad] | largest input z-score | rpy beyond +-pi | pitch near +-pi/2 |",
              "|---|---|---|---|---|---|---|"]
    for r in data["registered"]:
        lines.append(f"| {r['hand']} | {r['tip_mean_mm']:.1f} | {r['tip_mean_true_thumb_mount_mm']:.1f} | {r['thumb_rotation_error_rad']:.2f} | "
                     f"{r['max_abs_z']:.1f} ({r['max_z_value']}) | {'yes' if r['rpy_outside_pi'] else ''} | {'yes' if r['pitch_near_pi_2'] else ''} |")
    write_results("vae_diagnosis", data, "\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
