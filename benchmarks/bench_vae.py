"""Morphology VAE benchmark: held-out reconstruction, registered hands, interpolation smoothness,
training cost (from the model's metrics.json), sampler and inference speed.

Run: python benchmarks/bench_vae.py [--model DIR] [--heldout N]  -> benchmarks/results/vae.{json,md}
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_of, peak_rss_mib, write_results  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

import ohra  # noqa: E402
from ohra.errors import OhraError  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402
from ohra.learn import encode_vectors, sample_vectors  # noqa: E402
from ohra.learn.encoding import FLAGS  # noqa: E402
from ohra.learn.morph import load_vae  # noqa: E402
from ohra.learn.sampler import in_support  # noqa: E402
from ohra.learn.train_vae import reconstruct, reconstruction_metrics  # noqa: E402

HELDOUT_SEED = 2_000_003  # neither the training seed (0) nor the training run's own held-out seed
PAIRS = (("dex3_right", "shadow_hand_right"), ("barrett_hand", "allegro_hand_right"), ("leap_hand_right", "sharpa_wave_right"))


def base_hands() -> list[str]:
    out = []
    for n in ohra.list_hands():
        try:
            ohra.get_hand(n, "base")
            out.append(n)
        except OhraError:
            pass
    return out


def tips(p) -> np.ndarray:
    return HandModel.from_params(p).fingertips(np.zeros(22))


def registered(vae) -> list[dict]:
    rows = []
    for n in base_hands():
        p = ohra.get_hand(n, "base")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            x = encode_vectors(p.to_vector())[None]
        y = reconstruct(vae.model, vae.standardizer, x)[0]
        rec = vae.decode(vae.encode_encodings(x)[0][0], limits=p)  # the hand's own limits
        t0, t1 = tips(p), tips(rec)
        both = ~np.isnan(t0[:, 0]) & ~np.isnan(t1[:, 0])
        err = np.linalg.norm(t0[both] - t1[both], axis=1)
        rows.append({"hand": n, "in_sampler_support": in_support(x[0, FLAGS] > 0.5), "presence_exact": bool(np.array_equal(x[0, FLAGS], y[FLAGS])),
                     "presence_errors": int(np.sum(x[0, FLAGS] != y[FLAGS])),
                     "fingertip_mean_mm": float(1e3 * err.mean()), "fingertip_max_mm": float(1e3 * err.max())})
    return rows


def heldout_tips(vae, n: int = 400) -> dict:
    """Fingertip error at q=0 of sampled held-out hands decoded with their own limits [mm]."""
    v = sample_vectors(n, HELDOUT_SEED + 1)
    x = encode_vectors(v, warn=False)
    rec = vae.decode_vectors(vae.encode_encodings(x)[0], limits=np.concatenate([v[:, 38:60], v[:, 60:82]], axis=1))
    thumb, other = [], []
    for a, b in zip(v, rec):
        t0, t1 = tips(BaseParams.from_vector(a)), tips(BaseParams.from_vector(b))
        e = 1e3 * np.linalg.norm(t0 - t1, axis=1)
        thumb.append(e[0])
        other += [float(x) for x in e[1:] if not np.isnan(x)]
    return {"n": n, "thumb_mean_mm": float(np.nanmean(thumb)), "thumb_median_mm": float(np.nanmedian(thumb)),
            "fingers_mean_mm": float(np.mean(other)), "fingers_median_mm": float(np.median(other))}


def smoothness(vae, steps: int = 16) -> list[dict]:
    out = []
    for a, b in PAIRS:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                it = vae.interpolate(a, b, steps)
        except OhraError:
            continue
        T = [tips(p) for p in it.params]
        jumps, same, changes = [], [], 0
        for t0, t1, p0, p1 in zip(T[:-1], T[1:], it.params[:-1], it.params[1:]):
            both = ~np.isnan(t0[:, 0]) & ~np.isnan(t1[:, 0])
            jumps.append(float(np.linalg.norm(t0[both] - t1[both], axis=1).max()) if both.any() else 0.0)
            changes += int(np.sum(p0.present_fingers != p1.present_fingers))
            if np.array_equal(p0.present_joints, p1.present_joints):  # no joint appears or vanishes
                d = np.linalg.norm(t0 - t1, axis=1)
                same.append((float(d[0]), float(np.nanmax(d[1:]))))
        ends = float(np.linalg.norm(np.nan_to_num(T[0] - T[-1]), axis=1).max())
        out.append({"pair": f"{a} -> {b}", "steps": steps, "max_jump_mm": 1e3 * max(jumps), "mean_jump_mm": 1e3 * float(np.mean(jumps)),
                    "finger_appearances": changes,
                    "max_jump_same_structure_thumb_mm": 1e3 * max(j[0] for j in same) if same else None,
                    "max_jump_same_structure_fingers_mm": 1e3 * max(j[1] for j in same) if same else None,
                    "steps_same_structure": len(same), "dof": [p.dof for p in it.params]})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--model", help="model directory (default: the shipped model)")
    ap.add_argument("--heldout", type=int, default=16384)
    args = ap.parse_args()
    torch.set_num_threads(1)
    vae = load_vae(args.model)

    t_sample = best_of(lambda: sample_vectors(65536, 0), 3)
    x = encode_vectors(sample_vectors(args.heldout, HELDOUT_SEED), warn=False)
    held = reconstruction_metrics(x, reconstruct(vae.model, vae.standardizer, x))
    z = vae.encode_encodings(x[:1024])[0]
    t_enc = best_of(lambda: vae.encode_encodings(x[:1024]), 3) / 1024
    t_dec = best_of(lambda: vae.decode_vectors(z), 3) / 1024
    t_one = best_of(lambda: vae.decode(z[0]), 5)
    reg = registered(vae)
    held_tips = heldout_tips(vae)
    smooth = smoothness(vae)
    train = vae.metrics or {}
    data = {
        "model": str(vae.path), "config": vae.config, "heldout": {"seed": HELDOUT_SEED, **held},
        "heldout_fingertips": held_tips, "registered_hands": reg, "interpolation": smooth,
        "training": {"epochs": train.get("epochs"), "steps": train.get("steps"),
                     "seconds": train.get("train_seconds_total"), "peak_rss_mib": train.get("peak_rss_mib"),
                     "threads": vae.config.get("threads")},
        "speed": {"sample_65536_s": t_sample, "encode_per_hand_us": 1e6 * t_enc, "decode_to_valid_vector_per_hand_us": 1e6 * t_dec,
                  "decode_one_params_ms": 1e3 * t_one},
        "bench_peak_rss_mib": peak_rss_mib(),
    }

    lines = ["| morphology VAE (shipped model) | value | target |", "|---|---|---|"]
    lines.append(f"| held-out hands (seed {HELDOUT_SEED}) | {held['n']} | |")
    lines.append(f"| presence accuracy (22 flags) | {100 * held['presence_accuracy']:.2f} % | >= 99 % |")
    lines.append(f"| presence pattern exactly right (per hand) | {100 * held['presence_exact']:.2f} % | |")
    lines.append(f"| thumb axis accuracy (present thumb joints 1-2) | {100 * held['axis_accuracy']:.2f} % | >= 98 % |")
    lines.append(f"| thumb axis accuracy (all slots) | {100 * held['axis_accuracy_all']:.2f} % | |")
    for k, v in held["rmse"].items():
        name, unit = k.rsplit("_", 1)
        val = f"{1e3 * v:.2f} mm" if unit == "m" else f"{v:.3f} rad"
        lines.append(f"| RMSE {name} | {val} | |")
    lines.append(f"| held-out hands, fingertip error at q=0 (own limits), thumb mean / median | "
                 f"{held_tips['thumb_mean_mm']:.1f} / {held_tips['thumb_median_mm']:.1f} mm | |")
    lines.append(f"| held-out hands, fingertip error at q=0 (own limits), other fingers mean / median | "
                 f"{held_tips['fingers_mean_mm']:.1f} / {held_tips['fingers_median_mm']:.1f} mm | |")
    ok = sum(r["presence_exact"] for r in reg)
    sup = [r for r in reg if r["in_sampler_support"]]
    lines.append(f"| registered hands with presence pattern exactly right (all / in the sampler's support) | "
                 f"{ok} / {len(reg)} ; {sum(r['presence_exact'] for r in sup)} / {len(sup)} | all |")
    if reg:
        lines.append(f"| registered hands, fingertip error at q=0 (mean / worst hand mean) | "
                     f"{np.mean([r['fingertip_mean_mm'] for r in reg]):.1f} / {max(r['fingertip_mean_mm'] for r in reg):.1f} mm | |")
    for s in smooth:
        lines.append(f"| interpolation {s['pair']} ({s['steps']} steps): max / mean fingertip jump | "
                     f"{s['max_jump_mm']:.1f} / {s['mean_jump_mm']:.1f} mm | |")
        if s["steps_same_structure"]:
            lines.append(f"| ... steps with the same joints ({s['steps_same_structure']} of {s['steps'] - 1}): max jump thumb / other fingers | "
                         f"{s['max_jump_same_structure_thumb_mm']:.1f} / {s['max_jump_same_structure_fingers_mm']:.1f} mm | |")
    tr = data["training"]
    if tr["seconds"] is not None:
        lines.append(f"| training: {tr['epochs']} epochs, {tr['steps']} steps, 65,536 hands, {tr['threads']} thread(s) | "
                     f"{tr['seconds'] / 60:.1f} min | < 25 min |")
    if tr["peak_rss_mib"] is not None:
        lines.append(f"| training peak memory (RSS) | {tr['peak_rss_mib']:.0f} MiB | |")
    sp = data["speed"]
    lines.append(f"| sample 65,536 hands (vectorised) | {sp['sample_65536_s']:.2f} s | < 60 s |")
    lines.append(f"| encode / decode-to-valid-vector, batched | {sp['encode_per_hand_us']:.1f} / {sp['decode_to_valid_vector_per_hand_us']:.1f} us per hand | |")
    lines.append(f"| decode one latent to BaseParams | {sp['decode_one_params_ms']:.2f} ms | |")
    table = "\n".join(lines)
    if reg:
        table += "\n\n| hand | joint pattern in sampler support | presence exact | fingertip error at q=0, mean / max [mm] |\n|---|---|---|---|\n"
        table += "\n".join(f"| {r['hand']} | {'yes' if r['in_sampler_support'] else 'no'} | {'yes' if r['presence_exact'] else 'no (' + str(r['presence_errors']) + ' flags)'} | "
                           f"{r['fingertip_mean_mm']:.1f} / {r['fingertip_max_mm']:.1f} |" for r in reg)
    write_results("vae", data, table)


if __name__ == "__main__":
    main()
