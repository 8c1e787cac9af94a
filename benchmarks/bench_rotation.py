"""In-hand rotation environment throughput: control steps/s per core, 1 vs 2 processes, and grasp generation.

Each (hand, urdf) runs the Gymnasium environment as training does (resets included) under a seeded
uniform random policy (actions in [-0.5, 0.5]). "per core" is steps per CPU-second of the stepping
process (``time.process_time``): on this shared 2-core machine wall time also counts other jobs.
Two processes run the same loop side by side (spawned workers); their aggregate wall throughput is
what a 2-env ``SubprocVecEnv`` can reach. A settings table varies the physics step, solver
iterations and finger-finger collisions on LEAP canonical. Grasp generation: starting states per
second (``ohra.sim.rotation.grasps.generate``, 64 states, uncached).

Every stepping measurement is repeated (``--repeat``, default 3) and the median is reported: on this
virtual machine the same 2,000-step loop measured 580 and 973 steps per CPU-second minutes apart
(the host's other tenants slow the vCPU without it showing as load), so one sample can be far off.

    python benchmarks/bench_rotation.py [--steps 2000] [--repeat 3] [--quick]
"""

from __future__ import annotations

import multiprocessing as mp
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

HANDS = (("leap_hand_right", "canonical"), ("leap_hand_right", "original"),
         ("shadow_hand_right", "canonical"), ("shadow_hand_right", "original"))
SETTINGS = ({}, {"solver_iterations": 10}, {"solver_iterations": 50}, {"self_collision": False},
            {"sim_dt": 1 / 60}, {"sim_dt": 1 / 240})
GRASPS = 64  # starting states the benchmark envs use (the stepping speed does not depend on it)


def _run(args: tuple[dict, int, int]) -> dict:
    """Step one environment ``steps`` times; returns CPU and wall seconds of the loop."""
    from ohra.sim.rotation.env import InHandRotateEnv

    kw, steps, seed = args
    env = InHandRotateEnv(grasp_count=GRASPS, **kw)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-0.5, 0.5, size=(steps,) + env.action_space.shape)
    env.reset(seed=seed)
    episodes = 0
    t_cpu, t_wall = time.process_time(), time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
            episodes += 1
    cpu, wall = time.process_time() - t_cpu, time.perf_counter() - t_wall
    env.close()
    return {"cpu_s": cpu, "wall_s": wall, "episodes": episodes}


def _prepare(kw: dict) -> None:
    """Build the grasp cache once in this process (workers then only load it)."""
    from ohra.sim.rotation.env import InHandRotateEnv

    InHandRotateEnv(grasp_count=GRASPS, **kw).close()


def throughput(kw: dict, steps: int, repeat: int = 3) -> dict:
    """Medians over ``repeat`` measurements (the samples are kept too)."""
    _prepare(kw)
    ones = [_run((kw, steps, 0)) for _ in range(repeat)]
    ctx = mp.get_context("spawn")
    twos, walls = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        with ctx.Pool(2) as pool:
            twos.append(pool.map(_run, [(kw, steps, 1), (kw, steps, 2)]))
        walls.append(time.perf_counter() - t)
    med = statistics.median
    return {"steps": steps, "repeat": repeat,
            "1proc_per_core": med(steps / r["cpu_s"] for r in ones), "1proc_wall": med(steps / r["wall_s"] for r in ones),
            "1proc_per_core_samples": [steps / r["cpu_s"] for r in ones],
            "2proc_per_core": [med(steps / two[i]["cpu_s"] for two in twos) for i in range(2)],
            "2proc_aggregate_wall": med(2 * steps / max(r["wall_s"] for r in two) for two in twos),
            "2proc_aggregate_wall_with_startup": med(2 * steps / w for w in walls)}


def grasp_rate(kw: dict) -> dict:
    from ohra.sim.rotation.config import RotationConfig
    from ohra.sim.rotation.grasps import generate
    from ohra.sim.rotation.task import resolve

    task = resolve(RotationConfig(grasp_count=GRASPS, grasp_seed=123, **kw))
    t = time.process_time()
    gs = generate(task)
    cpu = time.process_time() - t
    return {"kept": len(gs), "attempts": gs.attempts, "per_core": len(gs) / cpu, "keep_rate": len(gs) / gs.attempts}


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--steps", type=int, default=2000, help="control steps per measurement")
    ap.add_argument("--repeat", type=int, default=3, help="measurements per figure (the median is reported)")
    ap.add_argument("--quick", action="store_true", help="LEAP canonical only, no settings table")
    args = ap.parse_args(argv)
    from ohra.sim.rotation.config import RotationConfig

    hands = HANDS[:1] if args.quick else HANDS
    load0 = os.getloadavg()[0]
    rows = {}
    for hand, urdf in hands:
        kw = {"hand": hand, "urdf": urdf}
        rows[f"{hand}/{urdf}"] = {**throughput(kw, args.steps, args.repeat), "grasps": grasp_rate(kw)}
        print(f"{hand}/{urdf}: {rows[f'{hand}/{urdf}']}", file=sys.stderr)
    settings = {}
    if not args.quick:
        for s in SETTINGS:
            kw = {"hand": "leap_hand_right", "urdf": "canonical", **s}
            _prepare(kw)
            rs = [_run((kw, args.steps, 0)) for _ in range(args.repeat)]
            settings[_label(s)] = {"per_core": statistics.median(args.steps / r["cpu_s"] for r in rs),
                                   "wall": statistics.median(args.steps / r["wall_s"] for r in rs)}
    d = RotationConfig()
    physics = (f"sim_dt 1/{round(1 / d.sim_dt)} s x {d.substeps} sub-steps per {d.control_hz:g} Hz control step, "
               f"{d.solver_iterations} solver iterations, finger-finger collisions {'on' if d.self_collision else 'off'}, "
               "fixed links merged")
    write_results("rotation", {"physics": physics, "load_average_start": load0, "load_average_end": os.getloadavg()[0],
                               "hands": rows, "settings_leap_canonical": settings}, _table(rows, settings, physics, load0))
    return 0


def _label(s: dict) -> str:
    if not s:
        return "default"
    return ", ".join(f"{k}={'1/%d' % round(1 / v) if k == 'sim_dt' else v}" for k, v in s.items())


def _table(rows: dict, settings: dict, physics: str, load: float) -> str:
    lines = [f"In-hand rotation env throughput (control steps/s; random policy, resets included). Physics: {physics}.",
             f"Shared 2-core machine, load average {load:.1f} at the start: per-core = steps per CPU-second of the "
             f"stepping process; each figure the median of {next(iter(rows.values()))['repeat']} measurements. "
             "Target: >= 1,000 per core for LEAP.", "",
             "| hand / urdf | 1 proc per core | 1 proc wall | 2 procs per core (each) | 2 procs aggregate wall | "
             "grasps kept / tried | grasps/s per core |", "|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        g = r["grasps"]
        each = " / ".join(f"{x:.0f}" for x in r["2proc_per_core"])
        lines.append(f"| {name} | {r['1proc_per_core']:.0f} | {r['1proc_wall']:.0f} | {each} | "
                     f"{r['2proc_aggregate_wall']:.0f} | {g['kept']} / {g['attempts']} | {g['per_core']:.1f} |")
    if settings:
        lines += ["", "Physics settings, LEAP canonical, 1 process (steps/s):", "",
                  "| setting | per core | wall |", "|---|---|---|"]
        lines += [f"| {k} | {v['per_core']:.0f} | {v['wall']:.0f} |" for k, v in settings.items()]
    return "\n".join(lines)


if __name__ == "__main__":
    run_script(main, __file__)
