"""Registered real hands: specs (``ohra/hands/specs/<name>.yaml``), committed params and canonical URDFs.

Each registered hand has a spec and, per form it is registered in, the parser's output committed as
``ohra/hands/params/{base,extended}/<name>.json`` and the rendered canonical URDF as
``ohra/urdf/{base,extended}/<name>.urdf``. Regenerate everything after changing a spec, the parser or
the templates with::

    python -m ohra.hands.registry            # all hands (needs the hand assets)
    python -m ohra.hands.registry shadow_hand_right
"""

from __future__ import annotations

import sys
from functools import lru_cache
from pathlib import Path

import yaml

from ohra.errors import AssetsNotFoundError, HandNotFoundError, SpecError
from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.resources import hands_data_dir, specs_dir, urdf_dir

FORMS = ("base", "extended")


@lru_cache(maxsize=1)
def _spec_files() -> dict[str, Path]:
    """Registered hand name -> spec file (every ``specs/*.yaml``; one that does not parse is an error)."""
    out = {}
    for p in sorted(specs_dir().glob("*.yaml")):
        try:
            d = yaml.safe_load(p.read_text())
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" line {mark.line + 1}" if mark is not None else ""
            raise SpecError(f"{p}:{where} invalid YAML: {getattr(exc, 'problem', None) or exc}") from None
        if not isinstance(d, dict) or "joints" not in d or "urdf" not in d:
            raise SpecError(f"{p}: not a hand spec (expected a mapping with 'urdf' and 'joints' keys)")
        out[str(d.get("name", p.stem))] = p
    return out


def params_path(name: str, form: str) -> Path:
    return hands_data_dir() / "params" / form / f"{name}.json"


def urdf_path(name: str, form: str) -> Path:
    return urdf_dir() / form / f"{name}.urdf"


def registered_hands() -> list[str]:
    """Names of hands with a spec and at least one committed params file."""
    return [n for n in _spec_files() if any(params_path(n, f).is_file() for f in FORMS)]


def registered_forms(name: str) -> list[str]:
    return [f for f in FORMS if params_path(name, f).is_file()]


def spec(name: str):
    """The :class:`ohra.original.spec.HandSpec` of a registered hand."""
    from ohra.original.spec import load_spec

    files = _spec_files()
    if name not in files:
        raise HandNotFoundError(f"unknown hand {name!r}; registered: {', '.join(registered_hands())}")
    return load_spec(files[name])


def registered_params(name: str, form: str | None = None) -> BaseParams | ExtendedParams:
    """Committed params of a registered hand (``form`` None: base when registered, else extended)."""
    forms = registered_forms(name)
    if not forms:
        raise HandNotFoundError(f"unknown hand {name!r}; registered: {', '.join(registered_hands())}")
    if form is None:
        form = forms[0]
    if form not in forms:
        raise HandNotFoundError(f"hand {name!r} is registered only in the {'/'.join(forms)} form, not {form!r}")
    return load_params(params_path(name, form))


def load_original(name: str, hands_root: str | Path | None = None):
    """The original hand model (:class:`ohra.original.urdf.OriginalHand`) of a registered hand.

    Needs the hand assets; raises :class:`ohra.AssetsNotFoundError` naming the expected path.
    """
    from ohra.original.urdf import load_urdf

    sp = spec(name)
    path = sp.urdf_path(hands_root)
    if not path.is_file():
        raise AssetsNotFoundError(
            f"original URDF of {name!r} not found at {path}; set OHRA_HANDS_ROOT to the folder holding the hand assets"
        )
    return load_urdf(path)


def generate(name: str, form: str, write: bool = True):
    """Parse (with fit and overrides) and optionally write params JSON + canonical URDF; returns the ParseResult."""
    from ohra.canonical import urdfgen
    from ohra.original.parse import parse

    sp = spec(name)
    res = parse(sp, form, fit_params=True)
    if write:
        p = params_path(name, form)
        p.parent.mkdir(parents=True, exist_ok=True)
        res.params.to_json(p)
        urdfgen.write(res.params, urdf_path(name, form), robot_name=name)
    return res


def main(argv: list[str] | None = None) -> int:
    import warnings

    names = (argv if argv is not None else sys.argv[1:]) or list(_spec_files())
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
