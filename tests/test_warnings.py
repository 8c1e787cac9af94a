"""ohra's warnings name the user's line (a notebook cell, a script), not ohra's internals or functools."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ohra.errors import ObjectWarning
from ohra.objects import ObjectModel


def test_an_object_warning_raised_inside_a_cached_property_points_at_the_callers_line(tmp_path):
    """The body of a non-convex mesh is chosen in a cached_property, two ohra frames and functools deep."""
    path = tmp_path / "ring.obj"
    trimesh.creation.annulus(r_min=0.02, r_max=0.035, height=0.08).export(path)
    obj = ObjectModel.load(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        obj.mass  # noqa: B018  (the property access is what warns)
    mine = [w for w in caught if issubclass(w.category, ObjectWarning)]
    assert mine and all(w.filename == __file__ for w in mine), [(w.filename, w.lineno) for w in mine]


def test_an_axis_snap_warning_points_at_the_callers_line():
    from ohra.learn.encoding import AxisSnapWarning, axis_categories

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        axis_categories(np.array([[0.99, 0.1, 0.0]]))
    snaps = [w for w in caught if issubclass(w.category, AxisSnapWarning)]
    assert len(snaps) == 1 and snaps[0].filename == __file__


def test_the_cli_prints_ohras_caller_pointing_warnings_as_one_line(tmp_path):
    """A warning ohra raises at its caller's frame (here: a latent far outside the VAE's prior) has, under the
    CLI, the console script as that frame: it is still ohra's, printed as ``ohra: warning: ...`` (it came out in
    Python's format with the script's ``sys.exit(main())`` line)."""
    import shutil
    import subprocess
    import sys

    pytest.importorskip("torch", reason="the VAE needs the learn extra")
    script = shutil.which("ohra") or str(Path(sys.executable).with_name("ohra"))
    if not Path(script).is_file():
        pytest.skip("the ohra console script is not installed")
    latent = ",".join(["20"] + ["0"] * 31)
    proc = subprocess.run([script, "vae", "decode", latent, "-o", str(tmp_path / "h.json")], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines and lines[0].startswith("ohra: warning: latent component 20 lies far outside"), proc.stderr
    assert "sys.exit" not in proc.stderr and "UserWarning" not in proc.stderr
