"""Train grasp models on a machine that has torch but not ohra's simulation stack (a GPU box).

``ohra.canonical`` imports Pinocchio and Coal at module level, and a few modules reachable from the
training path import CasADi or PyBullet, although training itself calls none of them (it reads the
committed datasets, the object meshes and the VAE). On a machine where those wheels are not installed
(GPU images usually lack them, and they are hundreds of MB), :func:`stand_in_for_missing` puts an
empty module in their place whose every attribute access raises ``ImportError`` naming the package:
a code path that does need one fails loudly instead of silently doing something else.

Never used by the library or the tests; benchmark scripts call it only under ``--torch-only``.
"""

from __future__ import annotations

import importlib.util
import sys
import types

SIM_STACK = ("pinocchio", "coal", "casadi", "pybullet", "pybullet_data")


class _Missing(types.ModuleType):
    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        raise ImportError(f"{self.__name__}.{attr}: {self.__name__} is not installed on this machine "
                          "(--torch-only stands in an empty module; this code path needs the real package)")


def stand_in_for_missing(names: tuple[str, ...] = SIM_STACK, force: bool = False) -> list[str]:
    """Register an empty stand-in for each of ``names`` that cannot be imported (every one of them when
    ``force``: a test of this path on a machine that has them). Returns the names stood in for."""
    done = []
    for name in names:
        if name in sys.modules and not force:
            continue
        if force or importlib.util.find_spec(name) is None:
            sys.modules[name] = _Missing(name)
            done.append(name)
    return done


def train_in_parallel(script: str, args, option: str, items: list[str]) -> None:
    """Run ``script train`` once per item (``option ITEM``), all at once, with the training settings of ``args``
    (a GPU has room for several runs; each draws its batches on its own CPU cores). Exits naming the failed ones."""
    import subprocess

    base = [sys.executable, script, "train", "--device", args.device, "--steps", str(args.steps), "--runs", args.runs,
            "--threads", str(args.threads), "--batch-size", str(args.batch_size), "--seed", str(args.seed), "--quiet",
            "--data", *args.data] + (["--torch-only"] if args.torch_only else [])
    procs = [subprocess.Popen(base + [option, item]) for item in items]
    codes = [p.wait() for p in procs]
    if any(codes):
        raise SystemExit(f"training failed: exit codes {dict(zip(items, codes))}")


def run_phase(args, train, evaluate, prog: str) -> None:
    """The two-phase benchmarks' entry: stand-ins under ``--torch-only`` (all of them with
    ``OHRA_FORCE_TORCH_ONLY=1``), then ``train(args)`` or ``evaluate(args)``; an ohra error is one line."""
    import os

    if args.torch_only:
        stood = stand_in_for_missing(force=os.environ.get("OHRA_FORCE_TORCH_ONLY") == "1")
        if stood:
            print(f"--torch-only: stand-ins for {', '.join(stood)}", file=sys.stderr)
    from ohra.errors import OhraError

    try:
        (train if args.phase == "train" else evaluate)(args)
    except OhraError as exc:
        raise SystemExit(f"{prog}: {exc}") from None
