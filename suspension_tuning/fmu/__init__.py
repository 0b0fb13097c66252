"""A user's full vehicle model as an FMU (FMI 2.0 / 3.0 co-simulation), run with FMPy.

See docs/fmu.md for the mapping file; :class:`FmuModel` evaluates designs like
:func:`suspension_tuning.evaluation.evaluate`.  No rclpy here: the simulation node
plugs the model in.
"""

from suspension_tuning.fmu.mapping import FmuMapping, MappingError, load_mapping, parse_mapping
from suspension_tuning.fmu.model import FmuConfigError, FmuModel, FmuRunError
from suspension_tuning.fmu.worker import worker_model

__all__ = ['FmuConfigError', 'FmuMapping', 'FmuModel', 'FmuRunError', 'MappingError',
           'load_mapping', 'parse_mapping', 'worker_model']
