"""What a simulation worker runs, as a fingerprint that numbers can be keyed by.

A full model's answers belong to that model alone: an eq. 25 calibration fitted on
one vehicle is wrong for another, and an optimisation whose workers run two vehicles
mixes two objectives.  The *fingerprint* is a short hash of everything that decides a
worker's answers:

- the model kind (``builtin`` or ``fmu``);
- for an FMU: the SHA-256 of the file and its mapping (parsed, so comments and layout
  do not count; the mapping holds the fixed parameters and start values the worker
  sets);
- the configuration files the worker reads (``WORKER_CONFIG_FILES``: the design space
  (the worker turns normalised designs into physical settings with its ranges),
  vehicle, strut, tyre, road, scenarios (with the normalisation of eqs. 9 and 10),
  manoeuvre...) and the SHA-256 of every file a road of
  config/road.yaml names (key ``file``);
- the built-in model's integrator (``fixed_step`` or ``variable_step``).

Workers publish it in their latched ``~/model`` description and with every answer;
the coordinator and the gradient evaluator refuse to mix fingerprints, and the
calibration cache, the bag's run configuration and the study records carry it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import yaml

from suspension_tuning.paths import file_sha256
from suspension_tuning.vehicle.params import CONFIG_DIR

#: Version of the fingerprint's recipe: a change of what it covers changes every value.
FINGERPRINT_VERSION = 1
#: Characters of the SHA-256 hex digest kept (64 bits: a collision among a user's
#: models is not a practical concern; short enough for a log line and a file name).
FINGERPRINT_LENGTH = 16
#: The configuration files a simulation worker's answers depend on.
WORKER_CONFIG_FILES = (
    'design_space.yaml',
    'vehicle.yaml',
    'strut_4s4.yaml',
    'tyre.yaml',
    'road.yaml',
    'scenarios.yaml',
    'manoeuvre.yaml',
    'mixed.yaml',
    'valve_controller.yaml',
)
#: The description keys that make up the identity (the rest are for people).
IDENTITY_KEYS = ('model', 'fmu_sha256', 'mapping_content', 'config_sha256', 'road_files',
                 'integrator')
BUILTIN_NAME = 'Land Rover Defender 110, 4S4 (built-in full model)'


def road_files(config_dir: str | Path | None = None) -> dict[str, str]:
    """SHA-256 of each file a road of config/road.yaml names (``file`` key), by road.

    A file that does not exist hashes as ``'missing'``: the worker refuses that road
    when it is driven, and the fingerprint still differs from one with the file.
    """
    d = Path(config_dir) if config_dir is not None else CONFIG_DIR
    path = d / 'road.yaml'
    if not path.exists():
        return {}
    roads = (yaml.safe_load(path.read_text()) or {}).get('roads') or {}
    out: dict[str, str] = {}
    for name, spec in sorted(roads.items()):
        if isinstance(spec, dict) and spec.get('file'):
            file = Path(str(spec['file']))
            file = file if file.is_absolute() else d / file
            out[str(name)] = file_sha256(file) if file.is_file() else 'missing'
    return out


def files_sha256(names: tuple[str, ...], config_dir: str | Path | None = None) -> str:
    """SHA-256 (hex) of configuration files in order, names included (missing: a mark)."""
    d = Path(config_dir) if config_dir is not None else CONFIG_DIR
    h = hashlib.sha256()
    for name in names:
        path = d / name
        h.update(name.encode())
        h.update(path.read_bytes() if path.exists() else b'<missing>')
    return h.hexdigest()


def config_sha256(config_dir: str | Path | None = None) -> str:
    """SHA-256 (hex) of the worker's configuration files, names included."""
    return files_sha256(WORKER_CONFIG_FILES, config_dir)


def fingerprint(description: dict[str, Any]) -> str:
    """The fingerprint of a model description (its identity keys only).

    Parameters
    ----------
    description : dict
        A worker's model description (:func:`builtin_description` or
        :meth:`suspension_tuning.fmu.FmuModel.description`).

    Returns
    -------
    str
        ``FINGERPRINT_LENGTH`` hex digits.
    """
    identity = {key: description.get(key) for key in IDENTITY_KEYS}
    identity['version'] = FINGERPRINT_VERSION
    text = json.dumps(identity, sort_keys=True, separators=(',', ':'), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:FINGERPRINT_LENGTH]


def with_fingerprint(description: dict[str, Any]) -> dict[str, Any]:
    """The description with the configuration it ran under and its fingerprint added."""
    out = dict(description)
    out.setdefault('config_sha256', config_sha256())
    out.setdefault('road_files', road_files())
    out['fingerprint'] = fingerprint(out)
    return out


def builtin_description(integrator: str) -> dict[str, Any]:
    """The description of the built-in full model with ``integrator``, fingerprinted."""
    return with_fingerprint({'model': 'builtin', 'model_name': BUILTIN_NAME,
                             'integrator': str(integrator)})


def builtin_fingerprint(integrator: str | None = None) -> str:
    """Fingerprint of the built-in model (default integrator of config/vehicle.yaml)."""
    if integrator is None:
        from suspension_tuning.vehicle.params import load_vehicle_params
        integrator = load_vehicle_params().integrator.method
    return builtin_description(integrator)['fingerprint']


def summary_line(description: dict[str, Any]) -> str:
    """One line for a start-up log: the model's name, what it is and its fingerprint."""
    fp = description.get('fingerprint') or fingerprint(description)
    if description.get('model') == 'fmu':
        return (f"model fmu {description.get('fmu_file')} "
                f"({description.get('model_name')}, FMI {description.get('fmi_version')}, "
                f"sha256 {str(description.get('fmu_sha256'))[:12]}, mapping "
                f"{description.get('fmu_mapping') or '(inline)'}), fingerprint {fp}")
    return (f"model builtin {description.get('model_name', BUILTIN_NAME)} "
            f"(integrator {description.get('integrator')}), fingerprint {fp}")


class ModelMismatchError(ValueError):
    """Workers, or a request and its workers, that run different models."""


def check_same(fingerprints: dict[str, str], what: str = 'simulation workers') -> str:
    """The one fingerprint of ``fingerprints`` (worker name -> fingerprint).

    Raises
    ------
    ModelMismatchError
        They differ: the message names each worker and its fingerprint.
    ValueError
        ``fingerprints`` is empty.
    """
    if not fingerprints:
        raise ValueError(f'no fingerprint of the {what} to compare')
    values = set(fingerprints.values())
    if len(values) == 1:
        return values.pop()
    listing = ', '.join(f'{name}: {fp}' for name, fp in sorted(fingerprints.items()))
    raise ModelMismatchError(
        f'the {what} run different models ({listing}); one optimisation uses one model: '
        'give every worker the same model, FMU, mapping and configuration, or list only '
        'the matching ones in sim_workers')
