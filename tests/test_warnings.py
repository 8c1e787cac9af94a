"""ohra's warnings name the user's line (a notebook cell, a script), not ohra's internals or functools."""

from __future__ import annotations

import warnings

import numpy as np
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
