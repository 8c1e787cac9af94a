"""Forward-kinematics paths: what each costs, and so why each stays (see tests/test_fk_paths.py).

Per hand and batch size N: Pinocchio looped over configurations (the reference), the vectorised
numpy batch (``HandModel.frame_poses``), the CasADi expressions of ``ohra.synth.fk`` evaluated
numerically (``map`` over the batch, the cheapest numeric use of that path), and for standard-template
hands ``canonical_keypoints`` from parameter arrays against the alternative the parse fit would
otherwise need per residual evaluation: render the URDF and build a ``HandModel``.

Run: python benchmarks/bench_fk_paths.py -> benchmarks/results/fk_paths.{json,md}
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_of, run_script, script_parser, write_results  # noqa: E402

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402
from ohra.canonical.urdfgen import template_name  # noqa: E402
from ohra.hands import get_hand, registry  # noqa: E402
from ohra.synth.fk import frame_transforms  # noqa: E402

HANDS = [("leap_3333", None), ("shadow_hand_right", "base"), ("allegro_hand_right", "extended")]
SIZES = (1, 64, 4096)


def casadi_batch(hm: HandModel, frames: list[str]):
    """(N,22) -> (N,F,4,4) through the CasADi FK, one ``map`` call per batch."""
    q = ca.SX.sym("q", 22)
    f = ca.Function("fk", [q], [ca.horzcat(*[ca.vertcat(ca.reshape(R, 9, 1), p) for R, p in frame_transforms(hm, q, frames)])])
    F = len(frames)

    def run(Q: np.ndarray) -> np.ndarray:
        N = Q.shape[0]
        out = np.asarray(f.map(N)(Q.T)).reshape(12, F, N, order="F")
        T = np.zeros((N, F, 4, 4))
        T[..., 3, 3] = 1.0
        T[..., :3, :3] = out[:9].reshape(3, 3, F, N, order="F").transpose(3, 2, 0, 1)
        T[..., :3, 3] = out[9:].transpose(2, 1, 0)
        return T

    return run


def keypoints_fn(params):
    from ohra.original.keypoints import canonical_keypoints, ext_arrays, ext_arrays_from_base

    arr = ext_arrays_from_base(params.to_vector(), params.present_joints) if isinstance(params, BaseParams) else ext_arrays(params)
    return lambda Q: canonical_keypoints(arr, params.present_joints, Q)


def measure(name: str, form: str | None) -> list[dict]:
    params = get_hand(name) if form is None else registry.registered_params(name, form)
    hm = HandModel.from_params(params)
    frames = list(hm.frame_names)
    cas = casadi_batch(hm, frames)
    kp = None if template_name(params) == "leap.urdf.j2" else keypoints_fn(params)
    build = best_of(lambda: HandModel.from_params(params), 5)
    rows = []
    for n in SIZES:
        Q = hm.random_configurations(n, seed=0)
        assert np.allclose(cas(Q), hm.frame_poses(Q), atol=1e-9)
        loop = Q[: min(n, 256)]
        rows.append({
            "hand": name, "form": form or "leap variant", "frames": len(frames), "N": n,
            "pinocchio_ms": best_of(lambda: [hm.frame_poses(q) for q in loop]) * 1e3 * n / len(loop),
            "numpy_ms": best_of(lambda: hm.frame_poses(Q) if n > 1 else hm.frame_poses(Q[0])) * 1e3,
            "casadi_ms": best_of(lambda: cas(Q)) * 1e3,
            "keypoints_ms": best_of(lambda: kp(Q)) * 1e3 if kp else None,
            "render_and_build_ms": build * 1e3,
        })
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    rows = [r for name, form in HANDS for r in measure(name, form)]
    ms = lambda v: "–" if v is None else f"{v:.2f}"  # noqa: E731
    lines = [
        "Time [ms] for N configurations, all link and tip frames (best of 3; Pinocchio: its C++ FK looped in Python, "
        "extrapolated from at most 256 configurations). `canonical_keypoints` (joint origins and tips from parameter "
        "arrays) applies to standard-template hands only; the parse fit would otherwise render a URDF and build a "
        "HandModel per residual evaluation (last column).",
        "",
        "| hand | form | N | Pinocchio loop | numpy batch | CasADi (map) | canonical_keypoints | render + build |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['hand']} | {r['form']} | {r['N']} | {ms(r['pinocchio_ms'])} | {ms(r['numpy_ms'])} | "
                     f"{ms(r['casadi_ms'])} | {ms(r['keypoints_ms'])} | {ms(r['render_and_build_ms'])} |")
    write_results("fk_paths", {"rows": rows}, "\n".join(lines))


if __name__ == "__main__":
    script_parser(__doc__, __file__).parse_args()  # --help; no options
    run_script(main, __file__)
