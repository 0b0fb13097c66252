"""Units the tool knows by name: their dimension and their factor to SI (no rclpy).

The design space (config/design_space.yaml), the FMU mapping and the FMU's own unit
declarations name units from this table.  Inside the tool every value is SI; a unit
appears only where a value is read or shown.
"""

from __future__ import annotations

import math
import re

#: Dimensions as SI base-unit exponents (kg, m, s, rad).
DIMENSIONS: dict[str, tuple[int, int, int, int]] = {
    'dimensionless': (0, 0, 0, 0),
    'volume': (0, 3, 0, 0),
    'length': (0, 1, 0, 0),
    'velocity': (0, 1, -1, 0),
    'acceleration': (0, 1, -2, 0),
    'force': (1, 1, -2, 0),
    'stiffness': (1, 0, -2, 0),
    'torsional_stiffness': (1, 2, -2, -1),
    'pressure': (1, -1, -2, 0),
    'angle': (0, 0, 0, 1),
    'angular_velocity': (0, 0, -1, 1),
    'time': (0, 0, 1, 0),
}

#: Unit names this tool knows: (dimension, factor to SI).  FMI base units count
#: angles in rad; a unit without rad (plain 1/s) is accepted for angular velocity.
UNITS: dict[str, tuple[str, float]] = {
    '1': ('dimensionless', 1.0), '-': ('dimensionless', 1.0), '': ('dimensionless', 1.0),
    'm3': ('volume', 1.0), 'm^3': ('volume', 1.0), 'L': ('volume', 1e-3),
    'l': ('volume', 1e-3), 'dm3': ('volume', 1e-3), 'cm3': ('volume', 1e-6),
    'm': ('length', 1.0), 'mm': ('length', 1e-3), 'cm': ('length', 1e-2),
    'm/s': ('velocity', 1.0), 'km/h': ('velocity', 1.0 / 3.6),
    'm/s2': ('acceleration', 1.0), 'm/s^2': ('acceleration', 1.0),
    'm/(s2)': ('acceleration', 1.0), 'm.s-2': ('acceleration', 1.0),
    'N': ('force', 1.0), 'kN': ('force', 1e3),
    'N/m': ('stiffness', 1.0), 'kN/m': ('stiffness', 1e3), 'N/mm': ('stiffness', 1e3),
    'N.m/rad': ('torsional_stiffness', 1.0), 'kN.m/rad': ('torsional_stiffness', 1e3),
    'Pa': ('pressure', 1.0), 'kPa': ('pressure', 1e3), 'bar': ('pressure', 1e5),
    'MPa': ('pressure', 1e6),
    'rad': ('angle', 1.0), 'deg': ('angle', math.pi / 180.0),
    'rad/s': ('angular_velocity', 1.0), 'deg/s': ('angular_velocity', math.pi / 180.0),
    's': ('time', 1.0),
}


def si_unit(quantity: str) -> str:
    """The SI unit name of a dimension."""
    return next(name for name, (dim, factor) in UNITS.items()
                if dim == quantity and factor == 1.0)


def known_units(quantity: str) -> str:
    """Comma-separated names of the known units of a dimension."""
    return ', '.join(repr(name) for name, (dim, _) in UNITS.items() if dim == quantity)


def unit_suffix(unit: str) -> str:
    """The unit as a name suffix: ``'L'`` -> ``'l'``, ``'kN/m'`` -> ``'kn_per_m'``.

    Dimensionless units give ``''`` (a name without suffix).
    """
    if unit in UNITS and UNITS[unit][0] == 'dimensionless':
        return ''
    text = unit.lower().replace('/', '_per_').replace('^', '')
    return re.sub(r'[^a-z0-9_]', '', text)
