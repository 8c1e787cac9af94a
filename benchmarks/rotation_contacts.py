"""How each URDF holds the cube at the start of a rotation episode: contacts and twist resistance.

A diagnostic for issue 15 (the original LEAP URDF never learned to turn the cube; the canonical one did).
For the starting states each shipped policy trained from (its exported ``grasps.npz``), after one control
step with zero action (the motors holding the start targets; no policy):

* *contacts*: hand-object contact points, the distinct links touching, which parts touch (palm; per
  finger, the distal link or a proximal one), and the summed normal force [N];
* *twist resistance*: an external torque about world +z on the object, ramped from 0 at ``--rate`` N m/s,
  and the torque [N m] at which the object has turned ``--slip`` rad (the grip's resistance to the very
  motion the task rewards; capped at the ramp's end value when it never turns that far); a torque
  that drops the object first counts as its slip torque (its ``dropped`` share is reported).

*relaxed starts* (``--transfer``): each canonical-URDF policy run on its own URDF and on the original URDF
  through the action map (as ``rotate eval --on-urdf original``), from the usual starting states and from
  the same states with the motor targets set to the settled joint angles (no finger pressing past its
  contact), the same seeded episodes: does a looser start let the policy turn the cube?

    python benchmarks/rotation_contacts.py [--states 40] [--policies rotate_leap_canonical ...] [--transfer [--episodes 20]]
    -> benchmarks/results/rotation_contacts.{json,md}
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402
import pybullet as pb  # noqa: E402

DEFAULT = ["rotate_leap_canonical", "rotate_leap_original", "rotate_shadow_canonical", "rotate_shadow_original"]


def contacts(scene) -> dict:
    """Contact summary of the scene's current state (see module doc)."""
    pts = pb.getContactPoints(scene.body, scene.obj_body, physicsClientId=scene.client)
    names = dict(scene.links)
    fingers = scene.link_finger
    # the distal link of a finger: its link farthest down the chain (largest PyBullet index)
    by_finger: dict[int, list[int]] = {}
    for j, _ in scene.links:
        by_finger.setdefault(fingers.get(j, -1), []).append(j)
    distal = {f: max(js) for f, js in by_finger.items() if f >= 0}
    links = {p[3] for p in pts}
    force = float(sum(p[9] for p in pts))
    return {"points": len(pts), "links": len(links), "normal_force": force,
            "palm": any(fingers.get(j, -1) < 0 for j in links),
            "distal": sum(1 for f, j in distal.items() if j in links),
            "proximal": len({fingers[j] for j in links if fingers.get(j, -1) >= 0 and j != distal[fingers[j]]}),
            "link_names": sorted(names.get(j, str(j)) for j in links)}


def twist(env, rate: float, slip: float, max_torque: float) -> tuple[float, bool]:
    """Ramp a +z torque on the object (motors holding their targets); the torque when it has turned
    ``slip`` rad, or dropped / left (True); ``max_torque`` if neither happens by the end of the ramp."""
    from ohra.sim.rotation import termination
    from ohra.sim.rotation.rewards import delta_yaw

    sc, cfg = env.unwrapped.scene, env.unwrapped.cfg
    start = sc.read()
    quat, turned, t = start.obj_quat, 0.0, 0.0
    while True:
        for _ in range(cfg.substeps):
            t += cfg.sim_dt
            pb.applyExternalTorque(sc.obj_body, -1, [0.0, 0.0, min(rate * t, max_torque)], pb.WORLD_FRAME,
                                   physicsClientId=sc.client)
            pb.stepSimulation(physicsClientId=sc.client)
        s = sc.read()
        turned += delta_yaw(quat, s.obj_quat)
        quat = s.obj_quat
        tau = min(rate * t, max_torque)
        if termination.reason(s.obj_pos, start.obj_pos, cfg.fall_height, cfg.max_distance, s.obj_quat, s.q, s.dq,
                              s.tau, s.obj_linvel, s.obj_angvel) is not None:
            return tau, True
        if abs(turned) >= slip:
            return tau, False
        if rate * t >= max_torque + rate * 0.5:  # half a second at the cap without turning
            return max_torque, False


def relaxed(gs):
    """The starting states ``gs`` with every motor target set to its settled joint angle."""
    import dataclasses

    return dataclasses.replace(gs, target=np.asarray(gs.q, dtype=float).copy())


def transfer_rows(name: str, pol, episodes: int, seed: int) -> tuple[list[str], dict]:
    """Steps-to-Fall and rotation of canonical-URDF policy ``pol`` (shipped as ``name``) on both URDFs, usual vs
    relaxed starts."""
    from rotation_table3 import summary_cell

    from ohra.learn.rl.evaluate import evaluate_policy, on_urdf
    from ohra.sim.rotation.grasps import load_or_generate
    from ohra.sim.rotation.task import resolve

    rows, data = [], {}
    for urdf in ("canonical", "original"):
        cfg = on_urdf(pol.env_cfg, urdf)
        gs = pol.grasps if urdf == pol.env_cfg.urdf and pol.grasps is not None else load_or_generate(resolve(cfg))
        for kind, g in (("usual", gs), ("relaxed", relaxed(gs))):
            r = evaluate_policy(pol, cfg, episodes, seed, name, grasps=g).summary()
            data[f"{urdf}/{kind}"] = r
            rows.append(f"| {name} | {urdf} | {kind} | {summary_cell(r, ' | ')} |")
            print(rows[-1], file=sys.stderr)
    return rows, data


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--policies", nargs="+", default=DEFAULT)
    ap.add_argument("--states", type=int, default=40, help="starting states per policy (the first N of its set)")
    ap.add_argument("--rate", type=float, default=0.1, help="torque ramp [N m/s]")
    ap.add_argument("--slip", type=float, default=0.1, help="turn [rad] that counts as slipping")
    ap.add_argument("--max-torque", type=float, default=0.5, help="end of the ramp [N m]")
    ap.add_argument("--transfer", action="store_true", help="also the relaxed-start runs of the canonical-URDF policies")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    args = ap.parse_args(argv)
    from ohra.learn.rl.evaluate import Policy, shipped
    from ohra.sim.rotation.env import InHandRotateEnv

    policies = {name: Policy(shipped(name)) for name in args.policies}
    rows, data = [], {}
    for name, pol in policies.items():
        env = InHandRotateEnv(pol.env_cfg, grasps=pol.grasps)
        n = min(args.states, len(env.grasps.q))
        per = []
        for i in range(n):
            env.reset(seed=i, options={"grasp": i})
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))  # contact forces exist after a step
            c = contacts(env.scene)
            c["twist_torque"], c["dropped"] = twist(env, args.rate, args.slip, args.max_torque)
            per.append(c)
        env.close()
        arr = {k: np.array([p[k] for p in per], dtype=float) for k in
               ("points", "links", "normal_force", "palm", "distal", "proximal", "twist_torque", "dropped")}
        names: dict[str, int] = {}
        for p in per:
            for ln in p["link_names"]:
                names[ln] = names.get(ln, 0) + 1
        summ = {k: {"mean": float(v.mean()), "median": float(np.median(v)), "q25": float(np.quantile(v, 0.25)),
                    "q75": float(np.quantile(v, 0.75))} for k, v in arr.items()}
        data[name] = {"hand": pol.env_cfg.hand, "urdf": pol.env_cfg.urdf, "states": n, "summary": summ,
                      "links_touching": dict(sorted(names.items(), key=lambda kv: -kv[1])), "per_state": per}
        s = summ
        rows.append(f"| {name} | {s['points']['median']:.0f} | {s['links']['mean']:.1f} | {100 * s['palm']['mean']:.0f} % | "
                    f"{s['distal']['mean']:.1f} / {s['proximal']['mean']:.1f} | {s['normal_force']['median']:.1f} "
                    f"({s['normal_force']['q25']:.1f}-{s['normal_force']['q75']:.1f}) | "
                    f"{s['twist_torque']['median']:.3f} ({s['twist_torque']['q25']:.3f}-{s['twist_torque']['q75']:.3f}) | "
                    f"{100 * s['dropped']['mean']:.0f} % |")
        print(rows[-1], file=sys.stderr)
    table = "\n".join([
        f"How each shipped rotation policy's starting states hold the cube (first {args.states} states of its set, motors "
        f"holding the start targets, no policy): contacts, and the +z torque on the object at which it turns "
        f"{args.slip} rad (ramped at {args.rate} N m/s up to {args.max_torque} N m).", "",
        "| policy | contact points, median | links touching, mean | palm touches | fingers touching with distal / "
        "proximal links, mean | normal force [N], median (quartiles) | twist torque [N m], median (quartiles) | dropped |",
        "|---|---|---|---|---|---|---|---|", *rows, "",
        "Links touching (share of states): " + "; ".join(
            f"{k}: " + ", ".join(f"{ln} {100 * c / v['states']:.0f} %" for ln, c in list(v['links_touching'].items())[:8])
            for k, v in data.items())])
    transfer: dict = {}
    if args.transfer:
        trows = []
        for name, pol in policies.items():
            if pol.env_cfg.urdf == "canonical":
                r, transfer[name] = transfer_rows(name, pol, args.episodes, args.seed)
                trows += r
        table += "\n".join([
            "", "", f"Relaxed starts: each canonical-URDF policy on both URDFs (the original through the action map), "
            f"from its usual starting states and from the same states with the motor targets at the settled joint angles, "
            f"{args.episodes} episodes (seeds {args.seed}..{args.seed + args.episodes - 1}), deterministic actions.", "",
            "| policy | URDF | starts | Steps-to-Fall | Cumulative Rotation [rad] | survived |", "|---|---|---|---|---|---|",
            *trows])
    write_results("rotation_contacts", {"states": args.states, "rate": args.rate, "slip": args.slip,
                                        "max_torque": args.max_torque, "policies": data,
                                        "transfer": {"episodes": args.episodes, "seed": args.seed, "runs": transfer}}, table)
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
