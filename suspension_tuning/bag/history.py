"""The iteration records of an optimisation bag, and where a run can resume from.

Read by :mod:`suspension_tuning.inspect_bag` (the summary, the plots) and by
:mod:`suspension_tuning.resume` (:func:`last_iteration`), which therefore need not
import each other.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import yaml

from suspension_tuning.bag.reader import BagContents, decode, read_messages

PROGRESS_TOPIC = '/optimisation/progress'
RESULT_TOPIC = '/optimisation/result'
RUN_CONFIG_TOPIC = '/optimisation/run_config'
FEEDBACK_SUFFIX = '/_action/feedback'


def _record(msg: Any) -> dict[str, Any]:
    """An IterationRecord as a plain dict (lists of floats, ints)."""
    return {
        'iteration': int(msg.iteration),
        'x': [float(v) for v in msg.x],
        'f': float(msg.f),
        'g': [float(v) for v in msg.g],
        'move_limit': float(msg.move_limit),
        'move_limit_next': float(getattr(msg, 'move_limit_next', 0.0)),
        'max_violation': float(msg.max_violation),
        'n_full_runs': int(msg.n_full_runs),
        'n_simplified_runs': int(msg.n_simplified_runs),
        'wall_time_s': float(msg.wall_time_s),
    }


def iterations(contents: BagContents) -> list[dict[str, Any]]:
    """The iteration records of the (last) run in the bag.

    From ``/optimisation/progress``; if the bag has none, from the action feedback,
    else from the result's history.  A record whose iteration number does not grow
    starts a new run: only the last run is returned.
    """
    messages = contents.on(PROGRESS_TOPIC)
    if messages:
        records = [_record(decode(contents, m)) for m in messages]
    else:
        feedback = [t for t in contents.topics() if t.endswith(FEEDBACK_SUFFIX)]
        if feedback:
            # Calibration feedback (phase 'calibration') carries no iteration; bags
            # recorded before the phase field have iterations only.
            decoded = [decode(contents, m).feedback for m in contents.on(feedback[0])]
            records = [_record(f.latest) for f in decoded
                       if getattr(f, 'phase', 'iteration') != 'calibration']
        else:
            result = _result_message(contents)
            records = [_record(r) for r in result.history] if result is not None else []
    start = 0
    for k in range(1, len(records)):
        if records[k]['iteration'] <= records[k - 1]['iteration']:
            start = k
    return records[start:]


def _result_message(contents: BagContents) -> Any:
    """The last ``/optimisation/result`` message, decoded (None if the bag has none)."""
    messages = contents.on(RESULT_TOPIC)
    return decode(contents, messages[-1]) if messages else None


def last_iteration(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What the optimiser needs to resume the bag's run from its last iteration.

    Returns
    -------
    dict
        ``history``: records in the form :class:`~suspension_tuning.optim.dynamic_q.DynamicQ`
        accepts (``x``, ``f``, ``g``, ``h`` = [], ``accepted``, ``from_iteration``,
        ``max_violation``, ``rho_next``: the move limit the next record used, and for
        the last record its own move limit);
        ``x``: the last iterate; ``iteration``; ``run_config`` (dict or None);
        ``scenario``, ``n_vars`` and ``options`` (``optimiser_options``) from it when
        present.

    Raises
    ------
    ValueError
        If the bag holds no iteration records.
    """
    contents = read_messages(path)
    records = iterations(contents)
    if not records:
        raise ValueError(
            f'{path}: no iteration records (no /optimisation/progress, feedback '
            'or result) to resume from'
        )
    history = []
    for k, rec in enumerate(records):
        history.append(
            {
                'iteration': rec['iteration'],
                'x': np.asarray(rec['x'], dtype=float),
                'f': rec['f'],
                'g': np.asarray(rec['g'], dtype=float),
                'h': np.zeros(0),
                'max_violation': rec['max_violation'],
                'accepted': True,
                'from_iteration': k - 1,
                # IterationRecord.move_limit is the limit the step to this record used (the
                # coordinator publishes the optimiser's 'rho'); the limit after record k is
                # the one record k + 1 used.  After the last record it is not recorded: its
                # own limit is taken (the optimiser may have halved or doubled it).
                # Records carry move_limit_next (the coordinator publishes the optimiser's
                # rho_next); older bags without it fall back to the next record's limit.
                'rho_next': rec['move_limit_next'] or (
                    records[k + 1]['move_limit'] if k + 1 < len(records) else rec['move_limit']
                ),
                'n_full_runs': rec['n_full_runs'],
                'n_simplified_runs': rec['n_simplified_runs'],
            }
        )
    config = None
    if 'run_config' in contents.metadata:
        text = contents.metadata['run_config'].get('yaml', '')
        config = yaml.safe_load(text) if text else None
    out = {
        'history': history,
        'x': history[-1]['x'].copy(),
        'iteration': history[-1]['iteration'],
        'run_config': config,
    }
    if isinstance(config, dict):
        out['scenario'] = config.get('scenario')
        out['n_vars'] = config.get('n_vars')
        out['options'] = config.get('optimiser_options')
    return out
