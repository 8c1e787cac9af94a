"""Yield of the data engine per CPU-second: what the NLP's finger-pair rows cost and what they save.

A fixed sample decided before running: the recipe's (``recipes/grasp_unified.yaml``) hands, 8 of its
objects evenly spaced through its object list, the recipe's 16 starts per pair, seed 0, its protocol
(isaac-drive) and robustness trials. Each variant of ``NLPSettings.finger_pairs`` synthesises every
(hand, object) shard in this process (:func:`ohra.synth.pipeline.synthesize_shard`) and the table
reports per hand: share of starts that converge, that converge but self-collide (exact Coal check,
status ``Self_Collision``), that pass the simulated test (verified) and the robustness trials
(robust), mean IPOPT iterations, CPU seconds (``time.process_time``, what an idle core would take) and
verified / robust grasps per CPU-second.

Second part (``--drive``): why Barrett's robust yield falls under the isaac-drive protocol while
Allegro's and Shadow's rise. 40 converged candidates per hand (seeded draw from the committed
``datasets/grasp_unified_s0``, read only) are simulated under the reference drive (position gain 0.3)
and isaac-drive (0.0208); the squeeze phase is replayed step by step to record when each finger first
touches the object, and, at its end, the torque of every still-blocked joint (more than 0.02 rad short
of its target: Isaac's drive, 1000 N m/rad, would press such a joint with its full 1 N m effort).

Run: python benchmarks/bench_yield.py [--hands ...] [--variants spheres capsules] [--cache DIR] [--drive]
Each (hand, variant) is cached as JSON in ``--cache`` so runs can be split across processes;
``--report`` writes benchmarks/results/yield.{json,md} from the cache.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.data.dataset import GraspDataset  # noqa: E402
from ohra.data.manifest import object_keys  # noqa: E402
from ohra.data.recipe import Recipe  # noqa: E402
from ohra.sim import GraspEvaluator, Protocol  # noqa: E402
from ohra.sim.hands import SimHand  # noqa: E402
from ohra.synth.pipeline import STATUS_CODES, synthesize_shard  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RECIPE = ROOT / "recipes" / "grasp_unified.yaml"
N_OBJECTS = 8


def sample_objects(objects: list, n: int = N_OBJECTS) -> list:
    """``n`` objects evenly spaced through the recipe's list (procedural families and YCB alike)."""
    idx = np.unique(np.linspace(0, len(objects) - 1, n).round().astype(int))
    return [objects[i] for i in idx]


def run(hand: str, variant: str, starts: int, seed: int) -> dict:
    """Synthesise the sample for one hand and one ``finger_pairs`` variant; counts and CPU time."""
    r = Recipe.load(RECIPE)
    params = dict(r.resolve_hands())[hand]
    base = r.synth_settings()
    settings = replace(base, grasps_per_object=starts, seed=seed, nlp=replace(base.nlp, finger_pairs=variant))
    per_obj, tot = [], {"starts": 0, "converged": 0, "self_collision": 0, "prefiltered": 0, "verified": 0, "robust": 0,
                        "iterations": 0, "cpu_s": 0.0, "solve_s": 0.0, "sim_s": 0.0}
    for obj in sample_objects(r.resolve_objects()):
        cpu0 = time.process_time()
        a = synthesize_shard(hand, params, obj, settings)
        cpu = time.process_time() - cpu0  # includes the solver build, as a shard does
        row = {"object": obj.name, "starts": int(len(a["raw"])), "converged": int(a["solver_success"].sum()),
               "self_collision": int((a["solver_status"] == STATUS_CODES["Self_Collision"]).sum()),
               "prefiltered": int(a["prefiltered"].sum()), "verified": int(a["sim_success"].sum()),
               "robust": int(a["robust_success"].sum()), "iterations": int(a["iterations"].sum()), "cpu_s": cpu,
               "solve_s": a["_timing"]["solve_s"], "sim_s": a["_timing"]["sim_s"]}
        per_obj.append(row)
        for k in tot:
            tot[k] += row[k]
        print(f"{hand} {variant} {obj.name}: {row}", flush=True)
    return {"hand": hand, "variant": variant, "starts_per_pair": starts, "seed": seed, "total": tot, "objects": per_obj}


BLOCKED_RAD = 0.02  # rad short of the squeeze target: a joint held back by contact


def squeeze_trace(ev: GraspEvaluator, grasp: np.ndarray) -> dict:
    """Replay the squeeze of :func:`ohra.sim.evaluator.run_grasp` step by step (same reset, targets and
    stepping): per finger the time of its first contact [s], and at the end of the squeeze every driven
    joint's residual ``target - q`` [rad] and applied motor torque over the effort limit."""
    import pybullet as pb

    from ohra.rotations import grasp_to_pose
    from ohra.sim.controller import closes_positive, squeeze_targets

    world, prot = ev.world, ev.protocol
    c, hand = world.client, world.hand
    T_palm, q = grasp_to_pose(np.asarray(grasp, dtype=float))
    qs = hand.project_sim(np.clip(hand.to_sim(np.clip(q, hand.canon_lower, hand.canon_upper)), hand.lower, hand.upper))
    pb.setGravity(0, 0, 0, physicsClientId=c)
    world.reset_hand(T_palm @ hand.T_palm_root, qs)
    obj = world.new_object()
    axis, link_z, origin = world.joint_frames()
    q_reset, q_target = squeeze_targets(qs, hand.lower, hand.upper, closes_positive(axis, link_z, origin), prot.outer, prot.inner,
                                       couple=hand.project_sim if hand.coupled else None)
    world.set_joints(q_reset)
    world.drive_joints(q_target)
    first: dict[int, float] = {}
    names, jidx = dict(world.links), world.jidx.tolist()
    at_reset: list[tuple[str, float]] = []  # links touching after the first step, their joint's reset opening [rad]
    for k in range(prot.squeeze_steps):
        pb.stepSimulation(physicsClientId=c)
        for cp in pb.getContactPoints(world.body, obj, physicsClientId=c):
            first.setdefault(world.link_finger.get(cp[3], -1), (k + 1) * prot.dt)
            if k == 0 and names.get(cp[3]) not in [a[0] for a in at_reset]:
                j = jidx.index(cp[3]) if cp[3] in jidx else None  # a link's index is its parent joint's
                at_reset.append((names.get(cp[3], "?"), float(abs(q_reset[j] - qs[j])) if j is not None else float("nan")))
    states = pb.getJointStates(world.body, world.jidx.tolist(), physicsClientId=c)
    tau = np.abs([st[3] for st in states]) / prot.motor_force
    return {"first_contact": first, "at_reset": at_reset, "residual": q_target - np.array([st[0] for st in states]), "torque": tau}


def drive_diagnosis(hand: str, n: int = 40, seed: int = 0) -> dict:
    """Reference vs isaac-drive on ``n`` converged candidates of ``hand`` (see the module doc)."""
    r = Recipe.load(RECIPE)
    params = dict(r.resolve_hands())[hand]
    objs = r.resolve_objects()
    by_key = dict(zip(object_keys(objs), objs))
    ds = GraspDataset(ROOT / "datasets" / "grasp_unified_s0")
    cands = []
    for h, key in ds.pairs:
        if h == hand:
            sh = ds.load_shard(h, key)
            cands += [(key, g) for g in sh["raw"][sh["solver_success"] & ~sh["prefiltered"]]]
    pick = np.random.default_rng(seed).permutation(len(cands))[:n]
    out: dict = {"hand": hand, "candidates": int(len(pick))}
    for name, prot in (("reference", Protocol()), ("isaac-drive", Protocol.isaac_drive())):
        ok, ejected, at_reset, spread, tau_blocked, n_blocked, cpu0 = [], [], [], [], [], 0, time.process_time()
        reset_links: dict[str, list[float]] = {}
        for i in pick:
            key, g = cands[i]
            with GraspEvaluator(SimHand.from_params(params, hand), by_key[key], prot) as ev:
                res = ev.evaluate(g[None].astype(float), mode="filter").results[0]
                tr = squeeze_trace(ev, g)
            ok.append(res.success)
            ejected.append(res.contacts == 0)  # nothing touches the object after the squeeze
            times = list(tr["first_contact"].values())
            at_reset.append(bool(times) and min(times) <= prot.dt * 1.000001)  # touching from the first step
            for link, opening in tr["at_reset"]:
                reset_links.setdefault(link, []).append(opening)
            if len(times) >= 2:
                spread.append(max(times) - min(times))
            blocked = np.abs(tr["residual"]) > BLOCKED_RAD
            n_blocked += int(blocked.sum())
            tau_blocked += tr["torque"][blocked].tolist()
        ok, ejected, at_reset = np.array(ok), np.array(ejected), np.array(at_reset)
        out[name] = {"passed": int(ok.sum()), "failed_ejected_in_squeeze": int((~ok & ejected).sum()),
                     "touching_at_reset": int(at_reset.sum()), "ejected_touching_at_reset": int((~ok & ejected & at_reset).sum()),
                     "failed_later": int((~ok & ~ejected).sum()), "contact_spread_s_median": float(np.median(spread)) if spread else None,
                     "blocked_joints_per_grasp": n_blocked / len(pick),
                     # per link touching at the reset pose: how often, and how often its joint opened < 0.01 rad
                     "links_touching_at_reset": {k: [len(v), int(np.sum(np.array(v) < 0.01))] for k, v in sorted(reset_links.items())},
                     "blocked_torque_over_effort_median": float(np.median(tau_blocked)) if tau_blocked else None,
                     "cpu_s": time.process_time() - cpu0}
        print(hand, name, out[name], flush=True)
    return out


def drive_table(diag: list[dict]) -> str:
    lines = ["", "## Drive diagnosis: reference vs isaac-drive on the same converged candidates", "",
             "40 converged candidates per hand from `datasets/grasp_unified_s0` (seeded draw), nominal filter test. "
             "*Ejected*: no hand link touches the object after the 1 s squeeze (in brackets: of those, a link already "
             "touched it in the first step, i.e. at the reset pose; *touching at reset* counts all such candidates). *Contact spread*: time from the first "
             "finger's first contact to the last finger's. *Blocked torque*: applied motor torque over the 1 N m effort "
             f"of joints still more than {BLOCKED_RAD} rad short of their target at the end of the squeeze (Isaac's "
             "1000 N m/rad drive would give 1.0).", "",
             "| hand | drive | passed | touching at reset | failed: ejected in squeeze | failed later | contact spread (median, s) | blocked joints/grasp | blocked torque / effort (median) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for d in diag:
        for name in ("reference", "isaac-drive"):
            x = d[name]
            sp = "-" if x["contact_spread_s_median"] is None else f"{x['contact_spread_s_median']:.3f}"
            tb = "-" if x["blocked_torque_over_effort_median"] is None else f"{x['blocked_torque_over_effort_median']:.2f}"
            lines.append(f"| {d['hand']} | {name} | {x['passed']}/{d['candidates']} | {x['touching_at_reset']} | "
                         f"{x['failed_ejected_in_squeeze']} ({x['ejected_touching_at_reset']}) | {x['failed_later']} | "
                         f"{sp} | {x['blocked_joints_per_grasp']:.1f} | {tb} |")
    lines += ["", "Links touching the object at the reset pose (isaac-drive; count, and of those whose joint the reset "
              "opened by less than 0.01 rad):", ""]
    for d in diag:
        lines.append(f"- {d['hand']}: " + ", ".join(f"{k} {n} ({m})" for k, (n, m) in d["isaac-drive"]["links_touching_at_reset"].items()))
    return "\n".join(lines)


def table(runs: list[dict]) -> str:
    lines = ["# Yield per CPU-second: finger-pair rows of the grasp NLP", "",
             f"Recipe `{RECIPE.relative_to(ROOT)}` (protocol isaac-drive, 2 robustness trials), {N_OBJECTS} of its objects evenly "
             "spaced through its list, 16 starts per pair, seed 0, one process (`benchmarks/bench_yield.py`). "
             "Shares are of all starts; CPU is `time.process_time` of the whole shard (build, solves, simulation).", "",
             "| hand | finger pairs | starts | converged | self-collision | verified | robust | iterations/start | CPU s | verified/CPU-s | robust/CPU-s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(runs, key=lambda r: (r["hand"], r["variant"] != "spheres")):
        t = r["total"]
        n = max(t["starts"], 1)
        lines.append(f"| {r['hand']} | {r['variant']} | {n} | {t['converged'] / n:.0%} | {t['self_collision'] / n:.0%} | "
                     f"{t['verified'] / n:.0%} | {t['robust'] / n:.0%} | {t['iterations'] / n:.0f} | {t['cpu_s']:.0f} | "
                     f"{t['verified'] / t['cpu_s']:.3f} | {t['robust'] / t['cpu_s']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--hands", nargs="+", default=["allegro_hand_left", "barrett_hand", "shadow_hand_right"])
    ap.add_argument("--variants", nargs="+", default=["spheres", "capsules"], choices=("spheres", "capsules"))
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/ohra_bench_yield"))
    ap.add_argument("--report", action="store_true", help="only write results/yield.{json,md} from the cache")
    ap.add_argument("--drive", action="store_true", help="run the drive diagnosis (cached as drive-<hand>.json) instead")
    a = ap.parse_args(argv)
    known = dict(Recipe.load(RECIPE).resolve_hands())
    unknown = [h for h in a.hands if h not in known]
    if unknown:  # the sample is the recipe's: another hand is another study
        ap.error(f"--hands {' '.join(unknown)}: not a hand of {RECIPE.name} ({', '.join(known)})")
    a.cache.mkdir(parents=True, exist_ok=True)
    if a.drive:
        for hand in a.hands:
            (a.cache / f"drive-{hand}.json").write_text(json.dumps(drive_diagnosis(hand), indent=1))
    elif not a.report:
        for hand in a.hands:
            for variant in a.variants:
                res = run(hand, variant, a.starts, a.seed)
                (a.cache / f"{hand}-{variant}.json").write_text(json.dumps(res, indent=1))
    runs = [json.loads(p.read_text()) for p in sorted(a.cache.glob("*.json")) if not p.name.startswith("drive-")]
    diag = [json.loads(p.read_text()) for p in sorted(a.cache.glob("drive-*.json"))]
    write_results("yield", {"runs": runs, "drive_diagnosis": diag}, table(runs) + ("\n" + drive_table(diag) if diag else ""))
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
