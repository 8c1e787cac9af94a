"""A signed-distance grid with trilinear queries (the solver fits a spline through its nodes)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SDFGrid:
    """Signed distance values on a regular grid (metres; negative inside).

    ``values[i, j, k]`` is the distance at ``origin + spacing * (i, j, k)``.
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.values.shape)  # type: ignore[return-value]

    @property
    def upper(self) -> np.ndarray:
        """Coordinates of the last grid node (the grid spans ``origin`` .. ``upper``)."""
        return self.origin + self.spacing * (np.array(self.values.shape) - 1)

    def axes(self) -> list[np.ndarray]:
        """Grid coordinates along x, y, z."""
        return [self.origin[d] + self.spacing * np.arange(n) for d, n in enumerate(self.values.shape)]

    def query(self, points: np.ndarray) -> np.ndarray:
        """Trilinear signed distance at (N,3) points; outside the grid, distance to the grid box is added."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        pc = np.clip(p, self.origin, self.upper)
        extra = np.linalg.norm(p - pc, axis=1)
        g = (pc - self.origin) / self.spacing
        i0 = np.clip(np.floor(g).astype(int), 0, np.array(self.values.shape) - 2)
        f = g - i0
        v = self.values
        out = np.zeros(len(p))
        for dx in (0, 1):
            wx = f[:, 0] if dx else 1 - f[:, 0]
            for dy in (0, 1):
                wy = f[:, 1] if dy else 1 - f[:, 1]
                for dz in (0, 1):
                    wz = f[:, 2] if dz else 1 - f[:, 2]
                    out += wx * wy * wz * v[i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz]
        return out + extra

    def gradient(self, points: np.ndarray, h: float | None = None) -> np.ndarray:
        """(N,3) gradient of :meth:`query` by central differences (step ``h``, default spacing / 2)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        h = self.spacing / 2 if h is None else float(h)
        g = np.empty_like(p)
        for d in range(3):
            e = np.zeros(3)
            e[d] = h
            g[:, d] = (self.query(p + e) - self.query(p - e)) / (2 * h)
        return g

    def interpolant(self, method: str = "linear"):
        """``scipy.interpolate.RegularGridInterpolator`` over the grid (``"linear"``, ``"cubic"``, ...);
        points outside the grid are extrapolated."""
        from scipy.interpolate import RegularGridInterpolator

        return RegularGridInterpolator(self.axes(), self.values, method=method, bounds_error=False, fill_value=None)
