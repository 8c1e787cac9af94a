"""The ``ohra`` command: one parser, one module per command group, one way to fail.

Command groups live in ``ohra/cli/<module>.py`` and are listed, in help order, in :data:`COMMANDS`.
Each module exposes ``register(subparsers) -> None``, which adds its parser(s) to the top-level
subparsers and sets ``func(args) -> int`` (the exit code) on every leaf parser. To add a group (e.g.
``ohra/cli/data.py``, ``rotate.py``, ``grasp.py``):

1. write the module with ``register(subparsers)``; build sub-parsers with ``subparsers.add_parser``
   (they are :class:`Parser`, so usage errors stay one line); a group shared between modules, such as
   ``ohra train vae`` here and ``ohra train grasp`` elsewhere, comes from :func:`subcommand_group`;
2. add the module name to :data:`COMMANDS`.

Modules are imported by name and nothing is skipped: a module that is missing, fails to import or has
no ``register`` is an error when the parser is built (and ``tests/test_cli.py`` builds it). Heavy
imports (torch, PyBullet, CasADi) belong inside the command functions, so ``ohra --help`` stays fast.

A command signals bad input by raising :class:`ohra.OhraError`; :func:`execute` turns it (and missing
files) into one line on stderr and exit code 2, as argparse does for bad usage.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import threading
import warnings
from pathlib import Path
from typing import Sequence

from ohra.errors import OhraError

COMMANDS = ("hand", "eval", "synth", "data", "learn", "grasp", "rotate")
"""Command modules under ``ohra.cli``, registered in this order (``learn`` adds ``train`` and ``vae``;
``grasp`` adds ``grasp`` and ``train grasp``)."""

EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in one line (``PROG: error: MESSAGE``) with exit code 2, and leaves
    in the parsed namespace (``_options``) the options of the command that parsed it, by destination."""

    def __init__(self, *args, **kwargs) -> None:
        # no prefixes of long options: `--hand` would read as a top-level `--hands-path` in one release and be
        # ambiguous in the next, whenever an option is added
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        # set before parsing: a subcommand's parser parses into a namespace of its own, copied over this one
        namespace = argparse.Namespace() if namespace is None else namespace
        options: dict[str, str] = {}
        for a in self._actions:  # a destination's first option (--form before its shorthand --extended), long if any
            if a.option_strings:
                options.setdefault(a.dest, next((o for o in a.option_strings if o.startswith("--")), a.option_strings[0]))
        namespace._options = options
        return super().parse_known_args(args, namespace)


def option_names(message: str, options: dict[str, str]) -> str:
    """``message`` with a leading setting name that is an option of the command (``batch_size must be >= 1``,
    ``GraspTrainConfig.batch_size must be ...``) named as the user typed it (``--batch-size must be >= 1``)."""
    m = re.match(r"(?:[A-Z]\w*\.)?([a-z_]\w*) must ", message)
    if m and m.group(1) in options:
        return options[m.group(1)] + message[m.end(1):]
    return message


_Parser = Parser  # the name this class had before the CLI became a package


# a group several command modules add to keeps one help text, whichever module registers it first
BODY_HELP = ("the body object files are grasped and simulated as: auto (default: the hull of a convex mesh, else the "
             "nearest to the mesh of the hull, a provided decomposition and V-HACD), hull, provided (collision_vhacd.obj "
             "beside the mesh or the URDF's collisions), vhacd; built-in and procedural shapes keep their exact solids")
BODY_CHOICES = ("auto", "hull", "provided", "vhacd")  # ohra.objects.model.BODY_CHOICES (a test holds them equal)

SHARED_GROUP_HELP = {"train": "train learned models: vae, grasp, rotate"}


def wrote(what: str | Path) -> None:
    """Announce a file (or folder) the command wrote: one ``wrote WHAT`` line on stderr, so that stdout carries only
    the command's data and results (URDFs, JSON, tables, summaries)."""
    print(f"wrote {what}", file=sys.stderr)


def subcommand_group(sub: argparse._SubParsersAction, name: str, help_text: str, dest: str) -> argparse._SubParsersAction:
    """The subparsers of top-level command ``name`` (``ohra NAME WHAT ...``), created on first use.

    Lets several command modules add to one group (``ohra train vae``, ``ohra train grasp``); such a
    group's help is :data:`SHARED_GROUP_HELP`'s, not ``help_text``.
    """
    parser = sub.choices.get(name)
    if parser is None:
        parser = sub.add_parser(name, help=SHARED_GROUP_HELP.get(name, help_text))
        group = parser.add_subparsers(dest=dest, metavar="WHAT", parser_class=type(parser))
        group.required = True
        return group
    for action in parser._actions:  # argparse keeps the subparsers action among the parser's actions
        if isinstance(action, argparse._SubParsersAction):
            return action
    raise RuntimeError(f"command {name!r} exists without subcommands")


def build_parser(prog: str = "ohra") -> argparse.ArgumentParser:
    """The full ``ohra`` parser: every module of :data:`COMMANDS` registered (import errors propagate)."""
    from ohra import __version__

    parser = Parser(prog=prog, description="Canonical dexterous hands: render, inspect, parse, evaluate, synthesise, learn.",
                    epilog="Run 'ohra COMMAND --help' for a command's options. Exit codes: 0 ok, 2 bad input or usage.")
    parser.add_argument("--version", action="version", version=f"ohra {__version__}")
    parser.add_argument("--hands-path", "--hands", action="append", default=[], metavar="DIR", dest="hands_dirs",
                        help="user hand folder: its *.yaml specs join the registry (also $OHRA_HANDS_PATH; --hands is its older spelling)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True
    for name in COMMANDS:
        module = importlib.import_module(f"ohra.cli.{name}")
        register = getattr(module, "register", None)
        if not callable(register):
            raise TypeError(f"command module ohra.cli.{name} has no register(subparsers) function")
        register(sub)
    return parser


def _one_line_warnings(previous):
    """A ``warnings.showwarning`` that prints ohra's own warnings (estimated mass properties,
    approximated bodies, parser notes) as one line, ``ohra: warning: MESSAGE``, like its errors; other
    packages' warnings go to ``previous`` (Python's format, with file and line)."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        where = Path(filename).resolve()
        # ohra's warnings point at the caller's frame (user_stacklevel): under the CLI, the console script itself
        ours = (category.__module__.startswith("ohra") or where.is_relative_to(_PACKAGE)
                or (bool(sys.argv[0]) and where == Path(sys.argv[0]).resolve()) or where.name == "runpy.py")
        if not ours:
            return previous(message, category, filename, lineno, file, line)
        try:
            print(f"ohra: warning: {message}", file=file if file is not None else sys.stderr)
        except OSError:  # stderr closed (e.g. a cut pipe): the warning is lost, as with Python's own
            pass

    return show


_PACKAGE = Path(__file__).resolve().parents[1]


def execute(args: argparse.Namespace) -> int:
    """Run the command parsed into ``args`` (its ``func``); user errors become one stderr line and exit 2."""
    from ohra.sim.pybullet_import import import_pybullet

    shown = warnings.showwarning
    warnings.showwarning = _one_line_warnings(shown)
    handlers = _stop_on_termination()
    try:
        import_pybullet()  # done once, after parsing: `ohra --help` does not pay the import; Ctrl-C here is one line too
        for folder in getattr(args, "hands_dirs", ()):
            from ohra.hands.registry import add_hands_path

            add_hands_path(folder)
        return int(args.func(args) or 0)
    except OhraError as exc:
        # a command whose options are not named as the library's fields renames them itself (``messages``)
        message = getattr(args, "messages", lambda m: m)(str(exc))
        print(f"ohra: error: {option_names(message, getattr(args, '_options', {}))}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        print(f"ohra: error: {exc.strerror or exc}: {exc.filename}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        sys.stderr.close()  # output was cut short by its reader (e.g. `| head`): not an error
        return 0
    except KeyboardInterrupt:
        # every command with --resume keeps its finished work (checkpoints, shards): say how to continue it
        hint = "; the same command with --resume continues it" if hasattr(args, "resume") else ""
        print(f"ohra: interrupted{hint}", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def _terminate(signum, frame) -> None:
    # meshcat's server runs in its own session, so the signal does not reach it: stop it, then end as the default
    # action would (at once; files are written atomically). Raising into the command instead ran its cleanup, which
    # could block on the meshcat connection under load.
    viz = sys.modules.get("ohra.viz")
    for proc in list(getattr(viz, "SERVERS", ())):
        try:
            proc.kill()
        except OSError:
            pass
    if "multiprocessing" in sys.modules:  # pool workers (default handlers: they end quietly), not left to find a broken pipe
        import multiprocessing

        for child in multiprocessing.active_children():
            child.terminate()
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


def _stop_on_termination() -> dict:
    """SIGTERM (a scheduler, `timeout`, `kill`) and SIGHUP (a closed terminal) still end a command at once, but first
    stop the meshcat servers it started (they outlived it, holding their ports). Returns the handlers to put back
    (none outside the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    old = {}
    for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None and signal.getsignal(sig) in (signal.SIG_DFL, None):
            old[sig] = signal.signal(sig, _terminate)
    return old


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ohra`` console script and ``python -m ohra.cli``."""
    return execute(build_parser().parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
