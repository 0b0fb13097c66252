"""The full model a simulation worker runs, from its parameters (built-in or an FMU).

Kept apart from :mod:`suspension_tuning.fmu.model` and
:mod:`suspension_tuning.fmu.isolated`, which it chooses between, so that neither of
those imports the other's user.
"""

from __future__ import annotations

from typing import Any

from suspension_tuning.fmu.isolated import IsolatedFmuModel
from suspension_tuning.fmu.model import FmuConfigError, FmuModel

MODELS = ('builtin', 'fmu')
#: Where a worker runs its FMU: in child processes that can be stopped, or in its own.
ISOLATIONS = ('process', 'none')


def worker_model(model: str, fmu_path: str = '', fmu_mapping: str = '',
                 isolation: str = 'process', **options: Any) -> FmuModel | None:
    """The full model a simulation worker runs: None (built-in) or an FmuModel.

    The settings must agree, so that a worker never starts half-configured.

    Parameters
    ----------
    model, fmu_path, fmu_mapping : str
        The worker's parameters of those names.
    isolation : str
        'process' (each design in a child process that can be stopped:
        :class:`~suspension_tuning.fmu.isolated.IsolatedFmuModel`, which takes
        ``options``) or 'none' (in this process; ``options`` may give ``on_message``).

    Raises
    ------
    FmuConfigError
        An unknown model or isolation, 'fmu' without fmu_path or fmu_mapping, 'builtin'
        with either set, or an FMU and mapping that do not fit (see :class:`FmuModel`).
    MappingError
        A bad mapping file.
    """
    if model not in MODELS:
        raise FmuConfigError(f'model must be one of {", ".join(MODELS)}, got {model!r}')
    if model == 'builtin':
        given = [name for name, value in (('fmu_path', fmu_path), ('fmu_mapping', fmu_mapping))
                 if value]
        if given:
            raise FmuConfigError(f'{" and ".join(given)} set but model is builtin: add '
                                 '-p model:=fmu to run the FMU, or drop them')
        return None
    missing = [name for name, value in (('fmu_path', fmu_path), ('fmu_mapping', fmu_mapping))
               if not value]
    if missing:
        raise FmuConfigError(f'model fmu needs {" and ".join(missing)} (-p fmu_path:=<file.fmu> '
                             '-p fmu_mapping:=<mapping.yaml>, docs/fmu.md)')
    if isolation not in ISOLATIONS:
        raise FmuConfigError(f'fmu_isolation must be one of {", ".join(ISOLATIONS)}, got '
                             f'{isolation!r}')
    if isolation == 'process':
        return IsolatedFmuModel(fmu_path, fmu_mapping, **options)
    fmu = FmuModel(fmu_path, fmu_mapping)
    fmu.on_message = options.get('on_message')
    return fmu
