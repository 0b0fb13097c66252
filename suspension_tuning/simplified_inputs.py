"""The simplified models' inputs as they travel through the graph.

Paper section 6.1: the simplified handling model "uses exactly the same steering input
as the MSC.ADAMS model for that iteration", and the full model's slip angles.  These
inputs are captured from the full model's run at the current design by
:class:`suspension_tuning.vehicle.simplified.SimplifiedInputs`; the simulation node
returns them with the design's values, and the coordinator passes them on to the
gradient evaluator, packed as a TimeHistories message (flat, row-major) by
:func:`pack` and unpacked by :func:`unpack`.  The ride model needs nothing from the
run (the seeded road is known in advance): its message is empty.  The mixed scenario's
handling part travels the same way (its lane change, :class:`SimplifiedInputs`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from suspension_tuning.vehicle.handling_model import HandlingInputs
from suspension_tuning.vehicle.simplified import INPUT_SCENARIOS, SimplifiedInputs

CORNERS = ('fl', 'fr', 'rl', 'rr')
CHANNELS = ('steer_rad', *(f'slip_angle_{c}_rad' for c in CORNERS))
SCALARS = ('speed_mps', 'first_lane_change_start_s', 'first_lane_change_end_s',
           'manoeuvre_start_s', 'manoeuvre_end_s', 't0_s')


def pack(inputs: SimplifiedInputs | None, message: Any) -> Any:
    """Fill a TimeHistories message from simplified-model inputs (empty for ride)."""
    if inputs is None or inputs.handling is None:
        return message
    h: HandlingInputs = inputs.handling
    data = np.vstack([h.steer_rad[None, :], h.slip_angle_rad])
    message.dt_s = h.dt_s
    message.names = list(CHANNELS)
    message.n_samples = int(data.shape[1])
    message.data = data.ravel().tolist()
    message.scalar_names = list(SCALARS)
    message.scalars = [h.speed_mps, *h.first_lane_change_s, *h.manoeuvre_s, float(h.t_s[0])]
    return message


def unpack(scenario: str, message: Any, x: np.ndarray | None = None) -> SimplifiedInputs:
    """Simplified-model inputs of a scenario from a TimeHistories message.

    Raises
    ------
    ValueError
        The handling or mixed scenario without inputs, or channels that do not fit.
    """
    if scenario not in INPUT_SCENARIOS:
        return SimplifiedInputs(scenario, x)
    if list(message.names) != list(CHANNELS) or list(message.scalar_names) != list(SCALARS):
        raise ValueError(f'the {scenario} gradient needs the full model\'s inputs at x '
                         f'(channels {list(CHANNELS)}), got {list(message.names)}')
    n = int(message.n_samples)
    data = np.asarray(message.data, dtype=float)
    if data.size != len(CHANNELS) * n:
        raise ValueError(f'inputs hold {data.size} values, expected {len(CHANNELS)} x {n}')
    data = data.reshape(len(CHANNELS), n)
    speed, lc0, lc1, m0, m1, t0 = (float(v) for v in message.scalars)
    handling = HandlingInputs(t_s=t0 + float(message.dt_s) * np.arange(n), speed_mps=speed,
                              steer_rad=data[0], slip_angle_rad=data[1:],
                              first_lane_change_s=(lc0, lc1), manoeuvre_s=(m0, m1))
    return SimplifiedInputs(scenario, x, handling)
