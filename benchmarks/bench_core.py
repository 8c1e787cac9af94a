"""Core benchmark: render + load all 256 LEAP variants, FK throughput, peak memory (one core).

Run: python benchmarks/bench_core.py  -> benchmarks/results/core.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_of, peak_rss_mib, run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import pybullet as pb  # noqa: E402

from ohra.sim.bullet import load_urdf_text  # noqa: E402
from ohra.hands import get_hand, variant_names  # noqa: E402
from ohra.hands.leap.variants import _variant_vector  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.urdfgen import render  # noqa: E402


def bench_variants() -> dict[str, float]:
    names = variant_names()
    _variant_vector.cache_clear()
    t0 = time.perf_counter()
    params = [get_hand(n) for n in names]
    t1 = time.perf_counter()
    texts = [render(p, robot_name=n) for p, n in zip(params, names)]
    t2 = time.perf_counter()
    for text in texts:
        pin.buildModelFromXML(text)
    t3 = time.perf_counter()
    client = pb.connect(pb.DIRECT)
    for text in texts:
        b = load_urdf_text(text, client, useFixedBase=True, flags=pb.URDF_IGNORE_VISUAL_SHAPES)
        pb.removeBody(b, physicsClientId=client)
    t4 = time.perf_counter()
    for text in texts:
        b = load_urdf_text(text, client, useFixedBase=True)
        pb.removeBody(b, physicsClientId=client)
    t5 = time.perf_counter()
    pb.disconnect(client)
    return {
        "params_s": t1 - t0,
        "render_s": t2 - t1,
        "pinocchio_load_s": t3 - t2,
        "pybullet_load_s": t4 - t3,
        "pybullet_load_with_visuals_s": t5 - t4,
        "render_plus_pinocchio_s": t2 - t0 + (t3 - t2),
        "render_plus_both_s": t4 - t0,
    }


def bench_fk(hand: str) -> dict[str, float]:
    hm = HandModel.from_params(get_hand(hand))
    Q = hm.random_configurations(1024, seed=0)
    single_tips = 256 / best_of(lambda: [hm.fingertips(q) for q in Q[:256]])
    qp = np.array([hm._to_pin(q) for q in Q])
    raw = 1024 / best_of(lambda: [pin.forwardKinematics(hm.model, hm.data, q) for q in qp])
    batch_tips = 1024 / best_of(lambda: hm.fingertips(Q), repeat=5)
    batch_all = 1024 / best_of(lambda: hm.frame_poses(Q), repeat=5)
    return {
        "single_fingertips_per_s": single_tips,
        "single_pinocchio_fk_per_s": raw,
        "batch1024_fingertips_per_s": batch_tips,
        "batch1024_all_frames_per_s": batch_all,
        "frames": len(hm.frame_names),
    }


def main() -> None:
    variants = bench_variants()
    fk = {h: bench_fk(h) for h in ("leap_3333", "leap_2203")}
    mem = peak_rss_mib()
    v = variants
    lines = [
        "| what | measured | target |",
        "|---|---|---|",
        f"| render 256 LEAP variants (params + Jinja2) | {v['params_s'] + v['render_s']:.2f} s | |",
        f"| render + load in Pinocchio, all 256 | {v['render_plus_pinocchio_s']:.2f} s | ≤ 2 s |",
        f"| + load in PyBullet (collision shapes only) | {v['render_plus_both_s']:.2f} s total ({v['pybullet_load_s']:.2f} s PyBullet) | ≤ 2 s |",
        f"| PyBullet load with visual shapes too | {v['pybullet_load_with_visuals_s']:.2f} s | |",
    ]
    for h, r in fk.items():
        lines += [
            f"| FK {h}, single config, fingertips via `HandModel` | {r['single_fingertips_per_s']:,.0f} /s | ≥ 100k/s |",
            f"| FK {h}, single config, raw `pin.forwardKinematics` | {r['single_pinocchio_fk_per_s']:,.0f} /s | ≥ 100k/s |",
            f"| FK {h}, batch 1024, fingertips | {r['batch1024_fingertips_per_s']:,.0f} /s | ≥ 100k/s |",
            f"| FK {h}, batch 1024, all {r['frames']} frames | {r['batch1024_all_frames_per_s']:,.0f} /s | |",
        ]
    lines.append(f"| peak memory (RSS) | {mem:.0f} MiB | |")
    write_results("core", {"variants": variants, "fk": fk, "peak_rss_mib": mem}, "\n".join(lines))


if __name__ == "__main__":
    script_parser(__doc__, __file__).parse_args()  # --help; no options
    run_script(main, __file__)
