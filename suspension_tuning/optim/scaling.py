"""Eq. 25 scaling of simplified-model values onto the full model's range (section 6.3.1).

Thoresson et al. (2009) evaluate both models at N = 30 designs over the design space and
map each simplified function value ``F_M`` onto the full model's range:

    F_s = (F_M - F_Mmin) (F_Amax - F_Amin) / (F_Mmax - F_Mmin) + F_Amin        (eq. 25)

per function (the objective and each constraint).  The map is affine, so a simplified
gradient is multiplied by ``(F_Amax - F_Amin) / (F_Mmax - F_Mmin)``; the offset does not
affect gradients (physics-reference 1.8).

Degenerate ranges (documented rules, reported in ``FunctionScaling.rule``):

* ``'simplified_constant'`` - ``F_Mmax - F_Mmin <= tol`` (e.g. a tyre-hop constraint that
  never activates in the simplified model: all values -1): unit slope and the offset
  ``F_Amin - F_Mmin`` (so ``F_s = F_M - F_Mmin + F_Amin``).  The gradient factor is then 1,
  and the simplified gradient (zero where the function is flat) passes unchanged.
* ``'full_constant'`` - the full values are all equal but the simplified ones are not:
  eq. 25 applies as written (factor 0: the full model says the function is flat).

``tol = 1e-12 * max(1, |F_Mmax|, |F_Mmin|)``.

Quality: ``r2`` is the coefficient of determination of the full values by the scaled
simplified values over the samples, ``1 - sum (F_A - F_s)^2 / sum (F_A - mean F_A)^2``
(NaN when the full values are constant); ``r2_linear`` is the squared Pearson correlation
(the best any affine map could reach).

Sampling (:func:`sample_design_space`): the 2^n corners of the box (when all fit), then a seeded
maximin Latin hypercube (best of ``candidates`` scipy ``qmc.LatinHypercube`` designs by
the smallest distance to each other and to the corners) for the remaining samples, all
mapped to ``[X_LOWER, X_UPPER]``.  Deterministic for a given seed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import qmc

from suspension_tuning.model_identity import builtin_fingerprint, files_sha256
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER, validate_design

Array = NDArray[np.float64]
FUNCTION_NAMES = ('f', 'g_fl', 'g_fr', 'g_rl', 'g_rr')
#: Config files whose content defines both models (hashed into the cache key).
KEY_CONFIG_FILES = (
    'design_space.yaml',
    'vehicle.yaml',
    'strut_4s4.yaml',
    'tyre.yaml',
    'road.yaml',
    'scenarios.yaml',
    'simplified_models.yaml',
)


def config_hash(config_dir: str | Path | None = None) -> str:
    """SHA-256 (first 16 hex digits) of the config files that define both models."""
    return files_sha256(KEY_CONFIG_FILES, config_dir)[:16]


def sample_design_space(
    n_vars: int,
    n_samples: int = 30,
    seed: int = 2009,
    include_corners: bool = True,
    candidates: int = 50,
) -> Array:
    """Deterministic sample designs over the normalised box (corners + maximin LHS).

    Parameters
    ----------
    n_vars : int
        2 or 4.
    n_samples : int
        Number of designs (paper: 30 [P s.6.3.1]).
    seed : int
        Seed of the Latin hypercubes.
    include_corners : bool
        Put the 2^n corners first, when all of them fit in ``n_samples`` (else the
        samples are the Latin hypercube alone).
    candidates : int
        Latin hypercubes tried for the maximin criterion.

    Returns
    -------
    np.ndarray
        (n_samples, n_vars) in [X_LOWER, X_UPPER].
    """
    validate_design(np.full(n_vars, X_UPPER), n_vars)
    if n_samples < 2:
        raise ValueError(f'n_samples must be >= 2, got {n_samples}')
    corners = np.empty((0, n_vars))
    # the corners only where they all fit: 2^n of them (n = 8: 256) would otherwise be
    # a biased handful of corners (the first variables all at their low end)
    if include_corners and 2 ** n_vars <= n_samples:
        grid = np.array(np.meshgrid(*[[X_LOWER, X_UPPER]] * n_vars, indexing='ij'))
        corners = grid.reshape(n_vars, -1).T[:n_samples]
    n_lhs = n_samples - corners.shape[0]
    if n_lhs == 0:
        return corners
    best, best_d = None, -np.inf
    for i in range(max(1, candidates)):
        u = qmc.LatinHypercube(d=n_vars, seed=np.random.default_rng([seed, i])).random(n_lhs)
        pts = X_LOWER + u * (X_UPPER - X_LOWER)
        allp = np.vstack([corners, pts])
        d = np.sqrt(((allp[:, None, :] - allp[None, :, :]) ** 2).sum(-1))
        np.fill_diagonal(d, np.inf)
        dmin = d.min()
        if dmin > best_d:
            best, best_d = pts, dmin
    return np.vstack([corners, best])


@dataclass(frozen=True)
class FunctionScaling:
    """Eq. 25 map of one function (objective or one constraint).

    Attributes
    ----------
    name : str
        Function name ('f', 'g_fl', ...).
    f_m_min, f_m_max : float
        Simplified-model minimum and maximum over the samples.
    f_a_min, f_a_max : float
        Full-model minimum and maximum over the samples.
    r2 : float
        Coefficient of determination of the full values by the scaled values (NaN if
        the full values are constant).
    r2_linear : float
        Squared Pearson correlation of simplified and full values (NaN if either is
        constant).
    rule : str
        'eq25', 'simplified_constant' or 'full_constant' (see module docstring).
    """

    name: str
    f_m_min: float
    f_m_max: float
    f_a_min: float
    f_a_max: float
    r2: float = float('nan')
    r2_linear: float = float('nan')
    rule: str = 'eq25'

    @property
    def gradient_factor(self) -> float:
        """Factor on simplified gradients: (F_Amax - F_Amin)/(F_Mmax - F_Mmin), or 1."""
        if self.rule == 'simplified_constant':
            return 1.0
        return (self.f_a_max - self.f_a_min) / (self.f_m_max - self.f_m_min)

    def apply(self, values: ArrayLike) -> Array:
        """Scaled value F_s of simplified values F_M (eq. 25 or the degenerate rule)."""
        v = np.asarray(values, dtype=float)
        return (v - self.f_m_min) * self.gradient_factor + self.f_a_min


def _r2(full: Array, scaled: Array) -> float:
    ss_tot = float(np.sum((full - full.mean()) ** 2))
    if ss_tot <= 0.0:
        return float('nan')
    return 1.0 - float(np.sum((full - scaled) ** 2)) / ss_tot


def _r2_linear(a: Array, b: Array) -> float:
    if np.ptp(a) == 0.0 or np.ptp(b) == 0.0:
        return float('nan')
    return float(np.corrcoef(a, b)[0, 1] ** 2)


def fit_function(name: str, full: ArrayLike, simplified: ArrayLike) -> FunctionScaling:
    """Fit the eq. 25 map of one function from paired samples."""
    a = np.asarray(full, dtype=float)
    m = np.asarray(simplified, dtype=float)
    if a.shape != m.shape or a.ndim != 1 or a.size < 2:
        raise ValueError(f'{name}: full and simplified samples must be 1-D, same length >= 2')
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(m))):
        raise ValueError(f'{name}: samples contain NaN or inf')
    m_min, m_max = float(m.min()), float(m.max())
    tol = 1e-12 * max(1.0, abs(m_min), abs(m_max))
    rule = 'eq25'
    if m_max - m_min <= tol:
        rule = 'simplified_constant'
    elif np.ptp(a) == 0.0:
        rule = 'full_constant'
    fs = FunctionScaling(name, m_min, m_max, float(a.min()), float(a.max()), rule=rule)
    return FunctionScaling(
        name, m_min, m_max, fs.f_a_min, fs.f_a_max, _r2(a, fs.apply(m)), _r2_linear(a, m), rule
    )


@dataclass(frozen=True)
class Scaling:
    """Eq. 25 scaling of the objective and the constraints of one scenario.

    Attributes
    ----------
    functions : tuple of FunctionScaling
        One per function: the objective first, then each constraint.
    key : dict
        Cache key: scenario, n_vars, n_samples, config_hash (and sampling details).
    x_samples : np.ndarray
        Sample designs (N, n_vars).
    full_values, simplified_values : np.ndarray
        (N, 1 + m): objective then constraints at the samples.
    """

    functions: tuple[FunctionScaling, ...]
    key: dict[str, Any] = field(default_factory=dict)
    x_samples: Array = field(default_factory=lambda: np.empty((0, 0)))
    full_values: Array = field(default_factory=lambda: np.empty((0, 0)))
    simplified_values: Array = field(default_factory=lambda: np.empty((0, 0)))

    @property
    def n_functions(self) -> int:
        """Number of functions (1 + number of constraints)."""
        return len(self.functions)

    @property
    def gradient_factors(self) -> Array:
        """Gradient factors of all functions (1 + m,)."""
        return np.array([fs.gradient_factor for fs in self.functions])

    def apply(self, values: ArrayLike) -> Array:
        """Scale values of shape (..., 1 + m) (objective then constraints)."""
        v = np.asarray(values, dtype=float)
        if v.shape[-1] != self.n_functions:
            raise ValueError(f'values must have {self.n_functions} columns, got {v.shape}')
        return np.stack([fs.apply(v[..., i]) for i, fs in enumerate(self.functions)], axis=-1)

    def apply_fg(self, f: ArrayLike, g: ArrayLike) -> tuple[Array, Array]:
        """Scale f (batch,) and g (batch, m); returns the scaled pair."""
        s = self.apply(np.column_stack([np.atleast_1d(f), np.atleast_2d(g)]))
        return s[:, 0], s[:, 1:]

    def summary(self) -> dict[str, dict[str, float | str]]:
        """Per-function numbers (ranges, R^2, rule, gradient factor) for reports."""
        return {
            fs.name: {
                'f_m_min': fs.f_m_min,
                'f_m_max': fs.f_m_max,
                'f_a_min': fs.f_a_min,
                'f_a_max': fs.f_a_max,
                'r2': fs.r2,
                'r2_linear': fs.r2_linear,
                'rule': fs.rule,
                'gradient_factor': fs.gradient_factor,
            }
            for fs in self.functions
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready mapping (NaN written as null)."""

        def clean(v):
            return None if isinstance(v, float) and not np.isfinite(v) else v

        return {
            'format': 'suspension_tuning.scaling/1',
            'key': self.key,
            'functions': [{k: clean(v) for k, v in fs.__dict__.items()} for fs in self.functions],
            'x_samples': self.x_samples.tolist(),
            'full_values': self.full_values.tolist(),
            'simplified_values': self.simplified_values.tolist(),
        }

    def save(self, path: str | Path) -> None:
        """Write the scaling as JSON (costs N full runs to rebuild: keep it).

        One line: the standard library's C encoder, 0.12 ms against 0.39 ms indented
        (its pure-Python path), paid inside every calibration through the graph.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict()), encoding='utf-8')

    @classmethod
    def load(cls, path: str | Path, expected_key: dict[str, Any] | None = None) -> Scaling:
        """Read a scaling saved by :meth:`save`.

        Raises
        ------
        ValueError
            Unreadable file, wrong format, or a key that differs from ``expected_key`` in
            any of its entries (stale cache: other scenario, n_vars, samples or config).
        """
        try:
            d = json.loads(Path(path).read_text(encoding='utf-8'))
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f'cannot read scaling file {path}: {exc}') from exc
        if not isinstance(d, dict) or d.get('format') != 'suspension_tuning.scaling/1':
            raise ValueError(f'{path} is not a suspension_tuning scaling file')
        key = d.get('key', {})
        if expected_key is not None:
            diff = {k: (key.get(k), v) for k, v in expected_key.items() if key.get(k) != v}
            if diff:
                raise ValueError(f'scaling file {path} does not match: (stored, wanted) {diff}')
        funcs = tuple(
            FunctionScaling(**{k: (float('nan') if v is None else v) for k, v in f.items()})
            for f in d['functions']
        )
        return cls(
            funcs,
            key,
            np.asarray(d['x_samples'], dtype=float),
            np.asarray(d['full_values'], dtype=float),
            np.asarray(d['simplified_values'], dtype=float),
        )


def fit_scaling(
    x_samples: ArrayLike,
    full_values: ArrayLike,
    simplified_values: ArrayLike,
    names: tuple[str, ...] | None = None,
    key: dict[str, Any] | None = None,
) -> Scaling:
    """Fit eq. 25 per function from N paired full/simplified evaluations.

    Parameters
    ----------
    x_samples : array_like
        (N, n_vars) sample designs.
    full_values, simplified_values : array_like
        (N, 1 + m): objective then constraints, full and simplified model.
    names : tuple of str, optional
        Function names (default 'f', 'g_fl', 'g_fr', 'g_rl', 'g_rr' for 1 + 4 columns).
    key : dict, optional
        Cache key stored with the scaling.

    Returns
    -------
    Scaling
    """
    x = np.atleast_2d(np.asarray(x_samples, dtype=float))
    a = np.asarray(full_values, dtype=float)
    m = np.asarray(simplified_values, dtype=float)
    if a.ndim == 1:
        a, m = a[:, None], m[:, None]
    if a.shape != m.shape or a.shape[0] != x.shape[0]:
        raise ValueError(
            f'shapes disagree: x {x.shape}, full {a.shape}, simplified {m.shape} '
            '(need (N, n), (N, k), (N, k))'
        )
    if names is None:
        names = FUNCTION_NAMES if a.shape[1] == 5 else tuple(f'F{i}' for i in range(a.shape[1]))
    if len(names) != a.shape[1]:
        raise ValueError(f'{len(names)} names for {a.shape[1]} functions')
    funcs = tuple(fit_function(nm, a[:, i], m[:, i]) for i, nm in enumerate(names))
    return Scaling(funcs, dict(key or {}), x, a, m)


#: Version of what a calibration holds; raised whenever the simplified values it maps
#: change meaning, so that a cached calibration made before is never reused.
#: 2: the constraints' simplified values are the measure of
#: config/simplified_models.yaml ``tyre_hop_gradient`` (the smooth tyre-hop measure).
CALIBRATION_VERSION = 2


def scaling_key(scenario: str, n_vars: int, n_samples: int, seed: int,
                model_fingerprint: str | None = None) -> dict[str, Any]:
    """Cache key of a calibration.

    Version, scenario, n_vars, n_samples, seed, the hash of the simplified models'
    configuration and the fingerprint of the full model that gave the samples
    (:mod:`suspension_tuning.model_identity`; default: the built-in model with the
    integrator of config/vehicle.yaml).  A cached calibration is used only under an
    equal key, so never for another full model.
    """
    if model_fingerprint is None:
        model_fingerprint = builtin_fingerprint()
    return {
        'calibration_version': CALIBRATION_VERSION,
        'scenario': scenario,
        'n_vars': int(n_vars),
        'n_samples': int(n_samples),
        'seed': int(seed),
        'config_hash': config_hash(),
        'model_fingerprint': str(model_fingerprint),
    }


#: Default of config/optimiser.yaml ``calibration_fit.min_r2``.
MIN_FIT_R2 = 0.5


def load_min_fit_r2(path: str | Path) -> float:
    """``calibration_fit.min_r2`` of an optimiser file (default :data:`MIN_FIT_R2`)."""
    import yaml

    data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    section = (data or {}).get('calibration_fit') or {}
    if not isinstance(section, dict) or set(section) - {'min_r2'}:
        raise ValueError(f'{path}: calibration_fit takes one key, min_r2')
    value = section.get('min_r2', MIN_FIT_R2)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value <= 1.0:
        raise ValueError(f'{path}: calibration_fit.min_r2 must be a number <= 1, got {value!r}')
    return float(value)


def poor_fits(names: Sequence[str], r_squared: Sequence[float], full_max: Sequence[float],
              min_r2: float) -> list[tuple[str, float]]:
    """The functions whose eq. 25 fit is too poor for their gradients to be used.

    The objective always counts.  A constraint counts when it is *active* over the
    samples: at least one full-model sample lies on or beyond its bound (full maximum
    >= 0); a constraint every sample satisfies does not steer the optimiser there,
    and its fit is not judged.  A fit that could not be measured (non-finite R^2,
    e.g. a simplified value that does not change over the samples) counts as poor.

    Parameters
    ----------
    names, r_squared, full_max : sequences
        Per function (objective first): name, R^2 of the scaled simplified values
        against the full ones over the samples, largest full-model value.
    min_r2 : float
        Threshold (config/optimiser.yaml ``calibration_fit.min_r2``).

    Returns
    -------
    list of (name, r2)
        The poor fits, in order; empty when the calibration may be used.
    """
    poor = []
    for i, (name, r2, top) in enumerate(zip(names, r_squared, full_max)):
        if i > 0 and top < 0.0:
            continue
        if not (math.isfinite(r2) and r2 >= min_r2):
            poor.append((str(name), float(r2)))
    return poor


def fit_note(scenario: str, n_vars: int, names: Sequence[str], r_squared: Sequence[float],
             full_max: Sequence[float], min_r2: float) -> str:
    """One line on a calibration's fit: R^2 per function, which are judged, the verdict."""
    parts = []
    for i, (name, r2, top) in enumerate(zip(names, r_squared, full_max)):
        judged = i == 0 or top >= 0.0
        parts.append(f'{name} {r2:.3f}' + ('' if judged else ' (inactive)'))
    poor = poor_fits(names, r_squared, full_max, min_r2)
    verdict = ('poor: ' + ', '.join(n for n, _ in poor)) if poor else 'ok'
    return (f'{scenario}/{n_vars} eq. 25 fit R^2: ' + ', '.join(parts)
            + f'; threshold {min_r2:g}: {verdict}')
