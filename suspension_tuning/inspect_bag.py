"""``inspect_bag``: what a recorded run holds, and where to resume it.

``inspect_bag <bag> [--plots DIR] [--json] [--reindex]`` prints:

* the bag: file, complete or truncated (and why), topics with types and message
  counts, start time and duration;
* the run's configuration (the ``run_config`` metadata record);
* the optimisation, if ``/optimisation/progress`` (IterationRecord) and/or
  ``/optimisation/result`` (OptimisationResult; Optimise_Result in older bags) are
  present: the iteration table
  (iteration, f, largest violation, move limit, full and simplified runs, x), the
  reported design (x, f, g, physical values): the best feasible iterate with its
  iteration, or, saying so plainly, the least violating one when none was feasible
  (for a result recorded before results named it: found in the recorded history), the
  baseline design, the physical metrics of both (seat W_b RMS in m/s^2, first roll
  peak in deg, roll-rate RMS in deg/s, lift-off time per tyre in %), the evaluation
  counts, and the requests seen on the service-event topics;
* valve switching events from ``/suspension/valve_command`` and
  ``/suspension/valve_state``: the simulated time of each change of the commanded
  state and the delay until the actual state reached it (paper section 3: 50-100 ms).

``--plots DIR`` writes PNG files: ``convergence.png`` (f and the largest violation vs
iteration, the reported design marked), ``design.png`` (each design variable vs
iteration in physical units, and the plane of the first two with the reported design,
the last iterate and the baseline), ``metrics.png`` (the physical metrics of the
baseline and the reported design), ``telemetry.png`` (the last run's
``/<sim>/telemetry/*`` streams vs simulated time).  Names and units are those of the
design space the run used (the run configuration's config/design_space.yaml).

:func:`last_iteration` returns what :class:`suspension_tuning.optim.dynamic_q.DynamicQ`
needs to resume the optimisation (``history=``).  Everything here is plain Python
(messages are decoded with the definitions stored in the bag), no rclpy.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from suspension_tuning.bag.history import (  # noqa: F401 (inspect_bag's names before the move)
    FEEDBACK_SUFFIX,
    PROGRESS_TOPIC,
    RESULT_TOPIC,
    RUN_CONFIG_TOPIC,
    _record,
    _result_message,
    iterations,
    last_iteration,
)
from suspension_tuning.bag.reader import BagContents, decode, read_messages, reindex
from suspension_tuning.physical_metrics import metric_lines
from suspension_tuning.vehicle.design import DESIGN_SPACE_FILE, DesignSpace, load_design_space

VALVE_COMMAND_TOPIC = '/suspension/valve_command'
VALVE_STATE_TOPIC = '/suspension/valve_state'
#: ServiceEventInfo.event_type of a request as the server received it (service_msgs).
REQUEST_RECEIVED = 1
VALVE_FIELDS = ('front_spring', 'front_damping', 'rear_spring', 'rear_damping')


def _stamp_s(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _run_config(contents: BagContents) -> dict[str, Any] | None:
    """The bag's ``run_config`` metadata record as a dict (None without one)."""
    text = contents.metadata.get('run_config', {}).get('yaml', '')
    config = yaml.safe_load(text) if text else None
    return config if isinstance(config, dict) else None


def design_space(contents: BagContents) -> DesignSpace:
    """The design space of the bag's run: its configuration's design_space.yaml.

    A bag recorded before the design space was configurable ran the paper's ranges,
    which the shipped config/design_space.yaml holds; that is used then, and for a bag
    without a run configuration.
    """
    config = _run_config(contents) or {}
    files = config.get('vehicle_configuration') or {}
    if isinstance(files, dict) and isinstance(files.get(DESIGN_SPACE_FILE), dict):
        try:
            return DesignSpace.from_mapping(files[DESIGN_SPACE_FILE],
                                            f'the run configuration\'s {DESIGN_SPACE_FILE}')
        except ValueError:
            pass
    return load_design_space()


def run_gtol(config: dict[str, Any] | None) -> float:
    """Feasibility tolerance of a recorded run: its optimiser options' gtol.

    0 (only designs that violate no constraint at all are feasible) when the run
    configuration does not say.
    """
    options = (config or {}).get('optimiser_options') or {}
    gtol = options.get('gtol')
    return float(gtol) if gtol is not None else 0.0


def optimum(contents: BagContents) -> dict[str, Any] | None:
    """The last ``/optimisation/result`` as a dict (None if the bag has none).

    x, f, g and the physical values are the reported design: the best feasible
    iterate of the run, or the least violating one when none was feasible
    (``feasible``), of iteration ``best_iteration``, with ``max_violation``;
    ``source`` says where it comes from: 'result' (the result names it), or
    'history' for a result recorded before results named their best design, whose x
    is the last iterate: then the design is found in the recorded history by
    Dynamic-Q's rule, with the run's gtol (:func:`run_gtol`), and ``gtol`` says
    which.  A result without a design (a failed run) has ``best_iteration`` None.
    ``last_iterate``: iteration, x, f and max_violation of the run's last record.
    ``baseline``: x, f and the physical values of the baseline design (None in a result
    recorded without it); ``physical_metrics``: ``reported`` and ``baseline``, each
    metric name (unit in the name, :mod:`suspension_tuning.physical_metrics`) -> value.
    """
    msg = _result_message(contents)
    if msg is None:
        return None
    history = [_record(r) for r in msg.history]
    names = [str(n) for n in getattr(msg, 'metric_names', [])]
    baseline_x = [float(v) for v in getattr(msg, 'baseline_x', [])]
    out = {
        'success': bool(msg.success),
        'message': str(msg.message),
        'x': [float(v) for v in msg.x],
        'f': float(msg.f),
        'g': [float(v) for v in msg.g],
        'feasible': bool(getattr(msg, 'feasible', False)),
        'best_iteration': int(getattr(msg, 'best_iteration', 0)),
        'max_violation': float(getattr(msg, 'max_violation', math.nan)),
        'source': 'result',
        'physical': dict(
            zip([str(n) for n in msg.physical_names], [float(v) for v in msg.physical_values])
        ),
        'iterations': int(msg.iterations),
        'n_full_runs': int(msg.n_full_runs),
        'n_simplified_runs': int(msg.n_simplified_runs),
        'n_calibration_runs': int(msg.n_calibration_runs),
        'history': history,
        'wall_time_s': float(msg.wall_time_s),
        'stop_test': str(getattr(msg, 'stop_test', '')),
        'check': {'verdict': str(getattr(msg, 'check', '')),
                  'max_violation': float(getattr(msg, 'check_max_violation', math.nan)),
                  'note': str(getattr(msg, 'check_note', ''))},
        'baseline': None if not baseline_x else {
            'x': baseline_x, 'f': float(msg.baseline_f),
            'physical': dict(zip([str(n) for n in msg.physical_names],
                                 [float(v) for v in msg.baseline_physical_values]))},
        'physical_metrics': {
            'reported': dict(zip(names, [float(v) for v in getattr(msg, 'metrics', [])])),
            'baseline': dict(zip(names, [float(v) for v in
                                         getattr(msg, 'baseline_metrics', [])]))},
    }
    out['conditions'] = condition_table(msg)
    records = history or iterations(contents)
    if not out['x']:  # the run failed before it had a design to report
        out.update(feasible=False, best_iteration=None, max_violation=None)
    elif not hasattr(msg, 'best_iteration'):
        out.update(_best_of_history(records, run_gtol(_run_config(contents)),
                                    design_space(contents)))
    last = records[-1] if records else None
    out['last_iterate'] = None if last is None else {
        k: last[k] for k in ('iteration', 'x', 'f', 'max_violation')}
    return out


def condition_table(msg: Any) -> dict[str, Any] | None:
    """Per condition of a result over a condition set (None without a set).

    ``names``, ``worst`` (the condition with the largest f at the reported design),
    ``rounds`` (batches of full runs) and ``per_condition``: name -> ``f``,
    ``baseline_f`` (NaN when not recorded) and ``physical_metrics`` (``reported`` and
    ``baseline``, metric name -> value).
    """
    names = [str(n) for n in getattr(msg, 'condition_names', [])]
    if not names:
        return None
    metric_names = [str(n) for n in msg.condition_metric_names]
    k = len(metric_names)

    def row(values: Any, c: int) -> dict[str, float]:
        values = [float(v) for v in values]
        return dict(zip(metric_names, values[c * k:(c + 1) * k])) if values else {}

    def at(values: Any, c: int) -> float:
        return float(values[c]) if len(values) > c else math.nan

    return {'names': names, 'worst': str(msg.worst_condition), 'rounds': int(msg.n_rounds),
            'per_condition': {name: {
                'f': at(msg.condition_f, c), 'baseline_f': at(msg.condition_baseline_f, c),
                'physical_metrics': {'reported': row(msg.condition_metrics, c),
                                     'baseline': row(msg.condition_baseline_metrics, c)}}
                for c, name in enumerate(names)}}


def _best_of_history(records: list[dict[str, Any]], gtol: float,
                     space: DesignSpace) -> dict[str, Any]:
    """The reported-design fields of :func:`optimum` from recorded iterates."""
    from suspension_tuning.reported_design import best_record

    found = best_record(records, gtol)
    if found is None:
        return {'feasible': False, 'best_iteration': None, 'max_violation': None,
                'source': 'history', 'gtol': gtol}
    k, feasible = found
    best = records[k]
    return {'x': list(best['x']), 'f': best['f'], 'g': list(best['g']),
            'feasible': feasible, 'best_iteration': best['iteration'],
            'max_violation': best['max_violation'], 'source': 'history', 'gtol': gtol,
            'physical': space.physical_values(best['x'])}


def service_requests(contents: BagContents) -> dict[str, dict[str, int]]:
    """Per service-event topic: requests received by the server and designs in them."""
    out: dict[str, dict[str, int]] = {}
    for topic in contents.topics():
        if not topic.endswith('/_service_event'):
            continue
        requests = designs = 0
        for message in contents.on(topic):
            event = decode(contents, message)
            if event.info.event_type != REQUEST_RECEIVED or not event.request:
                continue
            requests += 1
            request = event.request[0]
            if hasattr(request, 'designs') and hasattr(request, 'n_vars') and request.n_vars:
                designs += len(request.designs) // int(request.n_vars)
            else:
                designs += 1
        out[topic[: -len('/_service_event')]] = {'requests': requests, 'designs': designs}
    return out


def valve_events(contents: BagContents) -> list[dict[str, Any]]:
    """Changes of the commanded valve state and when the actual state followed.

    Returns
    -------
    list of dict
        ``time_s`` (simulated time of the command, header.stamp), ``step``, ``state``
        (front_spring, front_damping, rear_spring, rear_damping), ``actual_time_s``
        and ``delay_s`` (None if the actual state never reached it in the bag).
    """

    def changes(topic: str) -> list[tuple[float, int, tuple[int, ...]]]:
        out, last = [], None
        for message in contents.on(topic):
            msg = decode(contents, message)
            state = tuple(int(getattr(msg, f)) for f in VALVE_FIELDS)
            if state != last:
                out.append((_stamp_s(msg.header), int(msg.step), state))
                last = state
        return out

    commands = changes(VALVE_COMMAND_TOPIC)[1:]  # the first message is the initial state
    actual = changes(VALVE_STATE_TOPIC)
    events = []
    for time_s, step, state in commands:
        reached = next(((t, s) for t, s, st in actual if st == state and t >= time_s), None)
        events.append(
            {
                'time_s': time_s,
                'step': step,
                'state': list(state),
                'actual_time_s': reached[0] if reached else None,
                'delay_s': reached[0] - time_s if reached else None,
            }
        )
    return events


def summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Everything ``inspect_bag`` reports, as a JSON-ready dict."""
    contents = read_messages(path)
    counts = contents.counts()
    info: dict[str, Any] = {
        'bag': str(path),
        'complete': contents.complete,
        'stop_reason': contents.stop_reason,
        'message_count': contents.message_count,
        'start_ns': contents.start_ns,
        'duration_s': contents.duration_ns / 1e9,
        'topics': {
            t: {'type': ty, 'count': counts[t]} for t, ty in sorted(contents.topics().items())
        },
        'run_config': None,
    }
    if 'run_config' in contents.metadata:
        text = contents.metadata['run_config'].get('yaml', '')
        info['run_config'] = (
            yaml.safe_load(text) if text else dict(contents.metadata['run_config'])
        )
    records = iterations(contents)
    result = optimum(contents)
    if records or result:
        info['iterations'] = records
        info['optimum'] = {k: v for k, v in result.items() if k != 'history'} if result else None
        last = records[-1] if records else {}
        info['evaluations'] = {
            'n_full_runs': result['n_full_runs'] if result else last.get('n_full_runs'),
            'n_simplified_runs': (
                result['n_simplified_runs'] if result else last.get('n_simplified_runs')
            ),
            'n_calibration_runs': result['n_calibration_runs'] if result else None,
            'iterations': result['iterations'] if result else len(records),
            'services': service_requests(contents),
        }
    if contents.on(VALVE_COMMAND_TOPIC):
        info['valve_events'] = valve_events(contents)
    return info


# ---------------------------------------------------------------------- plots
def _last_run(samples: list[tuple[float, Any]]) -> list[tuple[float, Any]]:
    """The samples after the last time the simulated time went backwards (a new run)."""
    start = 0
    for k in range(1, len(samples)):
        if samples[k][0] < samples[k - 1][0]:
            start = k
    return samples[start:]


def write_plots(path: str | os.PathLike[str], out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write convergence.png, design.png, metrics.png, telemetry.png (those with data)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    contents = read_messages(path)
    records = iterations(contents)
    result = optimum(contents)
    # the reported design: the best feasible iterate, else the least violating one
    best = result if result and result['best_iteration'] is not None else None
    label = ('reported: best feasible' if best and best['feasible']
             else 'reported: least violating (none feasible)')
    written = []
    if records:
        k = [r['iteration'] for r in records]
        fig, (ax_f, ax_g) = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
        ax_f.plot(k, [r['f'] for r in records], 'o-')
        ax_f.set_ylabel('objective f')
        ax_g.plot(k, [r['max_violation'] for r in records], 's-', color='tab:red')
        ax_g.set_ylabel('largest violation max(0, g)')
        ax_g.set_xlabel('iteration')
        if best:
            ax_f.plot(best['best_iteration'], best['f'], '*', markersize=14,
                      color='tab:green', label=label)
            ax_g.plot(best['best_iteration'], best['max_violation'], '*', markersize=14,
                      color='tab:green', label=label)
            ax_f.legend()
        fig.suptitle('Dynamic-Q convergence')
        fig.tight_layout()
        fig.savefig(out / 'convergence.png', dpi=100)
        plt.close(fig)
        written.append(out / 'convergence.png')
        written.append(_design_plot(out, records, best, label, design_space(contents),
                                    result.get('baseline') if result else None))
    metrics = (result or {}).get('physical_metrics') or {}
    if metrics.get('reported') or metrics.get('baseline'):
        written.append(_metrics_plot(out, metrics, 'optimum' if best and best['feasible']
                                     else 'reported design'))
    if (result or {}).get('conditions'):
        written.append(_conditions_plot(out, result['conditions'],
                                        'optimum' if best and best['feasible']
                                        else 'reported design'))
    telemetry = sorted(t for t in contents.topics() if '/telemetry/' in t)
    if telemetry:
        fig, axes = plt.subplots(
            len(telemetry), 1, sharex=True, figsize=(8, 2.2 * len(telemetry)), squeeze=False
        )
        for ax, topic in zip(axes[:, 0], telemetry):
            samples = [
                (lambda m: (_stamp_s(m.header), m))(decode(contents, msg))
                for msg in contents.on(topic)
            ]
            samples = _last_run(samples)
            t = [s[0] for s in samples]
            first = samples[0][1] if samples else None
            if first is not None and hasattr(first, 'linear_acceleration'):
                for axis in 'xyz':
                    ax.plot(
                        t,
                        [getattr(s[1].linear_acceleration, axis) for s in samples],
                        label=f'a_{axis} m/s^2',
                    )
                roll = [
                    math.degrees(
                        math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))
                    )
                    for q in (s[1].orientation for s in samples)
                ]
                ax.plot(t, roll, label='roll deg')
            elif first is not None and hasattr(first, 'vector'):  # Vector3Stamped: attitude
                for axis, label in (('x', 'roll deg'), ('y', 'pitch deg')):
                    ax.plot(t, [math.degrees(getattr(s[1].vector, axis)) for s in samples],
                            label=label)
            elif first is not None and hasattr(first, 'accel'):  # AccelStamped: a seat
                ax.plot(t, [s[1].accel.linear.z for s in samples], label='a_z m/s^2')
            elif first is not None and hasattr(first, 'name'):
                field = 'effort' if any(len(s[1].effort) for s in samples) else 'position'
                for j, name in enumerate(first.name):
                    ax.plot(
                        t,
                        [
                            getattr(s[1], field)[j]
                            if len(getattr(s[1], field)) > j
                            else float('nan')
                            for s in samples
                        ],
                        label=f'{name} {field}',
                    )
            ax.set_title(topic, fontsize=9)
            ax.legend(fontsize=7, loc='upper right')
        axes[-1, 0].set_xlabel('simulated time, s')
        fig.tight_layout()
        fig.savefig(out / 'telemetry.png', dpi=100)
        plt.close(fig)
        written.append(out / 'telemetry.png')
    return written


def _design_plot(out: Path, records: list[dict[str, Any]], best: dict[str, Any] | None,
                 label: str, space: DesignSpace, baseline: dict[str, Any] | None) -> Path:
    """design.png: each variable vs iteration (physical units), and the first two's plane.

    The plane shows the reported design, the last iterate and the baseline.
    """
    import matplotlib.pyplot as plt

    x = np.array([r['x'] for r in records], dtype=float)
    n = x.shape[1]
    try:
        variables = list(space.design_variables(n))
        names = space.names(n)
    except ValueError:  # a design the space cannot show (another n): normalised values
        variables, names = [], [f'x{j + 1}' for j in range(n)]

    def physical(xs: np.ndarray) -> np.ndarray:
        if not variables:
            return np.atleast_2d(xs)
        low, high = space.bounds(n)
        factors = np.array([1.0 / v.factor for v in variables])
        return (low + np.atleast_2d(xs) * (high - low)) * factors

    values = physical(x)
    k = [r['iteration'] for r in records]
    fig = plt.figure(figsize=(10, 1.6 * n + 1.2))
    grid = fig.add_gridspec(n, 2)
    for j in range(n):
        ax = fig.add_subplot(grid[j, 0])
        ax.plot(k, values[:, j], 'o-')
        ax.set_ylabel(names[j], fontsize=8)
        if j == n - 1:
            ax.set_xlabel('iteration')
    ax_p = fig.add_subplot(grid[:, 1])
    ax_p.plot(values[:, 0], values[:, 1], 'o-')
    ax_p.plot(values[-1, 0], values[-1, 1], 'X', markersize=10, color='tab:gray',
              label='last iterate')
    if best and len(best['x']) == n:
        b = physical(np.asarray(best['x'], float))[0]
        ax_p.plot(b[0], b[1], '*', markersize=14, color='tab:green', label=label)
    if baseline and len(baseline['x']) == n:
        b = physical(np.asarray(baseline['x'], float))[0]
        ax_p.plot(b[0], b[1], 's', markersize=8, color='k', label='baseline')
    if variables:
        low, high = space.bounds(n)
        ax_p.set_xlim(variables[0].in_unit(low[0]), variables[0].in_unit(high[0]))
        ax_p.set_ylim(variables[1].in_unit(low[1]), variables[1].in_unit(high[1]))
    ax_p.set_xlabel(names[0])
    ax_p.set_ylabel(names[1])
    ax_p.legend(fontsize=8)
    fig.suptitle(f'design in physical units ({space.source})', fontsize=9)
    fig.tight_layout()
    fig.savefig(out / 'design.png', dpi=100)
    plt.close(fig)
    return out / 'design.png'


def _metrics_plot(out: Path, metrics: dict[str, dict[str, float]], reported_label: str
                  ) -> Path:
    """metrics.png: each physical metric of the baseline and the reported design."""
    import matplotlib.pyplot as plt

    from suspension_tuning.physical_metrics import LABELS

    baseline, reported = metrics.get('baseline') or {}, metrics.get('reported') or {}
    names = list(dict.fromkeys([*reported, *baseline]))
    columns = min(3, len(names))
    rows = -(-len(names) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.6 * rows),
                             squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        label, unit = LABELS.get(name, (name, ''))
        heights = [baseline.get(name, math.nan), reported.get(name, math.nan)]
        ax.bar(['baseline', reported_label], heights, color=['tab:gray', 'tab:green'])
        for i, h in enumerate(heights):
            if math.isfinite(h):
                ax.annotate(f'{h:.3g}', (i, h), ha='center', va='bottom', fontsize=8)
        ax.set_title(label, fontsize=9)
        ax.set_ylabel(unit)
        ax.margins(y=0.15)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    fig.suptitle('physical metrics: baseline and reported design')
    fig.tight_layout()
    fig.savefig(out / 'metrics.png', dpi=100)
    plt.close(fig)
    return out / 'metrics.png'


def _conditions_plot(out: Path, conditions: dict[str, Any], reported_label: str) -> Path:
    """conditions.png: per condition, f and each physical metric, baseline and reported."""
    import matplotlib.pyplot as plt

    from suspension_tuning.physical_metrics import LABELS

    names = conditions['names']
    entries = [conditions['per_condition'][n] for n in names]
    metric_names = list(dict.fromkeys(
        m for e in entries for side in ('reported', 'baseline')
        for m in e['physical_metrics'][side]))
    panels = [('f', ('objective f', '-'))] + [(m, LABELS.get(m, (m, ''))) for m in metric_names]
    columns = min(3, len(panels))
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3.6 * columns, 2.8 * rows),
                             squeeze=False)
    x = np.arange(len(names))
    for ax, (key, (label, unit)) in zip(axes.ravel(), panels):
        if key == 'f':
            base = [e['baseline_f'] for e in entries]
            rep = [e['f'] for e in entries]
        else:
            base = [e['physical_metrics']['baseline'].get(key, math.nan) for e in entries]
            rep = [e['physical_metrics']['reported'].get(key, math.nan) for e in entries]
        ax.bar(x - 0.2, base, 0.4, color='tab:gray', label='baseline')
        ax.bar(x + 0.2, rep, 0.4, color='tab:green', label=reported_label)
        ax.set_xticks(x, names, rotation=45, ha='right', fontsize=7)
        ax.set_title(label, fontsize=9)
        ax.set_ylabel(unit)
    axes.ravel()[0].legend(fontsize=7)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    fig.suptitle(f"per condition (worst at the reported design: {conditions['worst']})")
    fig.tight_layout()
    fig.savefig(out / 'conditions.png', dpi=100)
    plt.close(fig)
    return out / 'conditions.png'


# ------------------------------------------------------------------------ CLI
def _format_optimum(best: dict[str, Any]) -> list[str]:
    """Text lines of the reported design: the best feasible one, or plainly none."""
    from suspension_tuning.reported_design import statement

    state = 'success' if best['success'] else 'FAILED'
    k = best['best_iteration']
    if k is None:
        return [f'result ({state}: {best["message"]}): no design reported']
    title = 'optimum' if best['feasible'] else 'reported design'
    lines = [f'{title} ({state}: {best["message"]}):',
             f'  {statement(best["feasible"], k, best["max_violation"])}'
             + (f' (max violation {best["max_violation"]:.4g})' if best['feasible'] else '')]
    if best['source'] == 'history':
        lines += [f'  (found in the recorded history with gtol = {best["gtol"]:g}: the result',
                  '  was recorded before results named their best design)']
    lines.append(f'  x = {best["x"]}')
    lines.append(f'  f = {best["f"]!r}')
    lines.append(f'  g = {best["g"]}')
    if best.get('stop_test'):
        lines.append(f'  stopped by: {best["stop_test"]} test')
    check = best.get('check') or {}
    if check.get('verdict') or check.get('note'):
        lines.append(f'  check at a tighter solver tolerance: '
                     f'{check.get("verdict") or "not checked"}'
                     + (f' ({check["note"]})' if check.get('note') else ''))
    for name, value in best['physical'].items():
        lines.append(f'  {name} = {value:g}')
    last = best.get('last_iterate')
    if last and last['iteration'] != k:
        lines.append(f'  last iterate: iteration {last["iteration"]}, f = {last["f"]!r}, '
                     f'max violation {last["max_violation"]:.4g}')
    base = best.get('baseline')
    if base:
        lines.append(f'baseline design: f = {base["f"]!r}, x = {base["x"]}')
        lines += [f'  {name} = {value:g}' for name, value in base['physical'].items()]
    conditions = best.get('conditions')
    if conditions:
        lines.append(f'conditions: {len(conditions["names"])}, worst at the reported design: '
                     f'{conditions["worst"]} ({conditions["rounds"]} rounds of full runs)')
        for name, entry in conditions['per_condition'].items():
            lines.append(f'  condition {name}: f baseline {entry["baseline_f"]:.6g}, '
                         f'reported {entry["f"]:.6g}')
            lines += ['    ' + line for line in metric_lines(
                entry['physical_metrics']['baseline'], entry['physical_metrics']['reported'],
                'optimum' if best['feasible'] else 'reported')]
    metrics = best.get('physical_metrics') or {}
    if metrics.get('reported') or metrics.get('baseline'):
        lines.append('physical metrics:')
        lines += metric_lines(metrics.get('baseline', {}), metrics.get('reported', {}),
                              'optimum' if best['feasible'] else 'reported')
    return lines


def _format(info: dict[str, Any]) -> str:
    lines = [
        f'bag: {info["bag"]}  ({"complete" if info["complete"] else "TRUNCATED: "}'
        f'{info["stop_reason"]})',
        f'messages: {info["message_count"]}, duration {info["duration_s"]:.3f} s',
        'topics:',
    ]
    width = max((len(t) for t in info['topics']), default=10)
    for topic, t in info['topics'].items():
        lines.append(f'  {topic:<{width}}  {t["count"]:>7}  {t["type"]}')
    if info.get('run_config'):
        lines.append('run configuration:')
        lines += ['  ' + line for line in yaml.safe_dump(info['run_config']).splitlines()]
    if 'iterations' in info:
        lines.append('iterations:')
        lines.append(
            f'  {"it":>3} {"f":>14} {"max viol":>11} {"move lim":>9} {"full":>5} {"simpl":>6}  x'
        )
        for r in info['iterations']:
            x = ' '.join(f'{v:.6f}' for v in r['x'])
            lines.append(
                f'  {r["iteration"]:>3} {r["f"]:>14.8g} {r["max_violation"]:>11.4g} '
                f'{r["move_limit"]:>9.4g} {r["n_full_runs"]:>5} '
                f'{r["n_simplified_runs"]:>6}  [{x}]'
            )
        best = info.get('optimum')
        if best:
            lines += _format_optimum(best)
        ev = info['evaluations']
        lines.append(
            f'evaluations: iterations {ev["iterations"]}, full-model runs '
            f'{ev["n_full_runs"]}, simplified-model runs {ev["n_simplified_runs"]}, '
            f'calibration runs {ev["n_calibration_runs"]}'
        )
        for service, n in ev['services'].items():
            lines.append(f'  {service}: {n["requests"]} requests, {n["designs"]} designs')
    if info.get('valve_events'):
        lines.append('valve switching (commanded -> actual, simulated time):')
        for e in info['valve_events']:
            delay = 'never' if e['delay_s'] is None else f'{e["delay_s"] * 1e3:.1f} ms'
            lines.append(f'  t = {e["time_s"]:.3f} s step {e["step"]}: {e["state"]} delay {delay}')
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``inspect_bag``."""
    parser = argparse.ArgumentParser(prog='inspect_bag', description=__doc__.split('\n')[0])
    parser.add_argument('bag', help='bag folder or .mcap file')
    parser.add_argument('--plots', metavar='DIR', help='write PNG plots into DIR')
    parser.add_argument('--json', action='store_true', help='print JSON instead of text')
    parser.add_argument(
        '--resume',
        action='store_true',
        help='continue the optimisation from the last recorded iteration (in-process)',
    )
    parser.add_argument('--max-iterations', type=int, help='iteration limit for --resume')
    parser.add_argument(
        '--reindex',
        action='store_true',
        help='first rewrite the bag in place, like ros2 bag reindex: a truncated bag '
        '(killed recorder) becomes a complete one, the schemas of an older bag come out '
        'in the layout rosbag2 writes (and Foxglove decodes)',
    )
    args = parser.parse_args(argv)
    try:
        if args.reindex:
            reindex(args.bag)
        info = summary(args.bag)
        if not info['complete'] and info['message_count'] == 0:
            raise ValueError(f'{args.bag}: {info["stop_reason"]}: no message could be read')
    except ValueError as exc:
        print(f'inspect_bag: {exc}', file=sys.stderr)
        return 2
    print(json.dumps(info, indent=1) if args.json else _format(info))
    if args.plots:
        for path in write_plots(args.bag, args.plots):
            print(f'plot: {path}', file=sys.stderr)
    if args.resume:
        from suspension_tuning.reported_design import reported_design
        from suspension_tuning.resume import resume
        from suspension_tuning.tuning import physical_settings

        try:
            result = resume(args.bag, args.max_iterations)
        except ValueError as exc:
            print(f'inspect_bag: cannot resume: {exc}', file=sys.stderr)
            return 2
        print(format_resumed(result))
        design = reported_design(result)
        if design is not None:
            for name, value in physical_settings(design.x).items():
                print(f'  {name}: {value:.4g}')
    return 0


def format_resumed(result: Any) -> str:
    """One line on a resumed run: its stop, the reported design and the run counts.

    The design is the best feasible one over the whole run (the bag's iterations and
    the new ones), or, saying so plainly, the least violating one.
    """
    from suspension_tuning.reported_design import reported_design

    design = reported_design(result)
    counts = (f'iterations {result.get("nit", 0)}, full-model runs {result.n_full_runs}, '
              f'simplified runs {result.n_simplified_runs}')
    if design is None:
        return f'resumed: {result.message}; no iterate evaluated; {counts}'
    return (f'resumed: {result.message}; {design.statement}: f = {design.f:.6g}, '
            f'x = {[round(v, 4) for v in design.x]}; {counts}')


if __name__ == '__main__':
    sys.exit(main())
