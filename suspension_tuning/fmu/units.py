"""Units of FMU variables: what the mapping and the FMU may declare, and conversions.

A mapped value travels in SI inside the tool (m^3, N, rad, m/s^2...).  At the FMU's
boundary it is converted to the unit the FMU declares for the variable (its
``unit`` attribute or its declared type's), or, where the FMU declares none, to the
unit the mapping states, or else left in SI.  A unit is known by name (the table of
:mod:`suspension_tuning.units`) or by the FMU's own unit definition (SI base-unit
exponents, factor and offset, as FMI 2.0 and 3.0 ``<UnitDefinitions>`` give them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from suspension_tuning.units import DIMENSIONS, UNITS, known_units, si_unit

__all__ = ['DIMENSIONS', 'UNITS', 'Conversion', 'known_units', 'resolve', 'si_unit']


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
