"""Units of FMU variables: what the mapping and the FMU may declare, and conversions.

A mapped value travels in SI inside the tool (m^3, N, rad, m/s^2...).  At the FMU's
boundary it is converted to the unit the FMU declares for the variable (its
``unit`` attribute or its declared type's), or, where the FMU declares none, to the
unit the mapping states, or else left in SI.  A unit is known by name (table below)
or by the FMU's own unit definition (SI base-unit exponents, factor and offset, as
FMI 2.0 and 3.0 ``<UnitDefinitions>`` give them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Dimensions as SI base-unit exponents (kg, m, s, rad).
DIMENSIONS: dict[str, tuple[int, int, int, int]] = {
    'dimensionless': (0, 0, 0, 0),
    'volume': (0, 3, 0, 0),
    'length': (0, 1, 0, 0),
    'velocity': (0, 1, -1, 0),
    'acceleration': (0, 1, -2, 0),
    'force': (1, 1, -2, 0),
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
    'rad': ('angle', 1.0), 'deg': ('angle', math.pi / 180.0),
    'rad/s': ('angular_velocity', 1.0), 'deg/s': ('angular_velocity', math.pi / 180.0),
    's': ('time', 1.0),
}


@dataclass(frozen=True)
class Conversion:
    """``value_si = factor * value_fmu + offset`` for one variable, and the unit's name."""

    unit: str
    factor: float = 1.0
    offset: float = 0.0

    def to_fmu(self, value_si):
        """SI value(s) in the FMU's unit."""
        return (value_si - self.offset) / self.factor

    def to_si(self, value_fmu):
        """FMU value(s) in SI."""
        return self.factor * value_fmu + self.offset


def _from_base_unit(base) -> tuple[str | None, float, float]:
    """Dimension, factor and offset of an FMI BaseUnit (None: not one of ours)."""
    exps = (base.kg, base.m, base.s, base.rad)
    others = (base.A, base.K, base.mol, base.cd)
    dim = None
    if not any(others):
        for name, want in DIMENSIONS.items():
            plain_rate = name == 'angular_velocity' and exps == (0, 0, -1, 0)
            if exps == want or plain_rate:
                dim = name
                break
    return dim, float(base.factor), float(base.offset)


def resolve(quantity: str, declared: str | None, stated: str | None,
            unit_definitions: dict | None = None) -> Conversion:
    """The conversion of one mapped variable, or ValueError saying what does not fit.

    Parameters
    ----------
    quantity : str
        Dimension the tool expects (a key of :data:`DIMENSIONS`).
    declared : str or None
        Unit the FMU declares for the variable.
    stated : str or None
        Unit the mapping states for it.
    unit_definitions : dict, optional
        The FMU's unit definitions by name (objects with a ``baseUnit``).
    """
    if stated is not None and stated not in UNITS:
        raise ValueError(f'unit {stated!r} is not one this tool knows; known units of '
                         f'{quantity}: {known_units(quantity)}')
    if stated is not None and UNITS[stated][0] != quantity:
        raise ValueError(f'unit {stated!r} is a {UNITS[stated][0]}, expected a {quantity} '
                         f'({known_units(quantity)})')
    if declared is None:
        if stated is None:
            return Conversion(si_unit(quantity))
        return Conversion(stated, UNITS[stated][1])
    definition = (unit_definitions or {}).get(declared)
    if definition is not None and getattr(definition, 'baseUnit', None) is not None:
        dim, factor, offset = _from_base_unit(definition.baseUnit)
    elif declared in UNITS:
        (dim, factor), offset = UNITS[declared], 0.0
    elif stated is not None:
        return Conversion(stated, UNITS[stated][1])  # the FMU's unit name says nothing more
    else:
        raise ValueError(f'the FMU declares unit {declared!r}, which this tool does not know '
                         f'and the FMU does not define: state the unit in the mapping '
                         f'({known_units(quantity)})')
    if dim != quantity:
        raise ValueError(f'the FMU declares unit {declared!r}, not a {quantity} '
                         f'({known_units(quantity)})')
    if stated is not None and (not math.isclose(UNITS[stated][1], factor) or offset):
        raise ValueError(f'the mapping says {stated!r} but the FMU declares {declared!r}')
    return Conversion(declared, factor, offset)


def si_unit(quantity: str) -> str:
    """The SI unit name of a dimension."""
    return next(name for name, (dim, factor) in UNITS.items()
                if dim == quantity and factor == 1.0)


def known_units(quantity: str) -> str:
    """Comma-separated names of the known units of a dimension."""
    return ', '.join(repr(name) for name, (dim, _) in UNITS.items() if dim == quantity)
