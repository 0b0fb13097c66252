"""Road wheel tracks on a grid (:class:`RoadProfile`), shared by synthesised and file roads.

:mod:`suspension_tuning.vehicle.road` synthesises profiles and
:mod:`suspension_tuning.vehicle.road_files` reads them from files; both build this
class, which knows nothing of either (so neither imports the other to use it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Wheel tracks a profile gives: left, right, and their mean (the pitch-plane model).
SIDES = ('left', 'right', 'centre')


def _check_side(side: str) -> str:
    if side not in SIDES:
        raise ValueError(f'side must be one of {SIDES}, got {side!r}')
    return side


@dataclass(frozen=True, eq=False)
class RoadProfile:
    """Elevation of the left and right wheel tracks on a uniform x grid.

    Attributes
    ----------
    x_m : np.ndarray
        Longitudinal positions, m, shape (n,), strictly increasing and uniform.
    z_left_m, z_right_m : np.ndarray
        Elevations of the left and right tracks, m, shape (n,).
    spec : RoadSpec or None
        The specification the profile was synthesised from (None for bumps/flat roads).
    """

    x_m: np.ndarray
    z_left_m: np.ndarray
    z_right_m: np.ndarray
    spec: Any = field(default=None, compare=False)  # the vehicle.road spec that made it

    def __post_init__(self) -> None:
        """Check shapes and monotonic x; store float copies of the arrays."""
        for name in ('x_m', 'z_left_m', 'z_right_m'):
            object.__setattr__(self, name, np.array(getattr(self, name), dtype=float))
        x = self.x_m
        if x.ndim != 1 or x.size < 2:
            raise ValueError('RoadProfile.x_m must be 1-D with at least 2 samples')
        if np.shape(self.z_left_m) != x.shape or np.shape(self.z_right_m) != x.shape:
            raise ValueError('RoadProfile z arrays must have the shape of x_m')
        if not np.all(np.diff(x) > 0):
            raise ValueError('RoadProfile.x_m must be strictly increasing')
        if not (np.all(np.isfinite(self.z_left_m)) and np.all(np.isfinite(self.z_right_m))):
            raise ValueError('RoadProfile elevations contain NaN or inf')

    @property
    def length_m(self) -> float:
        """Road length x_end - x_start, m."""
        return float(self.x_m[-1] - self.x_m[0])

    def centreline(self) -> np.ndarray:
        """Return the left/right average (z_left + z_right)/2 in m, shape (n,).

        Used by the pitch-plane ride model [P section 6.2].
        """
        return 0.5 * (np.asarray(self.z_left_m) + np.asarray(self.z_right_m))

    def _track(self, side: str) -> np.ndarray:
        side = _check_side(side)
        if side == 'left':
            return np.asarray(self.z_left_m)
        if side == 'right':
            return np.asarray(self.z_right_m)
        return self.centreline()

    def _check_x(self, x_m: np.ndarray) -> np.ndarray:
        x = np.asarray(x_m, dtype=float)
        if np.any(np.isnan(x)):
            raise ValueError('road position contains NaN')
        lo, hi = self.x_m[0], self.x_m[-1]
        if np.any(x < lo) or np.any(x > hi):
            raise ValueError(
                f'road position outside the profile [{lo}, {hi}] m: '
                f'min {np.min(x):.6g}, max {np.max(x):.6g}'
            )
        return x

    def elevation(self, x_m: np.ndarray, side: str = 'left') -> np.ndarray:
        """Return the elevation at positions ``x_m`` by linear interpolation.

        Parameters
        ----------
        x_m : array_like
            Positions along the road, m, any shape, inside [x_m[0], x_m[-1]].
        side : str
            'left', 'right' or 'centre'.

        Returns
        -------
        np.ndarray
            Elevation in m, shape of ``x_m``.
        """
        return np.interp(self._check_x(x_m), self.x_m, self._track(side))

    def slope(self, x_m: np.ndarray, side: str = 'left') -> np.ndarray:
        """Return dz/dx at positions ``x_m`` (piecewise constant between samples).

        Multiply by the forward speed to get the road's vertical velocity (m/s), e.g.
        for tyre damping.

        Parameters
        ----------
        x_m : array_like
            Positions along the road, m.
        side : str
            'left', 'right' or 'centre'.

        Returns
        -------
        np.ndarray
            Slope, dimensionless, shape of ``x_m``.
        """
        x = self._check_x(x_m)
        xs = np.asarray(self.x_m, dtype=float)
        seg = np.diff(self._track(side)) / np.diff(xs)
        i = np.clip(np.searchsorted(xs, x, side='right') - 1, 0, seg.size - 1)
        return seg[i]

    def sample(self, distance_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the left and right elevations at ``distance_m`` (linear interpolation).

        Parameters
        ----------
        distance_m : array_like
            Positions along the road, m, any shape (e.g. x0 + v t for a time grid).

        Returns
        -------
        (np.ndarray, np.ndarray)
            z_left, z_right in m, each of the shape of ``distance_m``.
        """
        x = self._check_x(distance_m)
        return (
            np.interp(x, self.x_m, self.z_left_m),
            np.interp(x, self.x_m, self.z_right_m),
        )
