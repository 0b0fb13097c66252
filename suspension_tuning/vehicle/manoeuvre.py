"""ISO 3888-1 double lane change: track geometry, reference path, driver and speed control.

Geometry (physics-reference 7.1, after the Chrono ISO3888_Helper and the MathWorks
Simscape vehicle templates), for a vehicle of width b:

=========  ======  ===================
Section    Length  Lane width
=========  ======  ===================
1 entry    15 m    1.1 b + 0.25 m
2          30 m    (lane change)
3 side     25 m    1.2 b + 0.25 m
4          25 m    (lane change back)
5 exit     15 m    1.3 b + 0.25 m
6 exit     15 m    1.3 b + 0.25 m
=========  ======  ===================

Lateral offset of lane 3: 3.5 m.  Two readings exist and both are offered:

* ``offset_is_centreline=True`` (default, MathWorks): lane 3's centreline is 3.5 m from
  lane 1's; the exit lane shares lane 1's centreline.
* ``offset_is_centreline=False`` (Chrono): lane 3's near edge is 3.5 m from lane 1's
  centreline (centre shift 3.5 + w3/2); the exit lane's right edge is aligned with lane
  1's right edge.

Coordinates: x along the track from the entry of lane 1, y to the left (ISO 8855),
yaw anticlockwise from x.  The first lane change is to the left (+y).

The driver is a preview steering driver with path-curvature feed-forward, in the spirit
of the paper's "yaw rate steering driver, adjusting the front wheels' steering angles
according to the difference of the desired course from the current course at a preview
distance" [P section 4].  It is a pure function of the vehicle state, so it can
be evaluated inside any ODE right-hand side; all state arguments carry a leading batch
axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from suspension_tuning.paths import config_dir, read_yaml

DEFAULT_CONFIG_PATH = config_dir() / 'manoeuvre.yaml'
"""config/manoeuvre.yaml of the source tree."""

SECTION_LENGTHS_M = (15.0, 30.0, 25.0, 25.0, 15.0, 15.0)
"""ISO 3888-1 section lengths 1-6 in m [S: physics-reference 7.1]."""
LANE_WIDTH_FACTOR = {1: 1.1, 3: 1.2, 5: 1.3, 6: 1.3}
"""ISO 3888-1 lane width = factor * b + LANE_WIDTH_ADD_M per lane section [S]."""
LANE_WIDTH_ADD_M = 0.25
"""ISO 3888-1 lane width additive term, m [S: physics-reference 7.1]."""
PATH_SHAPES = ('cosine', 'quintic')


@dataclass(frozen=True)
class LaneSection:
    """One coned lane section.

    Attributes
    ----------
    number : int
        ISO 3888-1 section number (1, 3, 5 or 6).
    x_start_m, x_end_m : float
        Longitudinal extent, m.
    y_centre_m : float
        Lateral position of the lane centreline, m.
    half_width_m : float
        Half the lane width, m.
    """

    number: int
    x_start_m: float
    x_end_m: float
    y_centre_m: float
    half_width_m: float

    @property
    def width_m(self) -> float:
        """Lane width, m."""
        return 2.0 * self.half_width_m


def _blend(xi: np.ndarray, shape: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blend s(xi) from 0 to 1 on [0, 1] with its first two derivatives in xi."""
    xi = np.clip(xi, 0.0, 1.0)
    if shape == 'cosine':
        s = 0.5 * (1.0 - np.cos(np.pi * xi))
        ds = 0.5 * np.pi * np.sin(np.pi * xi)
        dds = 0.5 * np.pi**2 * np.cos(np.pi * xi)
    else:  # quintic 10 xi^3 - 15 xi^4 + 6 xi^5: C2 at both ends
        s = xi**3 * (10.0 - 15.0 * xi + 6.0 * xi**2)
        ds = 30.0 * xi**2 * (1.0 - xi) ** 2
        dds = 60.0 * xi * (1.0 - xi) * (1.0 - 2.0 * xi)
    return s, ds, dds


@dataclass(frozen=True)
class DlcTrack:
    """ISO 3888-1 double lane change track for a vehicle of a given width.

    Build it with :func:`dlc_cones`.

    Attributes
    ----------
    vehicle_width_m : float
        Vehicle width b used to size the lanes, m.
    offset_m : float
        Lateral offset of lane 3 (see module docstring), m.
    offset_is_centreline : bool
        Offset convention (see module docstring).
    path_shape : str
        Transition shape of the reference path: 'cosine' (C1, lowest peak curvature
        pi^2 A / (2 L^2)) or 'quintic' (C2, peak curvature 5.77 A / L^2).
    x_start_m : float
        x of the entry of lane 1, m.
    """

    vehicle_width_m: float
    offset_m: float = 3.5
    offset_is_centreline: bool = True
    path_shape: str = 'cosine'
    x_start_m: float = 0.0
    section_bounds_m: tuple = field(init=False)
    lanes: tuple = field(init=False)

    def __post_init__(self) -> None:
        """Validate the inputs and lay out the sections."""
        b = self.vehicle_width_m
        if not np.isfinite(b) or not 0.5 <= b <= 5.0:
            raise ValueError(f'vehicle_width_m must be a plausible width (0.5-5 m), got {b}')
        if not np.isfinite(self.offset_m) or self.offset_m <= 0:
            raise ValueError(f'offset_m must be positive, got {self.offset_m}')
        if self.path_shape not in PATH_SHAPES:
            raise ValueError(f'path_shape must be one of {PATH_SHAPES}, got {self.path_shape!r}')
        if not np.isfinite(self.x_start_m):
            raise ValueError('x_start_m must be finite')
        bounds = self.x_start_m + np.concatenate([[0.0], np.cumsum(SECTION_LENGTHS_M)])
        hw = {k: 0.5 * (f * b + LANE_WIDTH_ADD_M) for k, f in LANE_WIDTH_FACTOR.items()}
        if self.offset_is_centreline:
            y3 = self.offset_m
            y5 = 0.0
        else:
            y3 = self.offset_m + hw[3]
            y5 = hw[5] - hw[1]  # right edges of lanes 1 and 5 aligned
        yc = {1: 0.0, 3: y3, 5: y5, 6: y5}
        lanes = tuple(
            LaneSection(
                number=k,
                x_start_m=float(bounds[k - 1]),
                x_end_m=float(bounds[k]),
                y_centre_m=float(yc[k]),
                half_width_m=float(hw[k]),
            )
            for k in (1, 3, 5, 6)
        )
        object.__setattr__(self, 'section_bounds_m', tuple(float(v) for v in bounds))
        object.__setattr__(self, 'lanes', lanes)

    @property
    def x_end_m(self) -> float:
        """x of the exit of section 6, m."""
        return self.section_bounds_m[-1]

    @property
    def first_lane_change_x_m(self) -> tuple[float, float]:
        """x range of the first lane change: start of section 2 to end of section 3, m."""
        return self.section_bounds_m[1], self.section_bounds_m[3]

    def _transitions(self) -> list[tuple[float, float, float, float]]:
        xb = self.section_bounds_m
        y1, y3, y5 = (self.lanes[i].y_centre_m for i in (0, 1, 2))
        return [(xb[1], xb[2], y1, y3), (xb[3], xb[4], y3, y5)]

    def _path(self, x_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = np.asarray(x_m, dtype=float)
        if np.any(np.isnan(x)):
            raise ValueError('x_m contains NaN')
        (a0, a1, ya, yb), (b0, b1, yb2, yc) = self._transitions()
        y = np.full(x.shape, ya)
        dy = np.zeros(x.shape)
        ddy = np.zeros(x.shape)
        for lo, hi, y_from, y_to in ((a0, a1, ya, yb), (b0, b1, yb2, yc)):
            length = hi - lo
            s, ds, dds = _blend((x - lo) / length, self.path_shape)
            after = x >= lo
            y = np.where(after, y_from + (y_to - y_from) * s, y)
            inside = after & (x <= hi)
            dy = np.where(inside, (y_to - y_from) * ds / length, np.where(after, 0.0, dy))
            ddy = np.where(inside, (y_to - y_from) * dds / length**2, np.where(after, 0.0, ddy))
        return y, dy, ddy

    def y_ref(self, x_m: np.ndarray) -> np.ndarray:
        """Return the reference path's lateral position y(x) in m (any shape of x)."""
        return self._path(x_m)[0]

    def heading_ref(self, x_m: np.ndarray) -> np.ndarray:
        """Return the reference path's heading atan(dy/dx) in rad."""
        return np.arctan(self._path(x_m)[1])

    def curvature_ref(self, x_m: np.ndarray) -> np.ndarray:
        """Return the reference path's signed curvature y'' / (1 + y'^2)^1.5 in 1/m."""
        _, dy, ddy = self._path(x_m)
        return ddy / (1.0 + dy**2) ** 1.5

    def reference_path(
        self, dx_m: float = 0.1, x_before_m: float = 0.0, x_after_m: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Return the sampled reference path (x_m, y_m).

        The path follows lane 1's centreline, blends to lane 3's over section 2, and to
        the exit lane's over section 4 (shape :attr:`path_shape`, C1 or C2).

        Parameters
        ----------
        dx_m : float
            Sample spacing, m.
        x_before_m, x_after_m : float
            Extra straight path before lane 1 and after section 6, m.

        Returns
        -------
        (np.ndarray, np.ndarray)
            x and y in m.
        """
        if dx_m <= 0:
            raise ValueError(f'dx_m must be positive, got {dx_m}')
        x0 = self.x_start_m - x_before_m
        x1 = self.x_end_m + x_after_m
        x = np.linspace(x0, x1, int(round((x1 - x0) / dx_m)) + 1)
        return x, self.y_ref(x)

    def footprint_violation(
        self,
        x_m: np.ndarray,
        y_m: np.ndarray,
        yaw_rad: np.ndarray,
        vehicle_width_m: float,
        vehicle_length_m: float,
        ref_to_front_m: float | None = None,
    ) -> np.ndarray:
        """Return, per sample, how far the vehicle's rectangle leaves the coned lanes.

        For each lane section the footprint is clipped to the section's x-slab and its
        lateral extremes (corners inside the slab and intersections of its edges with the
        slab's end lines, i.e. the gate cone lines) are compared with the lane edges.

        Parameters
        ----------
        x_m, y_m, yaw_rad : array_like
            Position of the vehicle reference point and yaw, any common shape.
        vehicle_width_m, vehicle_length_m : float
            Footprint size, m.
        ref_to_front_m : float, optional
            Distance from the reference point to the front of the footprint, m
            (default: half the length, i.e. the reference point at the centre).

        Returns
        -------
        np.ndarray
            Violation in m, shape of the inputs: > 0 outside, <= 0 inside (the negative
            value is the smallest clearance to a lane edge); -inf where the footprint
            overlaps no lane section.
        """
        x, y, yaw = np.broadcast_arrays(
            np.asarray(x_m, dtype=float),
            np.asarray(y_m, dtype=float),
            np.asarray(yaw_rad, dtype=float),
        )
        if np.any(~np.isfinite(x)) or np.any(~np.isfinite(y)) or np.any(~np.isfinite(yaw)):
            raise ValueError('vehicle pose contains NaN or inf')
        if vehicle_width_m <= 0 or vehicle_length_m <= 0:
            raise ValueError('vehicle width and length must be positive')
        front = 0.5 * vehicle_length_m if ref_to_front_m is None else ref_to_front_m
        rear = front - vehicle_length_m
        hw = 0.5 * vehicle_width_m
        c, s = np.cos(yaw), np.sin(yaw)
        lon = np.array([front, front, rear, rear])  # corners in order around the box
        lat = np.array([hw, -hw, -hw, hw])
        cx = x[..., None] + c[..., None] * lon - s[..., None] * lat
        cy = y[..., None] + s[..., None] * lon + c[..., None] * lat
        nx = np.roll(cx, -1, axis=-1)
        ny = np.roll(cy, -1, axis=-1)
        out = np.full(x.shape, -np.inf)
        for lane in self.lanes:
            x0, x1 = lane.x_start_m, lane.x_end_m
            cand_y = [cy]
            cand_ok = [(cx >= x0) & (cx <= x1)]
            for xb in (x0, x1):
                dx = nx - cx
                with np.errstate(divide='ignore', invalid='ignore'):
                    t = (xb - cx) / dx
                ok = (dx != 0) & (t >= 0) & (t <= 1)
                cand_y.append(np.where(ok, cy + t * (ny - cy), 0.0))
                cand_ok.append(ok)
            ys = np.concatenate(cand_y, axis=-1)
            oks = np.concatenate(cand_ok, axis=-1)
            excess = np.maximum(
                ys - (lane.y_centre_m + lane.half_width_m),
                (lane.y_centre_m - lane.half_width_m) - ys,
            )
            viol = np.max(np.where(oks, excess, -np.inf), axis=-1)
            out = np.maximum(out, viol)
        return out

    def cone_violation(
        self,
        x_m: np.ndarray,
        y_m: np.ndarray,
        yaw_rad: np.ndarray,
        vehicle_width_m: float,
        vehicle_length_m: float,
        ref_to_front_m: float | None = None,
    ) -> np.ndarray:
        """Return the largest distance (m) by which the footprint leaves the lanes.

        Parameters
        ----------
        x_m, y_m, yaw_rad : array_like
            Pose history of the vehicle reference point, shape (..., n_samples).
        vehicle_width_m, vehicle_length_m, ref_to_front_m
            As :meth:`footprint_violation`.

        Returns
        -------
        np.ndarray
            Max over the last (time) axis, shape (...); <= 0 means the vehicle stayed
            inside every lane section (its magnitude is then the smallest clearance).
        """
        v = self.footprint_violation(
            x_m, y_m, yaw_rad, vehicle_width_m, vehicle_length_m, ref_to_front_m
        )
        if v.ndim == 0:
            return v
        return np.max(v, axis=-1)


def dlc_cones(
    vehicle_width_m: float,
    offset_m: float = 3.5,
    offset_is_centreline: bool = True,
    path_shape: str = 'cosine',
    x_start_m: float = 0.0,
) -> DlcTrack:
    """Return the ISO 3888-1 double lane change track for a vehicle width.

    Parameters
    ----------
    vehicle_width_m : float
        Vehicle width b, m (Defender 110: 1.79 m, physics-reference 4).
    offset_m : float
        Lateral offset of lane 3, m (ISO 3888-1: 3.5 m).
    offset_is_centreline : bool
        True: centreline shift (MathWorks); False: near-edge offset (Chrono).
    path_shape : str
        'cosine' or 'quintic' transitions of the reference path.
    x_start_m : float
        x of the entry of lane 1, m.

    Returns
    -------
    DlcTrack
        The track.
    """
    return DlcTrack(
        vehicle_width_m=float(vehicle_width_m),
        offset_m=float(offset_m),
        offset_is_centreline=bool(offset_is_centreline),
        path_shape=path_shape,
        x_start_m=float(x_start_m),
    )


def _state(name: str, v: np.ndarray) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if np.any(~np.isfinite(a)):
        raise ValueError(f'{name} contains NaN or inf')
    return a


_DRIVER_KEYS = (
    'preview_time_s',
    'preview_min_m',
    'lateral_gain_rad_per_m',
    'feedforward_time_s',
    'k_feedforward',
    'understeer_gradient_rad_per_mps2',
    'yaw_rate_gain_s',
    'max_steer_rad',
    'lag_s',
)


@dataclass(frozen=True)
class PreviewDriver:
    """Preview steering driver with path-curvature feed-forward, vectorised over a batch.

    Feedback: the lateral deviation from the desired course predicted at a preview
    distance ``L_p = max(preview_min_m, preview_time_s u)`` ahead, extrapolating the
    current heading against the path's tangent at the vehicle's x:

        e = (y_ref(x) - y) + L_p sin(psi_ref(x) - psi)

    Feed-forward: the steady-state steer angle for the path curvature a short time
    ``feedforward_time_s`` ahead (compensating the steering lag and the vehicle's
    lateral response), with the driver's idea of the understeer gradient ``K_us``:

        delta = k_ff (wheelbase + K_us u^2) kappa_ref(x + u t_ff)
                + lateral_gain e + yaw_rate_gain (u kappa_ref(x + u t_ff) - r)

    clipped to +/- ``max_steer_rad``.  This follows the paper's "yaw rate steering
    driver, adjusting the front wheels' steering angles according to the difference of
    the desired course from the current course at a preview distance" [P section 4].
    :meth:`steer` is a pure function of the state; :meth:`steer_rate` adds a first-order
    lag ``lag_s`` for use as an extra state of the vehicle model.

    Attributes
    ----------
    track : DlcTrack
        Track whose reference path is followed.
    wheelbase_m : float
        Vehicle wheelbase, m.
    preview_time_s, preview_min_m, lateral_gain_rad_per_m, feedforward_time_s,
    k_feedforward, understeer_gradient_rad_per_mps2, yaw_rate_gain_s, max_steer_rad,
    lag_s
        Gains, units in the names; see config/manoeuvre.yaml for values and reasons.
    """

    track: DlcTrack
    wheelbase_m: float
    preview_time_s: float = 2.0
    preview_min_m: float = 5.0
    lateral_gain_rad_per_m: float = 0.04
    feedforward_time_s: float = 0.25
    k_feedforward: float = 1.0
    understeer_gradient_rad_per_mps2: float = 0.0
    yaw_rate_gain_s: float = 0.0
    max_steer_rad: float = 0.6
    lag_s: float = 0.1

    def __post_init__(self) -> None:
        """Validate the gains."""
        if not isinstance(self.track, DlcTrack):
            raise ValueError('PreviewDriver.track must be a DlcTrack')
        for name in ('wheelbase_m', 'preview_time_s', 'max_steer_rad', 'lag_s'):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f'PreviewDriver.{name} must be positive, got {v}')
        for name in _DRIVER_KEYS:
            v = getattr(self, name)
            if not np.isfinite(v) or (name != 'understeer_gradient_rad_per_mps2' and v < 0):
                raise ValueError(f'PreviewDriver.{name} must be finite and >= 0, got {v}')

    @classmethod
    def from_yaml_dict(cls, d: dict, track: DlcTrack, wheelbase_m: float) -> PreviewDriver:
        """Build a driver from the ``driver`` mapping of config/manoeuvre.yaml.

        Parameters
        ----------
        d : dict
            Gains keyed by attribute name.
        track : DlcTrack
            Track to follow.
        wheelbase_m : float
            Vehicle wheelbase, m (from the vehicle parameters).

        Returns
        -------
        PreviewDriver
            The driver.
        """
        unknown = sorted(set(d) - set(_DRIVER_KEYS))
        if unknown:
            raise ValueError(f'unknown driver keys {unknown}; valid: {sorted(_DRIVER_KEYS)}')
        return cls(track=track, wheelbase_m=wheelbase_m, **d)

    def preview_distance(self, speed_mps: np.ndarray) -> np.ndarray:
        """Return the preview distance max(preview_min_m, preview_time_s u) in m."""
        return np.maximum(self.preview_min_m, self.preview_time_s * np.abs(speed_mps))

    def steer(
        self,
        x_m: np.ndarray,
        y_m: np.ndarray,
        yaw_rad: np.ndarray,
        speed_mps: np.ndarray,
        yaw_rate_rad_s: np.ndarray,
    ) -> np.ndarray:
        """Return the commanded front road-wheel steer angle in rad.

        Parameters
        ----------
        x_m, y_m : array_like
            Position of the vehicle reference point (cg), m, shape (batch,).
        yaw_rad : array_like
            Yaw angle, rad, shape (batch,).
        speed_mps : array_like
            Forward speed u, m/s, shape (batch,) (> 0).
        yaw_rate_rad_s : array_like
            Yaw rate r, rad/s, shape (batch,).

        Returns
        -------
        np.ndarray
            Steer angle, rad, shape (batch,), positive to the left.
        """
        x = _state('x_m', x_m)
        y = _state('y_m', y_m)
        yaw = _state('yaw_rad', yaw_rad)
        u = _state('speed_mps', speed_mps)
        r = _state('yaw_rate_rad_s', yaw_rate_rad_s)
        if np.any(u <= 0):
            raise ValueError('speed_mps must be positive for the preview driver')
        lp = self.preview_distance(u)
        e = self.track.y_ref(x) - y + lp * np.sin(self.track.heading_ref(x) - yaw)
        kappa = self.track.curvature_ref(x + u * self.feedforward_time_s)
        delta = (
            self.k_feedforward
            * (self.wheelbase_m + self.understeer_gradient_rad_per_mps2 * u**2)
            * kappa
            + self.lateral_gain_rad_per_m * e
            + self.yaw_rate_gain_s * (u * kappa - r)
        )
        return np.clip(delta, -self.max_steer_rad, self.max_steer_rad)

    def steer_rate(
        self,
        x_m: np.ndarray,
        y_m: np.ndarray,
        yaw_rad: np.ndarray,
        speed_mps: np.ndarray,
        yaw_rate_rad_s: np.ndarray,
        steer_rad: np.ndarray,
    ) -> np.ndarray:
        """Return d(steer)/dt in rad/s of a first-order lag towards :meth:`steer`.

        ``d delta / dt = (delta_cmd - delta) / lag_s``; integrate it as a state of the
        vehicle model to include the driver's and steering system's lag.

        Parameters
        ----------
        x_m, y_m, yaw_rad, speed_mps, yaw_rate_rad_s : array_like
            As :meth:`steer`.
        steer_rad : array_like
            Current road-wheel steer angle, rad, shape (batch,).

        Returns
        -------
        np.ndarray
            Steer rate, rad/s, shape (batch,).
        """
        cmd = self.steer(x_m, y_m, yaw_rad, speed_mps, yaw_rate_rad_s)
        return (cmd - _state('steer_rad', steer_rad)) / self.lag_s


@dataclass(frozen=True)
class SpeedController:
    """PI speed controller: longitudinal force from the speed error (vectorised).

    ``F = kp (u_target - u) + ki I``, clipped to +/- ``force_limit_n``, with
    ``dI/dt = u_target - u`` (conditional integration: I is frozen while the force is
    saturated in the direction of the error, to avoid wind-up).  The paper models the
    longitudinal driver as "a variable force attached to the body at wheel height
    depending on the difference between the instantaneous speed and desired speed"
    [P section 4].

    Attributes
    ----------
    target_speed_mps : float
        Desired speed, m/s.
    kp_n_per_mps : float
        Proportional gain, N per m/s.
    ki_n_per_m : float
        Integral gain, N per m (of accumulated speed error).
    force_limit_n : float
        Force saturation, N.
    """

    target_speed_mps: float
    kp_n_per_mps: float
    ki_n_per_m: float
    force_limit_n: float

    def __post_init__(self) -> None:
        """Validate the gains."""
        for name in ('target_speed_mps', 'kp_n_per_mps', 'force_limit_n'):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f'SpeedController.{name} must be positive, got {v}')
        if not np.isfinite(self.ki_n_per_m) or self.ki_n_per_m < 0:
            raise ValueError(f'SpeedController.ki_n_per_m must be >= 0, got {self.ki_n_per_m}')

    @classmethod
    def from_yaml_dict(cls, d: dict, target_speed_mps: float) -> SpeedController:
        """Build a controller from the ``speed_controller`` mapping of manoeuvre.yaml."""
        allowed = {'kp_n_per_mps', 'ki_n_per_m', 'force_limit_n'}
        unknown = sorted(set(d) - allowed)
        if unknown:
            raise ValueError(f'unknown speed_controller keys {unknown}; valid: {sorted(allowed)}')
        return cls(target_speed_mps=target_speed_mps, **d)

    def _raw(self, speed_mps: np.ndarray, integral_m: np.ndarray) -> np.ndarray:
        err = self.target_speed_mps - _state('speed_mps', speed_mps)
        return self.kp_n_per_mps * err + self.ki_n_per_m * _state('integral_m', integral_m)

    def force(self, speed_mps: np.ndarray, integral_m: np.ndarray) -> np.ndarray:
        """Return the longitudinal force in N (shape of the inputs).

        Parameters
        ----------
        speed_mps : array_like
            Forward speed, m/s.
        integral_m : array_like
            Integral of the speed error (state of the controller), m.

        Returns
        -------
        np.ndarray
            Force, N, positive forward.
        """
        return np.clip(self._raw(speed_mps, integral_m), -self.force_limit_n, self.force_limit_n)

    def integral_rate(self, speed_mps: np.ndarray, integral_m: np.ndarray) -> np.ndarray:
        """Return dI/dt in m/s (the speed error, or 0 while saturated in its direction)."""
        err = self.target_speed_mps - _state('speed_mps', speed_mps)
        raw = self._raw(speed_mps, integral_m)
        wind_up = ((raw > self.force_limit_n) & (err > 0)) | (
            (raw < -self.force_limit_n) & (err < 0)
        )
        return np.where(wind_up, 0.0, err)


@dataclass(frozen=True)
class ManoeuvreSetup:
    """Everything config/manoeuvre.yaml defines for the double lane change.

    Attributes
    ----------
    track : DlcTrack
        Cones and reference path.
    driver : PreviewDriver
        Steering driver.
    speed_controller : SpeedController
        Longitudinal driver.
    speed_mps : float
        Manoeuvre speed, m/s.
    vehicle_width_m, vehicle_length_m, cg_to_front_m : float
        Footprint used for the cone check, m.
    lead_in_m, run_out_m : float
        Straight distance simulated before lane 1 and after section 6, m.
    """

    track: DlcTrack
    driver: PreviewDriver
    speed_controller: SpeedController
    speed_mps: float
    vehicle_width_m: float
    vehicle_length_m: float
    cg_to_front_m: float
    lead_in_m: float
    run_out_m: float


def load_manoeuvre_config(path: str | Path | None = None) -> dict:
    """Return the raw mapping of config/manoeuvre.yaml (or ``path``)."""
    return read_yaml(Path(path) if path is not None else DEFAULT_CONFIG_PATH)


def load_manoeuvre(wheelbase_m: float, path: str | Path | None = None) -> ManoeuvreSetup:
    """Build the track, driver and speed controller from config/manoeuvre.yaml.

    Parameters
    ----------
    wheelbase_m : float
        Vehicle wheelbase, m (owned by the vehicle parameters, not this file).
    path : str or Path, optional
        YAML file; :data:`DEFAULT_CONFIG_PATH` when omitted.

    Returns
    -------
    ManoeuvreSetup
        The assembled objects.
    """
    cfg = load_manoeuvre_config(path)
    try:
        t = cfg['track']
        speed_mps = float(cfg['speed_kmh']) / 3.6
        track = dlc_cones(
            vehicle_width_m=t['vehicle_width_m'],
            offset_m=t['offset_m'],
            offset_is_centreline=t['offset_is_centreline'],
            path_shape=t['path_shape'],
        )
        driver = PreviewDriver.from_yaml_dict(cfg['driver'], track, wheelbase_m)
        speed = SpeedController.from_yaml_dict(cfg['speed_controller'], speed_mps)
        return ManoeuvreSetup(
            track=track,
            driver=driver,
            speed_controller=speed,
            speed_mps=speed_mps,
            vehicle_width_m=float(t['vehicle_width_m']),
            vehicle_length_m=float(t['vehicle_length_m']),
            cg_to_front_m=float(t['cg_to_front_m']),
            lead_in_m=float(t['lead_in_m']),
            run_out_m=float(t['run_out_m']),
        )
    except KeyError as exc:
        raise ValueError(f'manoeuvre config is missing key {exc}') from None
