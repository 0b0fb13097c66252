"""``tune``: send an optimisation goal to the coordinator and show its progress.

Usage::

    ros2 run suspension_tuning tune --scenario ride --n-vars 4 --gradient simplified

Extra constraints from another scenario or a named metric::

    tune --scenario ride --constraint 'handling:f_hand<=0.8'

The ride on another road than config/scenarios.yaml's: a road of config/road.yaml by
name, or an OpenCRG (.crg) or CSV (.csv) file (sent as an absolute path: the workers
read it); a file shorter than the ride run is refused unless ``--repeat-road`` says to
repeat it (a warning in the workers' log names the period that introduces)::

    tune --scenario ride --road belgian_block_measured
    tune --scenario ride --road ~/tracks/gerotek_belgian.crg

The ride or handling over a set of operating conditions (speeds, payloads, roads,
manoeuvre speeds; docs/conditions.md),
the worst case (default) or the weighted mean; the file is checked before the goal goes
out (one line naming the file, the condition and the key, exit status 2)::

    tune --scenario ride --n-vars 4 --conditions config/conditions.yaml
    tune --scenario ride --conditions my_set.yaml --condition-form mean
    tune --scenario ride --conditions my_set.yaml --constraint 'ride:a_rms_driver_mps2<=1.0'
    tune --scenario handling --n-vars 4 --conditions config/conditions_handling.yaml

One recorded full-model run of a design instead of an optimisation (any scenario; in
'mixed' the valves switch closed-loop), e.g. for a bag to look at in Foxglove::

    tune --scenario mixed --evaluate --x0 0.5 0.5

A start point in physical units, by the names of config/design_space.yaml::

    tune --scenario ride --n-vars 2 --start dpsf=1.2 gas_volume_l=0.35

Live telemetry for one goal (``ros2 topic hz``, Foxglove's live view): every simulation
worker's ``telemetry_rate`` set for the goal and set back when ``tune`` ends::

    tune --scenario ride --evaluate --telemetry-rate 1.0

Prints the eq. 25 calibration's progress (full-model samples done of total; the first
run of a model configuration spends them before its first iteration), then one line
per Dynamic-Q iteration (iteration, f, largest violation, model runs so far) from the
action's feedback, then the result: the best feasible design seen as the optimum, with
its iteration, in physical units (the names and units of config/design_space.yaml), or,
when no iterate was feasible, "no feasible design found" and the least violating one;
then the baseline design and the physical metrics of both (seat W_b RMS in m/s^2,
first roll peak in deg, roll-rate RMS in deg/s, lift-off time per tyre in %).  Ctrl-C
cancels the goal and exits with status 130.

Without an action server on the ROS domain, ``tune`` says at once that it waits for it
(the action and the domain), and after ``--server-timeout`` what to check.  Numbers out
of range (``--n-vars -2``, ``--max-iterations -1``, ``--move-limit -0.2``) are refused as
argparse refuses any bad option, naming it (exit status 2).

The goal goes to one action server only: with more than one server of the action on
the ROS domain (e.g. a second ``graph`` left running) each would run it, so ``tune``
says so and exits with status 2 before sending it (it waits up to the nodes' discovery
window, 3.5 s from its start, to see them, :mod:`suspension_tuning.nodes._unique`).  A
second server seen only once the goal is accepted, or accepting it too (rclpy's "Two
goals were accepted with the same ID"), is reported the same way, and the goal is
cancelled.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

import rclpy
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.signals import SignalHandlerOptions
from suspension_tuning_interfaces.action import Optimise
from suspension_tuning_interfaces.msg import Constraint

from suspension_tuning.config_check import check_params_files
from suspension_tuning.nodes._spin import wait_future
from suspension_tuning.nodes._unique import POLL_S, discovery_window_s
from suspension_tuning.physical_metrics import metric_lines
from suspension_tuning.reported_design import statement
from suspension_tuning.tuning import OBJECTIVE_NAMES, ConstraintSpec
from suspension_tuning.vehicle.design import DesignSpace, load_design_space


def _number(kind: type, minimum: float, strict: bool, maximum: float = float('inf')):
    """An argparse type: a finite ``kind`` (int or float) from ``minimum`` to ``maximum``.

    ``strict``: greater than ``minimum``, else at least ``minimum``.  Refused values get
    argparse's message naming the option (exit status 2), before any ROS set-up: the
    goal's fields are unsigned (``max_iterations``: uint32) or must be positive (the move
    limit), and a negative number would fail far from what the user typed.
    """
    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f'{text!r} is not a {"whole number" if kind is int else "number"}') from None
        low_ok = value > minimum if strict else value >= minimum
        if not (low_ok and value <= maximum and math.isfinite(value)):
            bound = f'{"greater than" if strict else "at least"} {minimum:g}'
            if math.isfinite(maximum):
                bound += f' and at most {maximum}'
            raise argparse.ArgumentTypeError(f'must be {bound}, got {text}')
        return value

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


def _design_size(text: str) -> int:
    """An argparse type: a number of design variables config/design_space.yaml offers.

    Those are the paper's 2 and 4 and the sizes of its presets; a file that does not
    load is left to the configuration check, which names its line.
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a whole number') from None
    try:
        sizes = load_design_space().sizes
    except (OSError, ValueError):
        sizes = ()
    if sizes and value not in sizes:
        raise argparse.ArgumentTypeError(
            f"must be one of {', '.join(map(str, sizes))} (the paper's sizes and the presets "
            f'of config/design_space.yaml), got {text}')
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be at least 1, got {text}')
    return value


def parse_args(argv: list[str]) -> argparse.Namespace:
    """Parse the command-line options of ``tune``.

    Out-of-range numbers (``--n-vars -2``, ``--max-iterations -1``, ``--move-limit
    -0.2``) are refused as argparse refuses any bad option: usage, a line naming the
    option, exit status 2.
    """
    parser = argparse.ArgumentParser(prog='tune', description=__doc__.split('\n')[0])
    parser.add_argument('--scenario', default='ride',
                        help="'ride', 'handling' or 'mixed' (both 4S4 states with a design that "
                             'names them: docs/design_space.md)')
    parser.add_argument('--n-vars', type=_design_size, default=None,
                        help='2 or 4 design variables (the paper\'s), or the size of a preset '
                             'of config/design_space.yaml (8: ride8); default 2, or the size '
                             'whose names --start gives')
    start = parser.add_mutually_exclusive_group()
    start.add_argument('--x0', type=float, nargs='*', default=[],
                       help='normalised start point (default: centre of the design space)')
    start.add_argument('--start', nargs='+', default=[], metavar='NAME=VALUE',
                       help='start point in physical units by name, e.g. dpsf=1.2 '
                            'gas_volume_l=0.35 (2 variables) or dpsf_front=... '
                            'gas_volume_front_l=... dpsf_rear=... gas_volume_rear_l=... '
                            '(4), or the names of a preset (8: dpsf_compression_front=... '
                            'anti_roll_bar_rear_knm_per_rad=...): the names and units of '
                            'config/design_space.yaml')
    parser.add_argument('--gradient', default='simplified', help="'simplified' or 'full'")
    parser.add_argument('--max-iterations', type=_number(int, 0, False, 2**32 - 1),
                        default=0,
                        help='0 = coordinator default')
    parser.add_argument('--move-limit', type=_number(float, 0.0, False),
                        default=0.0,
                        help='initial move limit, normalised (0 = coordinator default)')
    parser.add_argument('--constraint', action='append', default=[], metavar='SPEC',
                        help="extra constraint '<scenario>:<quantity><=<bound>', e.g. "
                        "'handling:f_hand<=0.8' or 'handling:roll_first_peak_deg<=4' "
                        '(repeatable)')
    parser.add_argument('--integrator', default='',
                        help="full model: 'fixed_step' or 'variable_step' (default: the "
                             "simulation's, config/vehicle.yaml)")
    parser.add_argument('--road', default='',
                        help='ride road: a road of config/road.yaml, or a .crg or .csv file '
                             "(default: config/scenarios.yaml's)")
    parser.add_argument('--repeat-road', action='store_true',
                        help='repeat a road file shorter than the run (a periodic excitation)')
    parser.add_argument('--conditions', default='', metavar='FILE',
                        help='optimise over the operating conditions of FILE (e.g. '
                        'config/conditions.yaml): speeds, payloads, roads, manoeuvre speeds '
                        '(docs/conditions.md)')
    parser.add_argument('--condition-form', default='worst', choices=('worst', 'mean'),
                        help='over the conditions: the worst case (min-max) or the '
                        'weighted mean (default: worst)')
    parser.add_argument('--evaluate', action='store_true',
                        help='one recorded full-model run of --x0 (default the centre), no '
                             'optimisation')
    parser.add_argument('--telemetry-rate', type=_number(float, 0.0, False), default=None,
                        metavar='R',
                        help="live telemetry for this goal: every simulation worker's "
                             "parameter telemetry_rate set to R (a run's telemetry paced at "
                             'its simulated time / R; 1.0: as it happened) and set back '
                             'when tune ends')
    parser.add_argument('--action', default='/coordinator/optimise', help='action name')
    parser.add_argument('--server-timeout', type=_number(float, 0.0, True),
                        default=30.0, help='seconds to wait for the coordinator')
    return parser.parse_args(argv)


def goal_road(road: str, repeat: bool = False) -> str:
    """The goal's road text for ``--road`` and ``--repeat-road``.

    A road file becomes its absolute path (the workers read it), as a YAML entry
    ``{file: ..., repeat: true}`` with ``--repeat-road``; a road name stays a name.

    Raises
    ------
    ValueError
        ``--repeat-road`` without a road file.
    """
    if not road:
        if repeat:
            raise ValueError('--repeat-road needs --road with a road file')
        return ''
    path = Path(road).expanduser()
    if path.suffix.lower() in ('.crg', '.csv') or path.is_file():
        text = json.dumps(str(path.absolute()))
        return f'{{file: {text}, repeat: true}}' if repeat else str(path.absolute())
    if repeat:
        raise ValueError(f'--repeat-road applies to a road file; {road!r} is a road of '
                         'config/road.yaml, whose entry says repeat: true')
    return road


def start_point(texts: list[str], n_vars: int | None,
                space: DesignSpace | None = None) -> list[float]:
    """The normalised start point of ``--start NAME=VALUE ...`` (physical units).

    ``n_vars`` None: the design size whose names the entries give (else 2).

    Raises
    ------
    ValueError
        A malformed entry, a name given twice, a missing or unknown name, or a value
        outside its range (config/design_space.yaml).
    """
    values: dict[str, float] = {}
    for text in texts:
        name, sep, value = text.partition('=')
        if not sep:
            raise ValueError(f'--start {text!r}: expected NAME=VALUE, e.g. dpsf=1.2')
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f'--start {text!r}: {value!r} is not a number') from None
        if name.strip() in values:
            raise ValueError(f'--start: {name.strip()} given twice')
        values[name.strip()] = number
    space = space if space is not None else load_design_space()
    return space.x_from_values(values, start_size(values, n_vars, space)).tolist()


def start_size(values: Iterable[str], n_vars: int | None, space: DesignSpace) -> int:
    """``n_vars``, or when None the size whose names ``values`` gives (default 2)."""
    if n_vars is not None:
        return int(n_vars)
    names = set(values)
    return next((n for n in space.sizes if set(space.names(n)) == names), 2)


def design_text(x: Sequence[float], space: DesignSpace | None = None) -> str:
    """A normalised design by name in physical units (``dpsf_front=1.2 ...``), or '' when
    the design space does not know its size.
    """  # noqa: D205
    space = space if space is not None else load_design_space()
    try:
        values = space.physical_values(list(x))
    except ValueError:
        return ''
    return ' '.join(f'{name}={value:.4g}' for name, value in values.items())


def format_feedback(feedback: Optimise.Feedback) -> str:
    """Format one progress line of the action's feedback.

    Phase 'calibration': the eq. 25 full-model samples done of total (the first run of
    a configuration spends them before its first iteration); phase 'calibration_fit':
    the R^2 of the eq. 25 fit per function against its threshold; phase 'pool': a
    simulation worker lost, joined, back or refused for another model, and designs sent
    to another worker; phase 'iteration': the Dynamic-Q iteration just finished.
    """
    if feedback.phase == 'calibration_fit':
        return f'calibration fit: {feedback.note}'
    if feedback.phase == 'pool':
        return f'workers: {feedback.note}'
    if feedback.phase == 'calibration':
        c = feedback.calibration
        return (f'calibration (eq. 25): {c.samples_done:3d}/{c.samples_total} full-model '
                f'samples  {c.wall_time_s:6.1f} s')
    latest = feedback.latest
    x = ', '.join(f'{v:.4f}' for v in latest.x)
    physical = design_text(latest.x)
    return (f'iteration {latest.iteration:3d}  f = {latest.f:9.5f}  '
            f'max violation = {latest.max_violation:8.4f}  move limit = {latest.move_limit:.4f}  '
            f'full runs = {latest.n_full_runs:4d}  simplified runs = '
            f'{latest.n_simplified_runs:4d}  x = [{x}]' + (f'  {physical}' if physical else ''))


def paid_full_runs(result) -> int:
    """Every full-model run the goal spent: its calibration's samples (0 when the eq. 25
    scaling came from the cache or the case has none), the optimisation's runs and the
    check of the answer (in ``n_full_runs``); what the method benchmark counts as paid
    (``method_benchmark.paid_full_runs``).  The baseline and telemetry runs of the
    report are not part of the optimisation.
    """  # noqa: D205
    return int(result.n_full_runs) + int(result.n_calibration_runs)


def format_result(result) -> str:
    """Format the action result as a report, physical units at the edge.

    The design reported is the result's: the best feasible iterate, shown as the
    optimum with its iteration, or, when no iterate was feasible, the least violating
    one under a plain "no feasible design found".  The last iterate follows when it is
    another one.
    """
    lines = [f'success: {result.success}', f'message: {result.message}']
    design = len(result.x) > 0 and len(result.history) > 0  # else failed before an iterate
    if design:
        if result.feasible:
            lines.append(f'optimum: the best feasible design, iteration '
                         f'{result.best_iteration} (max violation {result.max_violation:.4g})')
        else:
            lines.append(statement(False, result.best_iteration, result.max_violation))
        lines += [f'f: {result.f:.6f}', 'x: [' + ', '.join(f'{v:.4f}' for v in result.x) + ']',
                  'g: [' + ', '.join(f'{v:.4f}' for v in result.g) + ']',
                  *(f'constraint {i}: value {value:.6g} (gradient: {source})'
                    for i, (value, source) in enumerate(
                        zip(result.constraint_values, result.constraint_gradient_sources)))]
        last = result.history[-1]
        if last.iteration != result.best_iteration:
            lines.append(f'last iterate: iteration {last.iteration}, f = {last.f:.6f}, '
                         f'max violation {last.max_violation:.4g}')
    lines += [f'iterations: {result.iterations}', f'full-model runs: {result.n_full_runs}',
              f'simplified-model runs: {result.n_simplified_runs}',
              f'calibration full-model runs: {result.n_calibration_runs}',
              f'paid full-model runs: {paid_full_runs(result)} (calibration, optimisation '
              'and check)',
              f'wall time: {result.wall_time_s:.1f} s']
    if result.model_fingerprint:
        lines.append(f'full model: fingerprint {result.model_fingerprint}')
    if getattr(result, 'stop_test', ''):
        lines.append(f'stopped by: {result.stop_test} test')
    if getattr(result, 'check', '') or getattr(result, 'check_note', ''):
        verdict = result.check or 'not checked'
        lines.append(f'check at a tighter solver tolerance: {verdict}'
                     + (f' ({result.check_note})' if result.check_note else ''))
    if design:
        lines.append('optimum in physical units:' if result.feasible else
                     'least violating design in physical units (not feasible):')
        lines += [f'  {name}: {value:.4g}'
                  for name, value in zip(result.physical_names, result.physical_values)]
        if len(result.baseline_x):
            lines.append(f'baseline design (config/design_space.yaml): f = '
                         f'{result.baseline_f:.6f}')
            lines += [f'  {name}: {value:.4g}' for name, value in
                      zip(result.physical_names, result.baseline_physical_values)]
    lines += condition_lines(result)
    if len(result.metric_names):
        names = list(result.metric_names)
        lines.append('physical metrics:')
        title = ('this design' if not len(result.baseline_x) else
                 'optimum' if result.feasible else 'least violating')
        lines += metric_lines(dict(zip(names, result.baseline_metrics)),
                              dict(zip(names, result.metrics)), title)
    return '\n'.join(lines)


def condition_lines(result) -> list[str]:
    """Per condition: the objective and the physical metrics, baseline -> reported."""
    names = list(getattr(result, 'condition_names', []) or [])
    if not names:
        return []
    metric_names = list(result.condition_metric_names)
    k = len(metric_names)
    lines = [f'conditions: {len(names)}, worst: {result.worst_condition} '
             f'({result.n_rounds} rounds of full runs)']
    for c, name in enumerate(names):
        base_f = (f'{result.condition_baseline_f[c]:.4f} -> '
                  if len(result.condition_baseline_f) else '')
        f = f'{result.condition_f[c]:.4f}' if len(result.condition_f) else '-'
        lines.append(f'condition {name}: f {base_f}{f}')
        reported = dict(zip(metric_names, result.condition_metrics[c * k:(c + 1) * k]))
        baseline = dict(zip(metric_names, result.condition_baseline_metrics[c * k:(c + 1) * k]))
        lines += ['  ' + line for line in metric_lines(baseline, reported, 'optimum')]
    return lines


#: What rclpy's ActionClient raises (in the executor) when two servers accept one goal.
DUPLICATE_ACCEPT = 'Two goals were accepted with the same ID'


class DuplicateServerError(Exception):
    """More than one action server of the goal's action answered it."""


def count_servers(node: Node, action: str) -> int:
    """Action servers of ``action`` on the domain (the servers of its goal service)."""
    return node.count_services(action.rstrip('/') + '/_action/send_goal')


def servers_seen(node: Node, action: str, started: float, window_s: float) -> int:
    """Servers of ``action`` seen once the discovery window has passed (or two are seen).

    Parameters
    ----------
    started : float
        ``time.monotonic()`` when the node was created, s.
    window_s : float
        Discovery window from ``started``, s: a server announces itself only every few
        seconds (:data:`suspension_tuning.nodes._unique.DISCOVERY_WINDOW_S`).
    """
    while True:
        count = count_servers(node, action)
        if count > 1 or time.monotonic() - started >= window_s:
            return count
        time.sleep(POLL_S)


def not_unique(action: str, domain_id: int, count: int | None = None) -> str:
    """The error line for an action that more than one server serves."""
    many = f'{count} action servers' if count else 'more than one action server'
    return (f'error: {many} {action} on ROS domain {domain_id} (ROS_DOMAIN_ID), each '
            'would run the goal (another graph or coordinator left running?): stop the '
            'other one, or run the graphs on different ROS_DOMAIN_IDs or namespaces '
            '(--ros-args -r __ns:=/other; tune --action /other/coordinator/optimise)')


def spin(executor: MultiThreadedExecutor, duplicate: threading.Event) -> None:
    """Spin ``executor``; rclpy's error for a goal accepted twice sets ``duplicate``.

    The error comes from the executor when a second server's acceptance of the goal
    arrives; spinning goes on (the goal's cancel request still needs it).
    """
    while executor.context.ok():
        try:
            executor.spin()
            return
        except RuntimeError as error:
            if DUPLICATE_ACCEPT not in str(error):
                raise
            duplicate.set()


def wait_result(client: ActionClient, handle, poll_s: float = 1.0,
                duplicate: threading.Event | None = None) -> Optimise.Result | None:
    """The goal's result; None if the action server goes away first.

    DDS says at once when a server shuts down; a killed one drops out of the graph
    when its lease runs out (Fast DDS: 20 s by default).

    Raises
    ------
    DuplicateServerError
        ``duplicate`` was set: a second server accepted the goal too.
    """
    future = handle.get_result_async()
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    while not done.wait(poll_s):
        if duplicate is not None and duplicate.is_set():
            raise DuplicateServerError
        if not client.server_is_ready():
            return None
    if duplicate is not None and duplicate.is_set():
        raise DuplicateServerError
    return future.result().result


def cancel(handle) -> int:
    """Cancel the goal of ``handle`` (if it was accepted) after Ctrl-C; exit status 130."""
    if handle is None or not handle.accepted:
        print('interrupted before a goal was running', file=sys.stderr)
        return 130
    print('cancelling ...', file=sys.stderr)
    try:
        answer = wait_future(handle.cancel_goal_async(), 10.0)
    except (TimeoutError, KeyboardInterrupt):
        print('error: the cancel request was not answered', file=sys.stderr)
        return 130
    print('goal cancelled' if answer.goals_canceling else 'the goal had ended already',
          file=sys.stderr)
    return 130


#: The service every simulation worker offers (nodes/full_vehicle_sim.py), by type.
EVALUATE_TYPE = 'suspension_tuning_interfaces/srv/EvaluateDesign'


def simulation_workers(node: Node) -> list[str]:
    """The full names of the simulation workers ``node`` sees.

    They are the nodes serving ``<node>/evaluate`` of type EvaluateDesign.
    """
    return sorted(name.rsplit('/', 1)[0] for name, types in node.get_service_names_and_types()
                  if name.endswith('/evaluate') and EVALUATE_TYPE in types)


class LiveTelemetry:
    """``tune --telemetry-rate``: the workers' ``telemetry_rate`` set for one goal.

    Each worker seen on the graph gets the parameter through its parameter services (as
    ``ros2 param set`` does); :meth:`restore` sets every worker back to the value it
    had.  A worker that does not answer within ``timeout_s`` is named on stderr and
    left alone.
    """

    def __init__(self, node: Node, rate: float, timeout_s: float = 5.0) -> None:
        self.node, self.rate, self.timeout_s = node, float(rate), timeout_s
        self.previous: dict[str, float] = {}
        self.clients: dict[str, AsyncParameterClient] = {}

    def apply(self, discovery_s: float = 2.0) -> list[str]:
        """Set the rate on every worker seen within ``discovery_s``; returns their names."""
        deadline = time.monotonic() + discovery_s
        workers = simulation_workers(self.node)
        while time.monotonic() < deadline:  # the pool may still be being discovered
            time.sleep(POLL_S)
            workers = sorted(set(workers) | set(simulation_workers(self.node)))
        for name in workers:
            client = AsyncParameterClient(self.node, name)
            if not client.wait_for_services(timeout_sec=self.timeout_s):
                print(f'warning: {name} offers no parameter services: its telemetry stays '
                      'as it is', file=sys.stderr)
                continue
            try:
                old = wait_future(client.get_parameters(['telemetry_rate']), self.timeout_s)
                answer = wait_future(client.set_parameters(
                    [Parameter('telemetry_rate', value=self.rate)]), self.timeout_s)
            except TimeoutError:
                print(f'warning: {name} did not answer: its telemetry stays as it is',
                      file=sys.stderr)
                continue
            if not answer.results[0].successful:
                print(f'warning: {name} refused telemetry_rate {self.rate:g}: '
                      f'{answer.results[0].reason}', file=sys.stderr)
                continue
            self.clients[name] = client
            self.previous[name] = float(old.values[0].double_value)
        return sorted(self.clients)

    def restore(self) -> None:
        """Set each worker's ``telemetry_rate`` back to what it was before :meth:`apply`."""
        for name, client in self.clients.items():
            try:
                wait_future(client.set_parameters(
                    [Parameter('telemetry_rate', value=self.previous[name])]), self.timeout_s)
            except (TimeoutError, KeyboardInterrupt):
                print(f'warning: {name}: telemetry_rate not set back to '
                      f'{self.previous[name]:g}', file=sys.stderr)
        self.clients.clear()


#: How long ``tune`` looks for the action server before it says it is waiting, s.
QUIET_WAIT_S = 0.5


def wait_for_server(client: ActionClient, action: str, domain_id: int,
                    timeout_s: float) -> bool:
    """Wait for the action server, saying so when it is not there at once.

    A graph on the same domain is usually discovered within ``QUIET_WAIT_S``; otherwise
    one line on stderr names the action, the ROS domain and the time-out, and when the
    wait ends without a server, a second line says what to check.

    Returns
    -------
    bool
        True when the server was found.
    """
    if client.wait_for_server(timeout_sec=min(QUIET_WAIT_S, timeout_s)):
        return True
    print(f'waiting for the action server {action} on ROS domain {domain_id} (up to '
          f'{timeout_s:g} s; --server-timeout) ...', file=sys.stderr, flush=True)
    if client.wait_for_server(timeout_sec=max(0.0, timeout_s - QUIET_WAIT_S)):
        return True
    print(f'error: no action server {action} within {timeout_s:g} s on ROS domain '
          f'{domain_id}: is the graph running (graph, or the coordinator node) with the '
          'same ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE and namespace? (--action '
          'names another server)', file=sys.stderr)
    return False


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run suspension_tuning tune``."""
    args_list = sys.argv[1:] if argv is None else argv
    try:  # before rcl parses them: a syntax error there ends in its traceback
        check_params_files(args_list)
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    ros_args = rclpy.utilities.remove_ros_args(['tune', *args_list])[1:]
    args = parse_args(ros_args)
    try:  # checked here too, so that a typo is reported before any ROS set-up
        constraints = [ConstraintSpec.parse(text) for text in args.constraint]
        road = goal_road(args.road, args.repeat_road)
        conditions = ''
        if args.conditions:
            from suspension_tuning.conditions import CONDITION_SCENARIOS, load_conditions

            conditions = load_conditions(args.conditions).as_text()
            if args.scenario not in CONDITION_SCENARIOS or args.evaluate or road:
                raise ValueError('--conditions: a condition set is for the ride or handling '
                                 'optimisation (no --evaluate or --road: each condition names '
                                 'its road)')
            other = [c.label for c in constraints if c.scenario != args.scenario]
            if other:
                raise ValueError(f'--constraint {other[0]}: with --conditions a constraint '
                                 f'bounds a {args.scenario} quantity, which then holds in every '
                                 f"condition (e.g. '{args.scenario}:"
                                 f"{OBJECTIVE_NAMES[args.scenario]}<=0.5')")
        x0 = start_point(args.start, args.n_vars) if args.start else args.x0
        if args.n_vars is None:
            args.n_vars = (start_size([t.partition('=')[0].strip() for t in args.start], None,
                                      load_design_space()) if args.start else 2)
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    # Without rclpy's signal handler: it would shut the context down on Ctrl-C, and the
    # cancel request could no longer be sent.  Ctrl-C raises KeyboardInterrupt here.
    try:
        window_s = discovery_window_s()
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    rclpy.init(args=['tune', *args_list], signal_handler_options=SignalHandlerOptions.NO)
    node = Node('tune')
    started = time.monotonic()
    domain_id = node.context.get_domain_id()
    client = ActionClient(node, Optimise, args.action)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    duplicate = threading.Event()
    spinner = threading.Thread(target=spin, args=(executor, duplicate), daemon=True)
    spinner.start()
    sending, handle = None, None
    live = None if args.telemetry_rate is None else LiveTelemetry(node, args.telemetry_rate)
    try:
        if not wait_for_server(client, args.action, domain_id, args.server_timeout):
            return 2
        count = servers_seen(node, args.action, started, window_s) if window_s > 0 else 1
        if count > 1:
            print(not_unique(args.action, domain_id, count), file=sys.stderr)
            return 2
        if live is not None:
            workers = live.apply()
            print(f"live telemetry at {live.rate:g} x simulated time from "
                  f"{', '.join(workers) or 'no simulation worker'}", file=sys.stderr,
                  flush=True)
        goal = Optimise.Goal(scenario=args.scenario, n_vars=args.n_vars, x0=x0,
                             gradient_source='evaluate' if args.evaluate else args.gradient,
                             max_iterations=args.max_iterations, move_limit=args.move_limit,
                             constraints=[Constraint(scenario=c.scenario, quantity=c.quantity,
                                                     upper_bound=c.upper_bound)
                                          for c in constraints],
                             integrator=args.integrator, road=road, conditions=conditions,
                             condition_form=args.condition_form if conditions else '')
        sending = client.send_goal_async(
            goal, feedback_callback=lambda fb: print(format_feedback(fb.feedback),
                                                     flush=True))
        try:
            handle = wait_future(sending, args.server_timeout)
        except TimeoutError:
            print(f'error: the goal was not answered within {args.server_timeout} s (a '
                  f'stale server of {args.action} on this ROS domain?)', file=sys.stderr)
            return 1
        if handle is None or not handle.accepted:
            print('error: goal rejected', file=sys.stderr)
            return 2
        if duplicate.is_set() or count_servers(node, args.action) > 1:
            raise DuplicateServerError  # (rclpy logs a second acceptance, or raises)
        result = wait_result(client, handle, duplicate=duplicate)
        if result is None:
            print(f'error: the action server {args.action} went away before the result',
                  file=sys.stderr)
            return 1
        print(format_result(result), flush=True)
        return 0 if result.success else 1
    except DuplicateServerError:
        count = count_servers(node, args.action)
        print(not_unique(args.action, domain_id, count if count > 1 else None),
              file=sys.stderr)
        try:  # every server that accepted the goal gets the cancel request
            wait_future(handle.cancel_goal_async(), 10.0)
            print('the goal was cancelled', file=sys.stderr)
        except (TimeoutError, KeyboardInterrupt):
            print('error: the cancel request was not answered', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if handle is None and sending is not None:  # the goal may be accepted still
            try:
                handle = wait_future(sending, 5.0)
            except (TimeoutError, KeyboardInterrupt):
                pass
        return cancel(handle)
    finally:
        if live is not None:
            live.restore()
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        client.destroy()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
