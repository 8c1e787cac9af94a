"""``ohra train vae`` and ``ohra vae encode|decode|interpolate``: the morphology VAE from the shell.

Plugged into :mod:`ohra.cli.main` through ``register(subparsers)``; ``train`` is a group other modules may
add to (:func:`ohra.cli.main.subcommand_group`).
torch is imported only when a command runs (a missing torch is a one-line error).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from ohra.cli.main import subcommand_group, wrote
from ohra.errors import OhraError


def register(sub) -> None:
    """Add ``train vae`` and ``vae encode|decode|interpolate`` to the top-level subparsers ``sub``."""
    from ohra.learn.config import TrainConfig

    d = TrainConfig()
    train = subcommand_group(sub, "train", "train learned models", "train_command")
    p = train.add_parser("vae", help="train the morphology VAE on synthetic hands")
    p.add_argument("--samples", type=int, default=d.samples, help=f"synthetic training hands (default {d.samples})")
    p.add_argument("--epochs", type=int, default=d.epochs, help=f"epochs (default {d.epochs})")
    p.add_argument("--seed", type=int, default=d.seed, help=f"seed of data, init and noise (default {d.seed})")
    p.add_argument("--batch-size", type=int, default=d.batch_size, help=f"default {d.batch_size}")
    p.add_argument("--threads", type=int, default=d.threads, help=f"torch CPU threads (default {d.threads})")
    p.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every, help=f"epochs between checkpoints (default {d.checkpoint_every})")
    p.add_argument("--heldout", type=int, default=d.heldout,
                   help=f"number of sampled hands held out for the final metrics (default {d.heldout})")
    p.add_argument("-o", "--output", "--out", dest="output", default="out/vae", help="run directory (default out/vae)")
    p.add_argument("--resume", action="store_true", help="continue from OUTPUT/checkpoints/last.pt")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train_vae)

    vae = subcommand_group(sub, "vae", "use the morphology VAE: encode, decode, interpolate hands", "vae_command")
    model_help = "model directory or .pt file (default: the shipped model)"
    p = vae.add_parser("encode", help="print the latent mean and log-variance of hands")
    p.add_argument("hands", nargs="+", help="registered hands or base params JSON files")
    p.add_argument("--model", help=model_help)
    p.set_defaults(func=_cmd_encode)

    p = vae.add_parser("decode", help="decode a latent vector into base params JSON")
    p.add_argument("latent", help="comma-separated numbers, or a .json / .npy file with one latent (a first number "
                   "below 0: put -- before it, after the options, e.g. ohra vae decode -o h.json -- -0.1,0.2,...)")
    p.add_argument("-o", "--output", "--out", dest="output", help="params JSON path (default: stdout)")
    p.add_argument("--urdf", help="also write the canonical URDF here")
    p.add_argument("--model", help=model_help)
    p.set_defaults(func=_cmd_decode)

    p = vae.add_parser("interpolate", help="hands along a latent path between two hands: URDFs, PNG strip "
                       "(the two original hands beside the decoded ends), meshcat HTML")
    p.add_argument("hand_a")
    p.add_argument("hand_b")
    p.add_argument("-n", "--steps", type=int, default=8, help="number of hands, endpoints included (default 8)")
    p.add_argument("--spacing", choices=("geodesic", "arc", "even"), default="geodesic",
                   help="geodesic (default): a bent latent path of short fingertip travel, at equal fingertip arc "
                   "length (4 s per pair on average, up to ~10 s, in bench_vae on one free core); arc: the straight latent line at equal fingertip arc length; even: the straight "
                   "line at even latent steps")
    p.add_argument("-o", "--output", "--out", dest="output", required=True, help="output directory")
    p.add_argument("--model", help=model_help)
    p.add_argument("--no-png", action="store_true", help="skip the PNG strip")
    p.add_argument("--no-html", action="store_true", help="skip the meshcat HTML scene")
    p.set_defaults(func=_cmd_interpolate)


# -- commands ---------------------------------------------------------------------------------------
def _positive(name: str, value: int) -> None:
    if value <= 0:
        raise OhraError(f"--{name} must be positive, got {value}")


def _cmd_train_vae(args: argparse.Namespace) -> int:
    from ohra.learn import require_torch

    require_torch()
    from ohra.learn.config import TrainConfig
    from ohra.learn.train_vae import train

    for name in ("samples", "epochs", "batch_size", "threads", "checkpoint_every"):
        _positive(name.replace("_", "-"), getattr(args, name))
    if args.heldout < 0:
        raise OhraError(f"--heldout must be >= 0, got {args.heldout}")
    cfg = TrainConfig(samples=args.samples, epochs=args.epochs, seed=args.seed, batch_size=args.batch_size,
                      threads=args.threads, checkpoint_every=args.checkpoint_every, heldout=args.heldout)
    out = Path(args.output)
    if not args.resume and (out / "checkpoints" / "last.pt").exists():
        raise OhraError(f"{out} already holds a training run; pass --resume to continue it or choose another -o")
    res = train(cfg, out, resume=args.resume, progress=not args.quiet)
    m = res.metrics
    print(f"trained {m['epochs']} epochs ({m['steps']} steps) in {m['train_seconds_total']:.1f} s; final loss {m['final_losses'].get('total', float('nan')):.4f}")
    if "heldout" in m:
        h = m["heldout"]
        print(f"held-out ({h['n']} hands): presence {100 * h['presence_accuracy']:.2f} %, thumb axes {100 * h['axis_accuracy']:.2f} %")
    wrote(f"{out / 'model.pt'} and {out / 'metrics.json'}")
    return 0


def _load(model: str | None):
    from ohra.learn import require_torch

    require_torch()
    from ohra.learn.morph import load_vae

    return load_vae(model)


def _warnings_to_stderr(caught: list) -> None:
    for w in caught:
        print(f"ohra: warning: {w.message}", file=sys.stderr)


def _cmd_encode(args: argparse.Namespace) -> int:
    vae = _load(args.model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rows = {}
        for h in args.hands:
            mu, logvar = vae.encode(h)
            rows[h] = {"mu": [round(float(x), 6) for x in mu], "logvar": [round(float(x), 6) for x in logvar]}
    _warnings_to_stderr(caught)
    print(json.dumps(rows, indent=1))
    return 0


def _read_latent(text: str) -> np.ndarray:
    p = Path(text)
    if p.suffix in (".json", ".npy"):
        if not p.is_file():
            raise OhraError(f"latent file not found: {p}")
        try:
            data = np.load(p) if p.suffix == ".npy" else json.loads(p.read_text())
        except (ValueError, OSError, EOFError) as exc:  # EOFError: an empty .npy
            raise OhraError(f"{p}: cannot read a latent ({exc or type(exc).__name__})") from None
        if isinstance(data, dict):
            data = _latent_of(data, p)
        try:
            z = np.asarray(data, dtype=float)
        except (TypeError, ValueError):
            raise OhraError(f"{p}: expected a list of numbers") from None
        return _finite(z, str(p))
    fields = text.replace(" ", "").split(",")
    if "" in fields[:-1] or (len(fields) > 1 and fields[0] == ""):  # "0.1,,0.2": a number left out, not a shorter latent
        raise OhraError(f"latent: an empty field in {text!r}")
    try:
        z = np.array([float(x) for x in fields if x != ""])
    except ValueError:
        raise OhraError(f"latent: expected comma-separated numbers, got {text!r}") from None
    return _finite(z, "latent")


def _latent_of(data: dict, path: Path) -> object:
    """The latent a JSON object holds: its ``z`` or ``mu``, or the ``mu`` of the one hand ``ohra vae encode`` wrote."""
    if "z" in data or "mu" in data:
        return data.get("z", data.get("mu"))
    encoded = {k: v for k, v in data.items() if isinstance(v, dict) and "mu" in v}
    if len(encoded) == 1 and len(data) == 1:
        return next(iter(encoded.values()))["mu"]
    if encoded:
        raise OhraError(f"{path}: holds the encodings of {len(encoded)} hands ({', '.join(encoded)}): decode one at a time "
                        "(ohra vae encode HAND > one.json)")
    raise OhraError(f"{path}: expected {{\"z\": [...]}}, {{\"mu\": [...]}} or what ohra vae encode writes for one hand, "
                    f"got keys {sorted(data)}")


def _finite(z: np.ndarray, where: str) -> np.ndarray:
    if not np.all(np.isfinite(z)):
        raise OhraError(f"{where}: every number must be finite, got {z.ravel()[~np.isfinite(z.ravel())][:3].tolist()}")
    return z


def _cmd_decode(args: argparse.Namespace) -> int:
    from ohra.io import check_output, check_suffix

    if args.output and args.urdf and Path(args.output).resolve() == Path(args.urdf).resolve():
        raise OhraError(f"-o and --urdf name the same file ({args.output}): the URDF would overwrite the params JSON")
    for out, suffix, flag in ((args.output, ".json", "-o"), (args.urdf, ".urdf", "--urdf")):  # both before either is written
        if out:
            check_suffix(check_output(out), suffix, flag)
    z = _read_latent(args.latent)  # before the model loads (seconds): a typo is told at once
    vae = _load(args.model)
    params = vae.decode(z)
    if isinstance(params, list):
        raise OhraError(f"latent: expected one vector of {vae.latent_dim} numbers, got shape {z.shape} (decode "
                        "several with ohra.learn.load_vae().decode(Z) in Python)")
    if args.output:
        params.to_json(args.output)
        wrote(args.output)
    else:
        sys.stdout.write(params.to_json())
    if args.urdf:
        from ohra.canonical.urdfgen import write

        write(params, args.urdf)
        wrote(args.urdf)
    return 0


def _cmd_interpolate(args: argparse.Namespace) -> int:
    if args.steps < 2:
        raise OhraError(f"-n must be at least 2, got {args.steps}")
    from ohra.io import check_output

    check_output(args.output, folder=True)
    vae = _load(args.model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        interp = vae.interpolate(args.hand_a, args.hand_b, args.steps, args.spacing)
    _warnings_to_stderr(caught)
    out = Path(args.output)
    paths = interp.write(out)
    wrote(f"{len(paths)} URDFs to {out}")
    for p, params in zip(paths, interp.params):
        print(f"  {p.name}: {params.num_fingers} fingers, {params.dof} dof, {params.handedness} hand")
    if not args.no_png:
        from ohra.learn.strip import strip_png

        png = strip_png(interp.params, out / "strip.png", labels=interp.labels(), originals=interp.labelled_originals())
        wrote(png)
    if not args.no_html:
        from ohra.learn.strip import sequence_html

        where = ", ".join(f"{a:.2f}" for a in interp.alphas)
        html = sequence_html(interp.params, out / "scene.html", originals=interp.originals,
                             caption=f"{args.hand_a} -> {args.hand_b}: decoded hands left to right at path fraction a = {where}"
                                     + ("; grey, above the ends: the two hands as given" if interp.originals is not None else ""))
        wrote(html)
    return 0
