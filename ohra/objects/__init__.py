"""Objects to grasp: mesh loading and repair, SDF grids, point clouds, convex pieces, built-in primitives."""

from ohra.objects.model import (
    DEFAULT_DENSITY,
    ObjectModel,
    RepairReport,
    SDFGrid,
    builtin_object_names,
    farthest_point_sampling,
    load_convex_pieces,
    repair_mesh,
    resolve_objects,
)

__all__ = [
    "DEFAULT_DENSITY", "ObjectModel", "RepairReport", "SDFGrid", "builtin_object_names", "farthest_point_sampling",
    "load_convex_pieces", "repair_mesh", "resolve_objects",
]
