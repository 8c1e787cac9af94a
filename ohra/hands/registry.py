"""Registered real hands: specs, committed params (+ couplings) and canonical URDFs.

Package hands: a spec ``ohra/hands/specs/<name>.yaml`` and, per form it is registered in, the
parser's output committed as ``ohra/hands/params/{base,extended}/<name>.json`` (with the optional
``"couplings"`` key for hands with coupled joints) and the rendered canonical URDF as
``ohra/urdf/{base,extended}/<name>.urdf``. Regenerate them after changing a spec, the parser or the
templates with::

    python -m ohra.hands.registry            # all package hands (needs the hand assets)
    python -m ohra.hands.registry shadow_hand_right

User hands, no package edits: every folder in ``$OHRA_HANDS_PATH`` (``os.pathsep``-separated) or
added with :func:`add_hands_path` (``ohra --hands-path DIR``) contributes its ``*.yaml`` specs; their
params are read from ``DIR/params/<form>/<name>.json`` when present and newer than the spec and its URDF (else
the spec is parsed, with the fit, on first use and kept for the process; a stale file is named in a warning).
``OHRA_HANDS_PATH=DIR python -m ohra.hands.registry NAME`` writes those files (and ``DIR/urdf/<form>/<name>.urdf``),
so that later processes skip the fit. A name defined twice is an error naming both files.
"""

from __future__ import annotations

import os
import sys
import warnings
from functools import lru_cache
from pathlib import Path

from ohra.canonical.couplings import Coupling, params_json, read_couplings
from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.errors import AssetsNotFoundError, HandNotFoundError, SpecError
from ohra.io import write_text
from ohra.resources import hands_data_dir, specs_dir, urdf_dir

FORMS = ("base", "extended")
PATH_ENV = "OHRA_HANDS_PATH"
_added: list[Path] = []


def add_hands_path(folder: str | Path) -> None:
    """Add a user hand folder (its ``*.yaml`` specs join the registry) for this process and the
    processes it starts (worker pools, vectorised environments): the folder is appended to
    ``$OHRA_HANDS_PATH`` too, which spawned and forkserver children read."""
    p = Path(folder).expanduser().resolve()
    if p.is_file():
        raise HandNotFoundError(f"--hands-path takes the folder that holds your spec YAMLs, got the file {p} (--hands-path {p.parent}; "
                                "or give the spec itself where a hand is asked for)")
    if not p.is_dir():
        raise HandNotFoundError(f"hand folder not found: {p}")
    if p not in _added:
        _added.append(p)
    env = [x for x in os.environ.get(PATH_ENV, "").split(os.pathsep) if x.strip()]
    if str(p) not in env:
        os.environ[PATH_ENV] = os.pathsep.join(env + [str(p)])


def hands_paths() -> tuple[Path, ...]:
    """User hand folders: ``$OHRA_HANDS_PATH`` entries, then those added with :func:`add_hands_path`."""
    env = [Path(x).expanduser().resolve() for x in os.environ.get(PATH_ENV, "").split(os.pathsep) if x.strip()]
    for p in env:
        if not p.is_dir():
            raise HandNotFoundError(f"{PATH_ENV} names {p}, which is not a folder")
    return tuple(dict.fromkeys(env + _added))


def _spec_files() -> dict[str, Path]:
    """Hand name -> spec file over the package specs and the user folders (re-read when files change)."""
    listing = tuple((p, p.stat().st_mtime_ns) for folder in (specs_dir(),) + hands_paths() for p in sorted(folder.glob("*.yaml")))
    return _spec_files_in(listing)


@lru_cache(maxsize=8)
def _spec_files_in(listing: tuple[tuple[Path, int], ...]) -> dict[str, Path]:
    """Hand name -> spec file (a file that does not parse is an error, never skipped)."""
    from ohra.original.spec import read_yaml

    out: dict[str, Path] = {}
    for p, _ in listing:
        d = read_yaml(p.read_text(), str(p))
        if not isinstance(d, dict) or "joints" not in d or "urdf" not in d:
            raise SpecError(f"{p}: not a hand spec (expected a mapping with 'urdf' and 'joints' keys)")
        name = str(d.get("name", p.stem))
        if name in out:
            raise SpecError(f"hand {name!r} is defined twice: {out[name]} and {p}")
        out[name] = p
    return out


def _is_user(name: str) -> bool:
    files = _spec_files()
    return name in files and files[name].parent != specs_dir()


def params_path(name: str, form: str) -> Path:
    """Where the params JSON of a hand and form lives (package, or ``DIR/params/<form>/`` of a user folder)."""
    files = _spec_files()
    if name in files and _is_user(name):
        return files[name].parent / "params" / form / f"{name}.json"
    return hands_data_dir() / "params" / form / f"{name}.json"


def urdf_path(name: str, form: str) -> Path:
    """Where the canonical URDF of a hand and form is written (``DIR/urdf/<form>/`` for user hands)."""
    files = _spec_files()
    if name in files and _is_user(name):
        return files[name].parent / "urdf" / form / f"{name}.urdf"
    return urdf_dir() / form / f"{name}.urdf"


def registered_hands() -> list[str]:
    """Package hands with a spec and a committed params file, and every user-folder spec."""
    return [n for n in _spec_files() if _is_user(n) or any(params_path(n, f).is_file() for f in FORMS)]


def registered_forms(name: str) -> list[str]:
    """Forms a hand is registered in (user hands without params files: the forms of their spec)."""
    forms = [f for f in FORMS if params_path(name, f).is_file()]
    if forms or not _is_user(name):
        return forms
    return [f for f in FORMS if f in spec(name).forms]


def spec_path(name: str) -> Path:
    """The spec file of a registered hand."""
    files = _spec_files()
    if name not in files:
        from ohra.hands.leap.variants import is_variant

        if is_variant(name):  # asked for where an original hand is needed (--original, compare)
            raise HandNotFoundError(f"{name} is a LEAP variant, a canonical hand with no original URDF; the original "
                                    "LEAP hand is leap_hand_right / leap_hand_left")
        raise _unknown(name)
    return files[name]


def _unknown(name: str) -> HandNotFoundError:
    msg = f"unknown hand {name!r}; registered: {', '.join(registered_hands())}"
    p = Path(str(name)).expanduser()
    if p.suffix.lower() in (".yaml", ".yml") and p.is_file():  # a spec file where a registered name is expected
        msg += (f"; a hand spec is registered by its folder: pass ohra --hands-path {p.parent} (or set $OHRA_HANDS_PATH) and "
                "the spec's name")
    return HandNotFoundError(msg)


def spec(name: str):
    """The :class:`ohra.original.spec.HandSpec` of a registered hand."""
    from ohra.original.spec import load_spec

    return load_spec(spec_path(name))


def _resolve_form(name: str, form: str | None) -> str:
    forms = registered_forms(name)
    if not forms:
        raise _unknown(name)
    if form is None:
        return forms[0]
    if form not in forms:
        raise HandNotFoundError(f"hand {name!r} is registered only in the {'/'.join(forms)} form, not {form!r}")
    return form


def _written_params(name: str, form: str) -> Path | None:
    """The params JSON to read for a hand and form, or None to parse its spec.

    A user hand's file is used only while it is newer than its spec and the spec's URDF: after either is edited
    it no longer describes the hand, so the spec is parsed instead and a warning names the command that rewrites
    the file. Package files are regenerated with the package (tests hold them to the parser).
    """
    p = params_path(name, form)
    if not p.is_file():
        return None
    if not _is_user(name):
        return p
    spec_file = _spec_files()[name]
    sources = [spec_file]
    try:
        sources.append(spec(name).urdf_path())
    except Exception:  # noqa: BLE001 - a URDF that cannot be found fails later, where it is needed, naming the path
        pass
    written = p.stat().st_mtime_ns
    newer = [str(f) for f in sources if f.is_file() and f.stat().st_mtime_ns > written]
    if not newer:
        return p
    key = (str(p), written)
    if key not in _stale_warned:
        _stale_warned.add(key)
        warnings.warn(f"{p} is older than {' and '.join(newer)} (edited since the params were written): using the "
                      f"spec parsed now; rewrite the file with: {PATH_ENV}={spec_file.parent} python -m ohra.hands.registry "
                      f"{name}", stacklevel=3)
    return None


_stale_warned: set[tuple[str, int]] = set()


def registered_params(name: str, form: str | None = None) -> BaseParams | ExtendedParams:
    """Params of a registered hand (``form`` None: base when registered, else extended)."""
    form = _resolve_form(name, form)
    p = _written_params(name, form)
    if p is not None:
        return load_params(p)
    return _parsed(name, form).params


def couplings(name: str, form: str | None = None) -> tuple[Coupling, ...]:
    """Canonical couplings of a registered hand (empty for hands without coupled joints)."""
    form = _resolve_form(name, form)
    p = _written_params(name, form)
    if p is not None:
        return read_couplings(p)
    return _parsed(name, form).couplings


def _parsed(name: str, form: str):
    """A user hand parsed on use (fit included), kept for the process while its spec is unchanged."""
    from ohra.hands.resolve import parse_spec_file

    return parse_spec_file(_spec_files()[name], form)


def load_original(name: str, hands_root: str | Path | None = None):
    """The original hand model (:class:`ohra.original.hand.OriginalHand`) of a registered hand.

    Needs the hand assets; raises :class:`ohra.AssetsNotFoundError` naming the expected path.
    """
    from ohra.original.urdf import load_urdf

    sp = spec(name)
    path = sp.urdf_path(hands_root)
    if not path.is_file():
        tried = ", ".join(str(c) for c in sp.urdf_candidates(hands_root))
        raise AssetsNotFoundError(
            f"original URDF of {name!r} not found (tried {tried}); set OHRA_HANDS_ROOT to the folder holding the hand assets"
        )
    return load_urdf(path, root_link=sp.root_link, xacro_args=sp.xacro_args)


def generate(name: str, form: str, write: bool = True):
    """Parse (with fit and overrides) and optionally write params JSON (+ couplings) and the canonical
    URDF; returns the ParseResult."""
    from ohra.canonical import urdfgen
    from ohra.original.parse import parse

    sp = spec(name)
    res = parse(sp, form, fit_params=True)
    if write:
        p = params_path(name, form)
        p.parent.mkdir(parents=True, exist_ok=True)
        write_text(p, params_json(res.params, res.couplings))  # atomic: a reader never sees half a file
        urdfgen.write(res.params, urdf_path(name, form), robot_name=name)
    return res


def main(argv: list[str] | None = None) -> int:
    names = (argv if argv is not None else sys.argv[1:]) or [n for n in _spec_files() if not _is_user(n)]
    for n in names:
        sp = spec(n)
        for form in sp.forms:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = generate(n, form)
            fr = res.fit
            print(f"{n:22s} {form:9s} keypoint rms {fr.initial_rms_mm:6.2f} -> {fr.final_rms_mm:6.2f} mm")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
