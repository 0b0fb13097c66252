"""Check the configuration files when a node or command starts, not at the first goal.

Every node of the graph and every command that reads ``config/*.yaml`` calls
:func:`check_config` before it serves: a file that is not valid YAML, a missing key, a
number written as text, a design space that cannot be used (lower above upper, a
negative or zero-width range, a baseline outside its range, an unknown quantity, a unit
of another quantity, a coil-spring rate for the built-in gas-spring model) is reported
in one line naming the file and the key (:class:`ConfigError`); the programs print it
and exit with status 2.

The check runs the loaders the models use (the same parse, cached per file and
modification time, :func:`suspension_tuning.paths.read_yaml`), so what it accepts is
what a run accepts; it does not run a simulation.  A goal that meets an edited file
later reports the same line first (the coordinator checks again before each goal).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from suspension_tuning.paths import KEY_TRACKER, KeyTracker, config_dir, read_yaml


class ConfigError(ValueError):
    """A configuration file that cannot be used; the message names the file and key."""


def _relative(path: str | Path) -> str:
    """``config/<name>`` for a file of the configuration folder, else the path."""
    path = Path(path)
    try:
        return f'config/{path.resolve().relative_to(config_dir().resolve())}'
    except ValueError:
        return str(path)


def _run(check: Callable[[], object], default_file: str) -> None:
    """Run one loader; its failure as a ConfigError naming the file and key."""
    tracker = KeyTracker()
    token = KEY_TRACKER.set(tracker)
    try:
        check()
    except ConfigError:
        raise
    except (KeyError, ValueError, TypeError) as error:
        raise ConfigError(_message(error, tracker, default_file)) from None
    finally:
        KEY_TRACKER.reset(token)


#: A dotted key path (``integration.check.gtol``) opening a loader's message: the
#: loader named the key itself, which need not be the last key it read.
_DOTTED_KEY = re.compile(r'[A-Za-z_]\w*(\.[A-Za-z_]\w*)+')


def _message(error: Exception, tracker: KeyTracker, default_file: str) -> str:
    text = str(error.args[0]) if isinstance(error, KeyError) and error.args else str(error)
    first = text.split(':', 1)[0].strip()
    if first.endswith('.yaml') or first.endswith('.crg') or first.endswith('.csv'):
        head, _, rest = text.partition(':')
        return f'{_relative(head.strip())}:{rest}'  # the loader named the file already
    source, key = tracker.last if tracker.last else (default_file, '')
    source = _relative(source)
    if isinstance(error, KeyError):
        return f'{source}: missing key {key or text}'
    if 'convert' in text or 'must be a real number' in text or 'argument must be' in text:
        return f'{source}: {key}: expected a number, {text}'
    word = text.split(' ', 1)[0]
    if not key or text.startswith(key) or _DOTTED_KEY.fullmatch(word):
        return f'{source}: {text}'  # the loader named the key already
    return f'{source}: {key}: {text}'


def check_design_space(builtin_model: bool = True, path: str | Path | None = None) -> None:
    """Check config/design_space.yaml (or ``path``).

    Parameters
    ----------
    builtin_model : bool
        The built-in Defender model (gas springs) will run it: a spring of quantity
        'stiffness' (a coil-spring rate, for an FMU) is refused.

    Raises
    ------
    ConfigError
        The file's line: file, key, what is wrong.
    """
    from suspension_tuning.vehicle.design import DESIGN_SPACE_FILE, load_design_space

    file = _relative(path) if path is not None else f'config/{DESIGN_SPACE_FILE}'
    holder = {}
    _run(lambda: holder.setdefault('space', load_design_space(path)), file)
    spring = holder['space'].spring
    if builtin_model and spring.quantity != 'volume':
        raise ConfigError(
            f'{file}: spring.quantity: {spring.quantity!r} (a coil-spring rate) needs a model '
            "of one's own run as an FMU (docs/fmu.md); the built-in 4S4 model has gas springs: "
            "quantity 'volume' in a unit of volume (L)")


def check_config(builtin_model: bool = True) -> None:
    """Check every configuration file the graph reads (config/).

    Each ``*.yaml`` file of the folder must parse; then the design space, the vehicle
    (vehicle, strut, tyre), the scenarios with the ride road, the manoeuvre, the
    simplified models and the optimiser options are loaded as a run loads them.

    Parameters
    ----------
    builtin_model : bool
        The built-in Defender model will run (see :func:`check_design_space`).

    Raises
    ------
    ConfigError
        The first problem found: one line naming the file and the key.
    """
    directory = config_dir()
    for path in sorted(directory.glob('*.yaml')):
        _run(lambda p=path: read_yaml(p), _relative(path))
    check_design_space(builtin_model)

    from suspension_tuning.answer_check import load_check_settings
    from suspension_tuning.optim.correction import load_correction_options
    from suspension_tuning.optim.dynamic_q import load_options
    from suspension_tuning.optim.scaling import load_min_fit_r2
    from suspension_tuning.vehicle.manoeuvre import load_manoeuvre
    from suspension_tuning.vehicle.params import load_scenarios_config, load_vehicle_params
    from suspension_tuning.vehicle.pitch_plane import load_simplified_config
    from suspension_tuning.vehicle.scenarios import ride_road_spec

    params = {}
    _run(lambda: params.setdefault('vehicle', load_vehicle_params()), 'config/vehicle.yaml')
    _run(load_check_settings, 'config/vehicle.yaml')
    _run(lambda: ride_road_spec(load_scenarios_config()['ride']), 'config/scenarios.yaml')
    _run(lambda: load_manoeuvre(params['vehicle'].wheelbase_m), 'config/manoeuvre.yaml')
    _run(load_simplified_config, 'config/simplified_models.yaml')
    optimiser = str(directory / 'optimiser.yaml')
    for loader in (load_options, load_correction_options, load_min_fit_r2):
        _run(lambda f=loader: f(optimiser), 'config/optimiser.yaml')


def check_params_files(argv: list[str]) -> None:
    """Check the ROS parameter files named on a command line (``--params-file FILE``).

    rcl parses them when the program initialises ROS and ends it with a traceback on a
    syntax error; checked first, each one is refused in one line naming the file, the
    line and the column.  Only the arguments after ``--ros-args`` are ROS arguments.

    Raises
    ------
    ConfigError
        A parameter file that does not exist, cannot be read, is not valid YAML or does
        not hold a mapping.
    """
    import yaml

    from suspension_tuning.paths import yaml_error_text

    ros = False
    for k, arg in enumerate(argv):
        if arg == '--ros-args':
            ros = True
        elif arg == '--':
            ros = False
        elif ros and arg == '--params-file' and k + 1 < len(argv):
            path = Path(argv[k + 1])
            try:
                data = yaml.safe_load(path.read_text(encoding='utf-8'))
            except OSError as error:
                raise ConfigError(f'--params-file {path}: cannot read it '
                                  f'({error.strerror or error})') from None
            except yaml.YAMLError as error:
                raise ConfigError(f'--params-file {path}: {yaml_error_text(error)}') from None
            if not isinstance(data, dict):
                raise ConfigError(f'--params-file {path}: expected a mapping of node names '
                                  'to ros__parameters')
