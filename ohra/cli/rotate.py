"""``ohra rotate grasps|train|eval|plot`` (training also as ``ohra train rotate``): in-hand rotation from the shell.

Plugged into :mod:`ohra.cli.main` through ``register(subparsers)``; every parser sets
``func(args) -> int``. Also runnable alone: ``python -m ohra.cli.rotate train ...``.
gymnasium / stable-baselines3 / torch are imported only when a command runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Sequence

from ohra.cli.main import wrote
from ohra.errors import OhraError


# command-line option -> RotationConfig field; the options default to None (= not given), so a resume or a
# run started from another can tell an option given at the default value from one left out
_ENV_FIELDS = (("hand", "hand"), ("urdf", "urdf"), ("inertials", "inertials"), ("form", "form"), ("space", "space"),
               ("object", "object"), ("object_size", "object_size"), ("grasps", "grasp_count"))


# RotationConfig's defaults, named in the help texts (a test keeps them equal): importing ohra.sim while the
# parser is built would import PyBullet before ohra.cli.main silences its build-time line
HELP_DEFAULTS = {"hand": "leap_hand_right", "urdf": "canonical", "object": "cube", "grasp_count": 1000}


def _env_args(p: argparse.ArgumentParser) -> None:
    d = HELP_DEFAULTS
    p.add_argument("--hand", help=f"registered hand, leap_XXXX, hand spec YAML or params JSON (default {d['hand']})")
    p.add_argument("--urdf", choices=("canonical", "original"), help=f"default {d['urdf']}")
    p.add_argument("--inertials", choices=("capsule", "original"),
                   help="canonical URDF: finger masses of the template's capsules (default) or of the original URDF")
    p.add_argument("--form", choices=("base", "extended"), help="canonical form (default: extended when registered)")
    p.add_argument("--space", choices=("canonical", "native"), help="joint space of actions (default: by --urdf)")
    p.add_argument("--object", help=f"cube, sphere, cylinder (default {d['object']}), builtin:NAME, "
                   "procedural:FAMILY:SEED, or a mesh/URDF file or one-object folder")
    p.add_argument("--object-size", type=float, metavar="M",
                   help="cube side / sphere, cylinder diameter (default: the palm radius); a mesh file's largest extent")
    p.add_argument("--grasps", type=int, help=f"cached starting states (default {d['grasp_count']})")
    p.add_argument("--set", action="append", default=[], metavar="KEY=JSON",
                   help="any other RotationConfig field, e.g. --set sim_dt=0.0166 (repeatable)")


def _given_env(args: argparse.Namespace) -> dict[str, Any]:
    """The environment options given on the command line, as RotationConfig fields, and the --set items."""
    from ohra.sim.rotation.config import RotationConfigError

    given = {field: getattr(args, opt) for opt, field in _ENV_FIELDS if getattr(args, opt) is not None}
    sets = _key_values(args.set, "--set", RotationConfigError)
    option = {field: opt for opt, field in _ENV_FIELDS}
    both = [k for k in sets if k in given]
    if both:  # one would silently win over the other
        k = both[0]
        raise RotationConfigError(f"--set {k}={json.dumps(sets[k])} and --{option[k].replace('_', '-')} {given[k]} both "
                                  f"set {k}: give it once")
    given.update(sets)
    return given


def _env_config(args: argparse.Namespace):
    from ohra.sim.rotation.config import RotationConfig

    return RotationConfig.from_dict(_given_env(args), "command line")


def _key_values(items: Sequence[str], flag: str, error: type[OhraError]) -> dict[str, Any]:
    """``KEY=JSON`` items as a dict (a value that is not JSON stays a string)."""
    kw: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise error(f"{flag} expects KEY=VALUE, got {item!r}")
        try:
            kw[key] = json.loads(value)
        except json.JSONDecodeError:
            kw[key] = value
    return kw


TRAIN_HELP = "train a PPO rotation policy (resumable)"


def _train_args(p: argparse.ArgumentParser) -> None:
    """``ohra rotate train`` = ``ohra train rotate``."""
    from ohra.learn.rl.config import PPOSettings

    d = PPOSettings()
    _env_args(p)
    p.add_argument("--steps", type=int, help=f"total env steps (default {d.total_steps}; on --resume: the run's)")
    p.add_argument("--minutes", type=float, help="wall-clock budget over all sessions (stops and saves)")
    src = "; with --init-from: the source's"
    p.add_argument("--seed", type=int, help=f"default {d.seed}{src}")
    p.add_argument("--envs", type=int, help=f"subprocess environments (default {d.n_envs}{src})")
    p.add_argument("--n-steps", type=int, help=f"steps per env per rollout (default {d.n_steps}{src})")
    p.add_argument("--batch-size", type=int, help=f"default {d.batch_size}{src}")
    p.add_argument("--checkpoint-every", type=int, help=f"steps between checkpoints (default {d.checkpoint_every}{src})")
    p.add_argument("--policy", choices=("mlp", "lstm"), help=f"policy network: MLP {'-'.join(map(str, d.net_arch))} "
                   f"(default) or a recurrent one, an LSTM of {d.lstm_hidden} units before it (sb3-contrib RecurrentPPO)")
    p.add_argument("--ppo", action="append", default=[], metavar="KEY=JSON",
                   help="any other PPOSettings field, e.g. --ppo kl_target=null for a constant learning rate (repeatable; "
                        "with --resume only the run's own values: a resumed run keeps its settings)")
    p.add_argument("-o", "--output", "--out", dest="output", required=True, help="run directory")
    p.add_argument("--resume", action="store_true", help="continue OUTPUT from its last checkpoint")
    p.add_argument("--init-from", metavar="RUN", help="a new run that starts from RUN's trained policy and settings "
                   "(RUN: a run, an exported policy, or a shipped one by name such as leap_canonical) "
                   "(a fine-tune): options given here change them, e.g. --set 'weights={\"fall\": -25}'; "
                   "--steps and --minutes count the new run only")
    p.add_argument("--tensorboard", action="store_true", help="also log to OUTPUT/tensorboard (tensorboard --logdir OUTPUT)")
    p.set_defaults(func=_cmd_train, messages=flag_names)


FLAGS = {"RotationConfig.grasp_count": "--grasps", "RotationConfig.object_size": "--object-size",
         "PPOSettings.total_steps": "--steps", "PPOSettings.max_minutes": "--minutes", "PPOSettings.seed": "--seed",
         "PPOSettings.n_envs": "--envs", "PPOSettings.n_steps": "--n-steps", "PPOSettings.batch_size": "--batch-size",
         "PPOSettings.checkpoint_every": "--checkpoint-every"}
"""The settings that have an option of their own, as the library's errors name them (``Class.field``)."""


def flag_names(message: str) -> str:
    """``message`` with every setting that has an option of its own named by that option: ``PPOSettings.n_envs
    must be >= 1`` -> ``--envs must be >= 1``; the bare ``n_envs x n_steps ... batch_size`` too. Settings without one
    (``--set``, ``--ppo``) and messages about those options keep the field names, which are what they take."""
    import re

    for key, flag in FLAGS.items():
        message = message.replace(key, flag)
    if "must be a multiple of batch_size" in message:  # PPOSettings names these three bare
        for field in ("n_envs", "n_steps", "batch_size"):
            message = re.sub(rf"(?<![\w.-]){field}(?![\w=])", FLAGS[f"PPOSettings.{field}"], message)
    return message


def register(sub: Any) -> None:
    from ohra.cli.main import subcommand_group

    rot = sub.add_parser("rotate", help="in-hand rotation: starting grasps, PPO training, evaluation")
    rs = rot.add_subparsers(dest="rotate_command", metavar="WHAT", parser_class=type(rot))
    rs.required = True

    p = rs.add_parser("grasps", help="generate (or load) the cached starting states and print where they are")
    _env_args(p)
    p.set_defaults(func=_cmd_grasps, messages=flag_names)

    _train_args(rs.add_parser("train", help=TRAIN_HELP))
    # the same command under the train group, beside ``ohra train vae`` and ``ohra train grasp``
    _train_args(subcommand_group(sub, "train", "train learned models", "train_command")
                .add_parser("rotate", help=TRAIN_HELP))

    p = rs.add_parser("eval", help="Steps-to-Fall and Cumulative Rotation of a trained run; renders an episode")
    p.add_argument("run", help="run directory, or a shipped policy by name (rotate_leap_canonical, or leap_canonical; "
                                "its results go to ./NAME unless -o says where)")
    p.add_argument("-o", "--output", "--out", dest="out", help="folder for eval*.json and episode*/ (default: the run directory)")
    p.add_argument("--episodes", type=int, default=20, help="seeded episodes (default 20)")
    p.add_argument("--seed", type=int, default=1000, help="first episode seed (default 1000)")
    p.add_argument("--checkpoint", choices=("model", "last"), default="model", help="the final model (default) or the last checkpoint")
    p.add_argument("--render", action="store_true", help="also write OUT/episode/{rollout.gif,strip.png}")
    p.add_argument("--replay", action="store_true", help="also write OUT/episode/replay.html (meshcat)")
    p.add_argument("--on-urdf", choices=("canonical", "original"),
                   help="run the policy on the hand's other URDF through the canonical joint space (a policy "
                        "trained with space canonical); writes OUT/eval_on_URDF.json and OUT/episode_on_URDF/; the first "
                        "use generates that URDF's starting states (minutes; cached)")
    p.set_defaults(func=_cmd_eval, messages=flag_names)

    p = rs.add_parser("plot", help="reward curves, mean +- std over seeds: LABEL=RUN[,RUN...] per group")
    p.add_argument("groups", nargs="+", metavar="LABEL=RUNS",
                   help="a label and its runs: training run folders or shipped policies by name (leap_canonical)")
    p.add_argument("-o", "--output", "--out", dest="output", required=True, help="PNG path")
    p.add_argument("--key", default="ep_reward_mean", help="progress.csv column (default ep_reward_mean)")
    p.set_defaults(func=_cmd_plot)


def _cmd_grasps(args: argparse.Namespace) -> int:
    from ohra.sim.rotation.grasps import cache_path, load_or_generate
    from ohra.sim.rotation.task import resolve

    task = resolve(_env_config(args))
    gs = load_or_generate(task, progress=sys.stderr.isatty())
    print(f"{len(gs)} starting states ({gs.attempts} tried) for {task.hand.name} + {task.obj.name}: {cache_path(task)}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from ohra.learn.rl import require_rl
    from ohra.learn.rl.config import PPOSettings, RLConfigError

    require_rl()
    from ohra.learn.rl.train import load_run, train_rotation, with_budget

    out = Path(args.output)
    from ohra.io import check_output

    check_output(out, folder=True)  # before the starting grasps are made (minutes), not only at the run's lock
    extra = _key_values(args.ppo, "--ppo", RLConfigError)
    if args.resume:
        if args.init_from:
            raise RLConfigError("--init-from starts a new run; --resume continues OUTPUT from its own checkpoint")
        env_cfg, ppo = load_run(out)
        _same_as_run(args, env_cfg, ppo, out, {**extra, **({"policy": args.policy} if args.policy else {})})
        ppo = with_budget(ppo, args.steps, args.minutes)
        if args.checkpoint_every is not None:
            from dataclasses import replace

            ppo = replace(ppo, checkpoint_every=int(args.checkpoint_every))
    else:
        # a new run's own budget and the PPO options given; the rest from the source (--init-from) or the defaults
        given = {"total_steps": PPOSettings().total_steps if args.steps is None else args.steps, "max_minutes": args.minutes,
                 **_given_ppo(args), **({"policy": args.policy} if args.policy else {}), **extra}
        if args.init_from:
            from ohra.learn.rl.evaluate import policy_dir

            args.init_from = str(policy_dir(args.init_from))  # a run, an export, or a shipped policy by name
            env_cfg, ppo = load_run(args.init_from)
            env_cfg = env_cfg.with_overrides(**_given_env(args))
            given = {**ppo.to_dict(), **given}
        else:
            env_cfg = _env_config(args)
        ppo = PPOSettings.from_dict(given, "command line (--ppo)")
    path = train_rotation(env_cfg, ppo, out, resume=args.resume, verbose=0, tensorboard=args.tensorboard,
                          init_from=args.init_from)
    wrote(path)
    return 0


_PPO_OPTIONS = (("seed", "seed"), ("envs", "n_envs"), ("n_steps", "n_steps"), ("batch_size", "batch_size"),
                ("checkpoint_every", "checkpoint_every"))


def _given_ppo(args: argparse.Namespace) -> dict[str, Any]:
    """The PPO options (of ``_PPO_OPTIONS``) given on the command line, as PPOSettings fields."""
    return {field: getattr(args, opt) for opt, field in _PPO_OPTIONS if getattr(args, opt) is not None}


def _same_hand_file(given: str, run: str) -> bool:
    """Whether ``given`` and ``run`` are hand files (params JSON or spec YAML) holding the same canonical hand."""
    import numpy as np

    from ohra.errors import OhraError
    from ohra.hands import get_hand

    a, b = Path(given).expanduser(), Path(run)
    if not (a.is_file() and b.is_file() and a.suffix == b.suffix):
        return False
    try:
        pa, pb = get_hand(str(a)), get_hand(str(b))
    except OhraError:
        return False
    return type(pa) is type(pb) and np.array_equal(pa.to_vector(), pb.to_vector())


def _same_as_run(args: argparse.Namespace, env_cfg, ppo, out: Path, extra: dict[str, Any]) -> None:
    """On --resume, refuse environment or PPO options (``extra``: the --ppo and --policy ones) that differ from
    the run's (they would be ignored); repeating the run's own options is fine, and the budget (--steps,
    --minutes) and --checkpoint-every may change."""
    from ohra.learn.rl.config import PPOSettings, RLConfigError
    from ohra.learn.rl.train import RESUMABLE_CHANGES

    theirs, mine = env_cfg.to_dict(), env_cfg.with_overrides(**_given_env(args)).to_dict()
    for k in ("hand", "object"):  # a file given again by a relative path is the file the run names absolutely
        if (isinstance(mine[k], str) and Path(str(theirs[k])).is_absolute() and Path(mine[k]).expanduser().exists()
                and Path(mine[k]).expanduser().resolve() == Path(theirs[k]).resolve()):
            mine[k] = theirs[k]
    if isinstance(mine["hand"], str) and mine["hand"] != theirs["hand"] and _same_hand_file(mine["hand"], str(theirs["hand"])):
        mine["hand"] = theirs["hand"]  # the run keeps its own copy of a params file: the file given is that hand
    diff = [f"{k}: run {theirs[k]!r}, given {mine[k]!r}" for k in mine if mine[k] != theirs[k]]
    run_ppo = ppo.to_dict()
    given = PPOSettings.from_dict({**run_ppo, **_given_ppo(args), **extra}, "command line (--ppo)").to_dict()
    diff += [f"{k}: run {run_ppo[k]!r}, given {given[k]!r}" for k in given
             if k not in RESUMABLE_CHANGES and given[k] != run_ppo[k]]
    if diff:
        raise RLConfigError(f"{out}: a resumed run keeps the settings in {out / 'config.json'}; only --steps, "
                            f"--minutes and --checkpoint-every change on --resume (differs: {'; '.join(diff)})")


def _cmd_eval(args: argparse.Namespace) -> int:
    from ohra.learn.rl import require_rl

    require_rl()
    from ohra.learn.rl.evaluate import (evaluate_run, is_shipped, on_urdf, output_suffix, policy_dir, record_episode,
                                        replay_html)
    from ohra.learn.rl.train import load_run

    run = policy_dir(args.run)
    # a shipped policy lives in the package: its results go beside the user, not into site-packages
    dest = Path(args.out) if args.out else (Path(run.name) if is_shipped(run) else run)
    from ohra.io import check_output

    check_output(dest, folder=True)  # a file there, or no permission: one line now, not after the episodes
    res = evaluate_run(run, args.episodes, args.seed, args.checkpoint, urdf=args.on_urdf, out_dir=dest)
    own = load_run(run)[0]
    cfg, suffix = on_urdf(own, args.on_urdf), output_suffix(own, args.on_urdf)
    where = f" on the {cfg.urdf} URDF" if suffix else ""
    s = res.summary()
    print(f"Steps-to-Fall {s['steps_to_fall_mean']:.1f} +- {s['steps_to_fall_std']:.1f} (of {res.episode_steps}), "
          f"Cumulative Rotation {s['rotation_mean']:.2f} +- {s['rotation_std']:.2f} rad, "
          f"survived {100 * s['survived']:.0f} % over {res.episodes} episodes{where}")
    wrote(dest / f"eval{suffix}.json")
    ret = res.return_summary()
    print("mean episode return " + f"{ret['total']:.1f} = " + " ".join(f"{k} {v:+.1f}" for k, v in ret.items() if k != "total"))
    if args.render or args.replay:
        out = dest / f"episode{suffix}"
        ep = record_episode(run, out, seed=args.seed, which=args.checkpoint, urdf=args.on_urdf)
        print(f"episode (seed {args.seed}): {ep['steps']} steps, {ep['rotation']:.2f} rad")
        wrote(f"{ep['gif']} and {ep['strip']}")
        if args.replay:
            html = replay_html(cfg, ep["trajectory"], out / "replay.html")
            wrote(html)
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from ohra.learn.rl.evaluate import policy_dir
    from ohra.learn.rl.plots import reward_curves

    from ohra.io import check_output, check_suffix

    check_suffix(check_output(args.output), ".png", "-o")  # a PNG written to plot.html was accepted
    groups: dict[str, list[str]] = {}
    for g in args.groups:
        label, sep, runs = g.partition("=")
        items = runs.split(",")
        if not sep or not label or not all(items):
            raise OhraError(f"expected LABEL=RUN[,RUN...] (no empty label or run), got {g!r}")
        if label in groups:
            raise OhraError(f"label {label!r} is given twice: put its runs in one group, {label}=RUN,RUN")
        groups[label] = [policy_dir(r) for r in items]  # a run folder, or a shipped policy by name
    for label, runs in groups.items():
        if len({r.resolve() for r in runs}) < len(runs):  # it would count as two seeds
            raise OhraError(f"group {label!r} names one run twice: {', '.join(map(str, runs))}")
        for r in runs:
            if not (r / "progress.csv").is_file():
                raise OhraError(f"{r} has no progress.csv: give a training run's folder or a shipped policy's name")
    wrote(reward_curves(groups, args.output, key=args.key))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Standalone entry (``python -m ohra.cli.rotate ...``): ``ohra rotate ...``, failing the same way (one line, exit 2)."""
    from ohra.cli.main import main as ohra_main

    return ohra_main(["rotate", *(argv if argv is not None else sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
