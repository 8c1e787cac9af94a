"""Morphology VAE benchmark: the targets of issue 16, for the shipped model and the kept reference
(66-D, paper settings) model side by side.

* held-out hands of each model's own training sampler: presence / axis accuracy, thumb mounting
  rotation error (geodesic), fingertip error at q = 0 (decoded with their own limits);
* registered hands: fingertip error at q = 0 per hand, encoded and decoded with their own limits;
* plausibility of decoded hands (random latents from the prior and every interpolation step):
  finger base inside the palm, thumb pointing into the palm (:mod:`ohra.learn.geometry`), fingers
  intersecting at q = 0 (Coal, ``HandModel.self_collision``);
* interpolation between every pair of registered hands (16 hands, from ``VAEBundle.interpolate``:
  the default geodesic path, the straight line at equal fingertip arc length and at even alphas for
  comparison): the largest fingertip move of a step that keeps the same joints and handedness, next
  to the least a thumb that keeps its length needs per step (:func:`turning_thumb_bound`), and the
  time per interpolation;
* training cost (from the model's metrics.json), sampler and inference speed.

Run: python benchmarks/bench_vae.py [--model DIR] [--latents N] [--heldout N]  -> benchmarks/results/vae.{json,md}
"""

from __future__ import annotations

import itertools
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_of, peak_rss_mib, run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402
from ohra.hands import hands_in_form  # noqa: E402
from ohra.learn import geometry as geo  # noqa: E402
from ohra.learn.encoding_rot6d import is_left  # noqa: E402
from ohra.learn.morph import load_vae, reference_model_dir  # noqa: E402
from ohra.learn.sampler import LOWERS, UPPERS, XYZ, mirror_vectors, sample_vectors, support_violations  # noqa: E402
from ohra.learn.sampler_reference import sample_reference_vectors  # noqa: E402
from ohra.learn.vae_metrics import reconstruct, reconstruct_vectors, reconstruction_metrics, shape_errors  # noqa: E402

HELDOUT_SEED = 2_000_003  # neither the training seed (0) nor the training run's own held-out seed
LATENT_SEED = 5
STEPS = 16
MOVE_LIMIT_M = 0.02


def own_sampler(vae):
    return sample_reference_vectors if vae.encoding.name == "reference66" else sample_vectors


def heldout(vae, n: int) -> dict:
    v = own_sampler(vae)(n, HELDOUT_SEED)
    x = vae.encoding.encode_vectors(v, warn=False)
    out = reconstruction_metrics(x, reconstruct(vae.model, vae.standardizer, x), vae.encoding)
    g, e = shape_errors(v, reconstruct_vectors(vae.model, vae.standardizer, v))
    mm = 1e3 * e
    out["shape"] = {"thumb_rotation_rmse_rad": float(np.sqrt(np.mean(g ** 2))), "thumb_tip_mean_mm": float(np.nanmean(mm[:, 0])),
                    "finger_tip_mean_mm": float(np.nanmean(mm[:, 1:])), "tip_mean_mm": float(np.nanmean(mm))}
    return out


def registered(vae, hands: dict[str, BaseParams]) -> list[dict]:
    V = np.stack([p.to_vector() for p in hands.values()])
    rec = reconstruct_vectors(vae.model, vae.standardizer, V)
    x = vae.encoding.encode_vectors(V, warn=False)
    y = reconstruct(vae.model, vae.standardizer, x)
    g, e = shape_errors(V, rec)
    rows = []
    for i, (n, p) in enumerate(hands.items()):
        flags_ok = np.array_equal(x[i, vae.encoding.flags], y[i, vae.encoding.flags])
        rows.append({"hand": n, "in_sampler_support": not support_violations(p), "presence_exact": bool(flags_ok),
                     "tip_mean_mm": float(1e3 * np.nanmean(e[i])), "tip_max_mm": float(1e3 * np.nanmax(e[i])),
                     "thumb_rotation_error_rad": float(g[i])})
    return rows


def plausibility(V: np.ndarray) -> dict:
    """Counts of decoded hands (N, 82) breaking each rule; Coal on every hand."""
    coal = sum(HandModel.from_params(BaseParams.from_vector(v)).self_collision(np.zeros(22)) for v in V)
    return {"n": int(len(V)), "finger_base_inside_palm": int(geo.knuckles_inside_palm(V).any(axis=1).sum()),
            "thumb_into_palm": int(geo.thumb_into_palm(V).sum()), "fingers_intersect_q0_coal": int(coal)}


def turning_thumb_bound(va: np.ndarray, vb: np.ndarray) -> float:
    """Largest thumb-tip move [m] of a step when the thumb goes from hand ``a`` to hand ``b`` in
    STEPS even steps of its own path: base and reach linear, direction turned the shortest way at
    a constant rate (right-hand form). A thumb that keeps its length cannot do with less per step."""
    from scipy.spatial.transform import Rotation

    ends = []
    for v in (va, vb):
        v = v[None].copy()
        if is_left(v)[0]:
            v = mirror_vectors(v)
        reach, _ = geo.finger_reach(v)
        ends.append((v[0, XYZ][:3], reach[0, 0], geo.finger_directions(v)[0, 0]))
    (ba, la, da), (bb, lb, db) = ends
    axis = np.cross(da, db)
    angle = float(np.arctan2(np.linalg.norm(axis), da @ db))
    axis = axis / max(np.linalg.norm(axis), 1e-12)
    t = np.linspace(0.0, 1.0, 64 * (STEPS - 1) + 1)
    d = Rotation.from_rotvec(np.outer(t * angle, axis)).apply(da)
    tip = (1 - t)[:, None] * ba + t[:, None] * bb + ((1 - t) * la + t * lb)[:, None] * d
    return float(np.linalg.norm(np.diff(tip, axis=0), axis=1).sum() / (STEPS - 1))


def step_moves(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps (STEPS - 1,) that keep the joints and the handedness, and every fingertip's move of
    each step (STEPS - 1, 5) [m] (NaN for absent fingers)."""
    T = geo.tips_q0(V)
    present = (V[:, LOWERS] != 0) | (V[:, UPPERS] != 0)
    left = is_left(V)
    same = np.all(present[1:] == present[:-1], axis=1) & (left[1:] == left[:-1])
    return same, np.linalg.norm(T[1:] - T[:-1], axis=-1)


def interpolations(vae, hands: dict[str, BaseParams], spacing: str = "geodesic") -> tuple[list[dict], np.ndarray]:
    """Every unordered pair of registered hands, STEPS hands from the library's interpolation
    (``VAEBundle.interpolate``, with ``spacing``): largest fingertip move of a step that keeps the
    same joints (thumb, other fingers), and all decoded steps (for the plausibility check)."""
    rows, all_steps = [], []
    for a, b in itertools.combinations(list(hands), 2):
        t0 = time.perf_counter()
        V = np.stack([p.to_vector() for p in vae.interpolate(hands[a], hands[b], STEPS, spacing).params])
        seconds = time.perf_counter() - t0
        all_steps.append(V)
        same, d = step_moves(V)
        moves = d[same]
        T = geo.tips_q0(V)
        bound = np.nanmax(np.linalg.norm(T[-1] - T[0], axis=-1)) / (STEPS - 1)  # even a straight, even path moves this much
        rows.append({"pair": f"{a} -> {b}", "same_handedness": bool(hands[a].handedness == hands[b].handedness),
                     "straight_path_bound_mm": float(1e3 * bound),
                     "turning_thumb_bound_mm": 1e3 * turning_thumb_bound(hands[a].to_vector(), hands[b].to_vector()),
                     "steps_same_joints": int(same.sum()), "seconds": seconds,
                     "max_move_thumb_mm": float(1e3 * np.nanmax(moves[:, 0])) if same.any() else None,
                     "max_move_fingers_mm": float(1e3 * np.nanmax(moves[:, 1:])) if same.any() else None,
                     "steps_over_limit": int(np.sum(np.nanmax(moves, axis=1) > MOVE_LIMIT_M)) if same.any() else 0})
    return rows, np.concatenate(all_steps)


def interpolation_part(vae, hands: dict[str, BaseParams]) -> dict:
    """The interpolation results: geodesic (default), straight at equal arc length, even alphas, and
    the plausibility of every step ``interpolate`` returns."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        interp, steps = interpolations(vae, hands)
        arc, _ = interpolations(vae, hands, "arc")
        even, _ = interpolations(vae, hands, "even")
    return {"interpolation": interp, "interpolation_arc": arc, "interpolation_even_alphas": even,
            "plausibility_interpolation_steps": plausibility(steps)}


def evaluate(vae, hands: dict[str, BaseParams], n_heldout: int, n_latents: int) -> dict:
    torch.manual_seed(0)
    z = np.random.default_rng(LATENT_SEED).standard_normal((n_latents, vae.latent_dim))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = {"model": str(vae.path), "encoding": vae.encoding.name, "config": vae.config,
                "heldout": {"seed": HELDOUT_SEED, **heldout(vae, n_heldout)}, "registered_hands": registered(vae, hands),
                **interpolation_part(vae, hands), "plausibility_random_latents": plausibility(vae.decode_vectors(z))}
    train = vae.metrics or {}
    data["training"] = {"epochs": train.get("epochs"), "steps": train.get("steps"), "seconds": train.get("train_seconds_total"),
                        "peak_rss_mib": train.get("peak_rss_mib"), "threads": vae.config.get("threads")}
    x = vae.encoding.encode_vectors(own_sampler(vae)(1024, HELDOUT_SEED), warn=False)
    zz = vae.encode_encodings(x)[0]
    data["speed"] = {"encode_per_hand_us": 1e6 * best_of(lambda: vae.encode_encodings(x), 3) / 1024,
                     "decode_to_valid_vector_per_hand_us": 1e6 * best_of(lambda: vae.decode_vectors(zz), 3) / 1024,
                     "decode_one_params_ms": 1e3 * best_of(lambda: vae.decode(zz[0]), 5)}
    return data


def _worst(r: dict) -> float:
    return max(r["max_move_thumb_mm"], r["max_move_fingers_mm"]) if r["steps_same_joints"] else float("nan")


def _interp_cells(rows: list[dict]) -> str:
    worst = max((_worst(r) for r in rows if r["steps_same_joints"]), default=float("nan"))
    over = sum(r["steps_over_limit"] for r in rows)
    secs = [r.get("seconds", float("nan")) for r in rows]
    return (f"{worst:.1f} mm; {over} of {sum(r['steps_same_joints'] for r in rows)} steps > 20 mm; "
            f"{np.mean(secs):.2f} s per pair (max {max(secs):.2f})")


def _rows(d: dict) -> dict[str, str]:
    """Table cells of one model's results."""
    h, s, reg = d["heldout"], d["heldout"]["shape"], d["registered_hands"]
    per_hand = [r["tip_mean_mm"] for r in reg]
    if "interpolation_arc" not in d:  # results of a run before the geodesic: "interpolation" was the straight arc
        return {**_rows({**d, "interpolation_arc": d["interpolation"]}), "interp": "not run"}
    geo, arc, even = (_interp_cells(d[k]) for k in ("interpolation", "interpolation_arc", "interpolation_even_alphas"))
    over = [r for r in d["interpolation"] if r["steps_over_limit"]]
    bound = ", ".join(f"{r['pair']} {_worst(r):.1f} (bound {r['turning_thumb_bound_mm']:.1f})" for r in over) if len(over) <= 8 else ""
    arc_over = {r["pair"]: r for r in d["interpolation_arc"] if r["steps_over_limit"]}
    geo_rows = {r["pair"]: r for r in d["interpolation"]}
    fixed = ", ".join(f"{p} {_worst(r):.1f} -> {_worst(geo_rows[p]):.1f} (bound {r['turning_thumb_bound_mm']:.1f})"
                      for p, r in arc_over.items()) if len(arc_over) <= 8 else ""
    pr, pi = d["plausibility_random_latents"], d["plausibility_interpolation_steps"]
    tr, sp = d["training"], d["speed"]
    fmt_p = lambda p: f"{p['finger_base_inside_palm']} / {p['thumb_into_palm']} / {p['fingers_intersect_q0_coal']} of {p['n']}"  # noqa: E731
    return {
        "presence": f"{100 * h['presence_accuracy']:.2f} %", "axes": f"{100 * h['axis_accuracy']:.2f} %",
        "rot": f"{s['thumb_rotation_rmse_rad']:.3f} rad",
        "tips": f"{s['tip_mean_mm']:.1f} mm ({s['thumb_tip_mean_mm']:.1f} / {s['finger_tip_mean_mm']:.1f})",
        "reg": f"{np.mean(per_hand):.1f} / {max(per_hand):.1f} mm, {sum(t <= 10.0 for t in per_hand)} of {len(per_hand)} hands <= 10 mm",
        "interp": geo, "interp_arc": arc, "interp_even": even,
        "interp_bound": f"{len(over)} of {len(d['interpolation'])} pairs" + (f": {bound} mm" if bound else ""),
        "interp_fixed": f"{len(arc_over)} pairs" + (f": {fixed} mm" if fixed and arc_over else ""),
        "random": fmt_p(pr), "steps": fmt_p(pi),
        "train": f"{tr['seconds'] / 60:.1f} min ({tr['epochs']} epochs, {tr['steps']} steps)" if tr["seconds"] else "-",
        "speed": f"{sp['encode_per_hand_us']:.1f} / {sp['decode_to_valid_vector_per_hand_us']:.1f} us",
    }


LABELS = [
    ("presence", "held-out hands (own sampler): presence accuracy (22 flags)", ">= 99 %"),
    ("axes", "held-out hands: thumb axis accuracy (present thumb joints 1-2)", ">= 98 %"),
    ("rot", "held-out hands: thumb mounting rotation error, RMSE (geodesic)", "<= 0.1 rad"),
    ("tips", "held-out hands: fingertip error at q=0, mean (thumb / other fingers)", "<= 10 mm"),
    ("reg", "registered hands: fingertip error at q=0, mean of hands / worst hand", "<= 10 mm per hand"),
    ("interp", f"interpolation (`interpolate`, default `spacing=\"geodesic\"`: bent latent path at equal fingertip arc length), every pair of registered hands ({STEPS} hands): largest fingertip move of a step keeping joints and handedness; time per pair (one thread)", "<= 20 mm"),
    ("interp_arc", "... straight latent line at equal fingertip arc length (`spacing=\"arc\"`, before)", "<= 20 mm"),
    ("interp_even", "... straight latent line, even alphas (`spacing=\"even\"`)", "<= 20 mm"),
    ("interp_fixed", "pairs with a step > 20 mm on the straight line (arc): largest move straight -> geodesic, and the least a thumb that keeps its length needs per step (base and reach linear, turning the shortest way at a constant rate)", ""),
    ("interp_bound", "pairs with a step > 20 mm (geodesic, the default)", "0 pairs"),
    ("random", "random latents: finger base inside palm / thumb into palm / fingers intersecting at q=0 (Coal)", "0 / 0 / 0"),
    ("steps", "interpolation steps: finger base inside palm / thumb into palm / fingers intersecting at q=0 (Coal)", "0 / 0 / 0"),
    ("train", "training time (wall, shared 2-core machine)", "<= 30 min"),
    ("speed", "encode / decode to a valid vector, batched, per hand", ""),
]


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--model", help="model directory (default: the shipped model)")
    ap.add_argument("--heldout", type=int, default=16384)
    ap.add_argument("--latents", type=int, default=10000, help="random latents for the plausibility check")
    ap.add_argument("--no-reference", action="store_true", help="skip the reference model column")
    ap.add_argument("--interpolation-only", action="store_true",
                    help="re-run only the interpolation part, keeping the rest of benchmarks/results/vae.json "
                    "(the models it was run on must be the ones given); written after each model")
    args = ap.parse_args()
    torch.set_num_threads(1)
    hands = hands_in_form("base")
    models = {"new": load_vae(args.model)}
    if not args.no_reference:
        models = {"reference66": load_vae(reference_model_dir()), **models}
    if args.interpolation_only:
        _rerun_interpolation(models, hands)
        return
    data = {name: evaluate(vae, hands, args.heldout, args.latents) for name, vae in models.items()}
    data["sample_65536_s"] = best_of(lambda: sample_vectors(65536, 0), 3)
    data["bench_peak_rss_mib"] = peak_rss_mib()
    write_results("vae", data, tables(data, list(models)))


def _rerun_interpolation(models: dict, hands: dict[str, BaseParams]) -> None:
    """Replace the interpolation part of each model in the stored results (newest model first, so
    that a run cut short still updates the shipped one); the other parts stay as they were."""
    import json

    from _common import RESULTS

    data = json.loads((RESULTS / "vae.json").read_text())
    data.pop("machine", None)
    for name in sorted(models, key=lambda k: k != "new"):
        stored = Path(data.get(name, {}).get("model", "none"))
        if stored.parts[-2:] != Path(models[name].path).parts[-2:]:  # run in another checkout: same model folder
            raise SystemExit(f"vae.json holds {stored} as {name!r}, not {models[name].path}: run the whole bench")
        data[name].update(interpolation_part(models[name], hands))
        write_results("vae", data, tables(data, [m for m in ("reference66", "new") if m in data]))


def tables(data: dict, models: list[str]) -> str:
    """The markdown tables of a run's results (one column per model; per-hand rows of the last)."""
    cells = {name: _rows(data[name]) for name in models}
    head = " | ".join(f"{name} ({data[name]['encoding']})" for name in models)
    lines = [f"| morphology VAE | {head} | target |", "|---|" + "---|" * len(models) + "---|"]
    for key, label, target in LABELS:
        lines.append(f"| {label} | " + " | ".join(cells[m][key] for m in models) + f" | {target} |")
    lines.append(f"| sample 65,536 hands (vectorised, with thumb redraws) | {data['sample_65536_s']:.2f} s | | < 60 s |")
    last = models[-1]
    table = "\n".join(lines)
    table += f"\n\n| hand ({last}) | in sampler support | presence exact | fingertip error at q=0, mean / max [mm] | thumb rotation error [rad] |\n|---|---|---|---|---|\n"
    table += "\n".join(f"| {r['hand']} | {'yes' if r['in_sampler_support'] else 'no'} | {'yes' if r['presence_exact'] else 'no'} | "
                       f"{r['tip_mean_mm']:.1f} / {r['tip_max_mm']:.1f} | {r['thumb_rotation_error_rad']:.3f} |" for r in data[last]["registered_hands"])
    return table


if __name__ == "__main__":
    t0 = time.perf_counter()
    run_script(lambda: main() or print(f"({time.perf_counter() - t0:.0f} s)"), __file__)
