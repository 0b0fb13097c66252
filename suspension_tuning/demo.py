"""``make demo``: the paper's method end to end on the ROS 2 graph, recorded.

Starts the graph (simulation worker, gradient evaluator, valve controller, coordinator,
recorder) in this process on loopback DDS, then runs the 4-variable ride optimisation
and the 4-variable handling optimisation with simplified-model gradients (the eq. 25
calibration of each case's default: none on the ride, whose gradients the run's
first-order correction maps onto the full model, 4 full-model samples on handling,
cached across runs).  Prints the
progress of each iteration, the best feasible design seen (or says plainly that none
was feasible) in physical units beside the baseline vehicle, with the physical metrics
of both (seat W_b RMS in m/s^2, first roll peak in deg, roll-rate RMS in deg/s, tyre
lift-off time in %), where the bags are and the plots written from them, and the wall
time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
if os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] != 'LOCALHOST':
    sys.exit('demo: ROS_AUTOMATIC_DISCOVERY_RANGE must be LOCALHOST (DDS stays on loopback)')
os.environ.setdefault('ROS_DOMAIN_ID', '42')


def optimiser_stopped(message: str) -> bool:
    """True if a goal's result message ends in one of Dynamic-Q's own stops.

    An optimisation that converged or stopped on its own criteria (iteration limit, move
    limit; possibly at an infeasible point) is a result the demo reports; anything else
    (a bad goal, a failed evaluation, ROS shutting down) is a failure of the demo.  The
    message may start with the sentence on the reported design
    (:func:`suspension_tuning.reported_design.result_message`).
    """
    from suspension_tuning.optim.dynamic_q import STATUS_MESSAGES
    from suspension_tuning.reported_design import stop_message

    own = {STATUS_MESSAGES[k] for k in STATUS_MESSAGES if k != 99}
    return stop_message(message).removesuffix(' (last iterate infeasible)') in own


def report(scenario: str, result) -> str:
    """The reported design (the best feasible one seen) beside the baseline, physical units.

    The baseline is the result's (config/design_space.yaml), with the physical metrics
    of both designs.  When no iterate was feasible the report says so plainly and shows
    the least violating design in the column of the optimum.
    """
    from suspension_tuning.physical_metrics import metric_lines
    from suspension_tuning.tune import paid_full_runs

    base = dict(zip(result.physical_names, result.baseline_physical_values))
    baseline_f = result.baseline_f if len(result.baseline_x) else float('nan')
    column, w = ('optimum', 10) if result.feasible else ('least violating', 17)
    lines = [f'{scenario}: {result.message}',  # which iteration, or that none was feasible
             f'  {"setting":<22}{"baseline":>10}{column:>{w}}']
    for name, value in zip(result.physical_names, result.physical_values):
        lines.append(f'  {name:<22}{base.get(name, float("nan")):>10.3f}{value:>{w}.3f}')
    gain = 100.0 * (baseline_f - result.f) / abs(baseline_f) if baseline_f else float('nan')
    lines.append(f'  {"objective f":<22}{baseline_f:>10.4f}{result.f:>{w}.4f}'
                 f'   (improvement {gain:.1f} %)')
    lines.append(f'  largest constraint g  {max(result.g, default=0.0):.3f} (<= 0 feasible, '
                 f'eq. 11)')
    if result.stop_test:
        lines.append(f'  stopped by the {result.stop_test} test')
    if result.check or result.check_note:
        lines.append(f'  check at a tighter solver tolerance: {result.check or "not checked"}'
                     + (f' ({result.check_note})' if result.check_note else ''))
    names = list(result.metric_names)
    lines += metric_lines(dict(zip(names, result.baseline_metrics)),
                          dict(zip(names, result.metrics)), column)
    lines.append(f'  iterations {result.iterations}, full-model runs {result.n_full_runs}, '
                 f'simplified runs {result.n_simplified_runs}, calibration runs '
                 f'{result.n_calibration_runs}, paid full-model runs '
                 f'{paid_full_runs(result)}, {result.wall_time_s:.1f} s')
    return '\n'.join(lines)


#: Seconds the demo waits for a run's bag while the recorder records nothing: a
#: recorder that stalls, not one still draining the run's telemetry burst (8 topics x
#: 3750 messages for a ride run, in this process beside the graph: 8 s at a load
#: average of 8 on 2 cores), which may take longer on a busier machine.
RECORDER_STALL_S = 30.0


def wait_for_bag(recorder, closed_before: int, stall_s: float = RECORDER_STALL_S) -> None:
    """Wait until the recorder closes the run's bag.

    The recorder closes it ``post_run_s`` after the last message of the run it
    processes (at most its ``post_run_max_s`` after the result), so the wait lasts as
    long as the recorder still records messages.

    Raises
    ------
    TimeoutError
        The recorder recorded nothing for ``stall_s`` and left the bag open.
    """
    seen, last_progress = recorder.received, time.monotonic()
    while len(recorder.session.closed_bags) == closed_before:
        if recorder.received != seen:
            seen, last_progress = recorder.received, time.monotonic()
        elif time.monotonic() - last_progress > stall_s:
            raise TimeoutError(f"the recorder did not close the run's bag (nothing "
                               f'recorded for {stall_s:g} s)')
        time.sleep(0.1)


def main(argv: list[str] | None = None) -> int:
    """Run the demo; return the exit status."""
    parser = argparse.ArgumentParser(prog='demo', description=__doc__.split('\n')[0])
    parser.add_argument('--bags', default='bags', help='folder for the recorded bags')
    parser.add_argument('--n-vars', type=int, default=4, help='2 or 4 design variables')
    parser.add_argument('--scenarios', nargs='+', default=['ride', 'handling'])
    args = parser.parse_args(argv)
    start = time.perf_counter()

    import rclpy
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.config_check import ConfigError, check_config
    from suspension_tuning.graph import SpinningGraph, build_nodes
    from suspension_tuning.inspect_bag import write_plots
    from suspension_tuning.nodes._spin import wait_future
    from suspension_tuning.tune import format_feedback
    try:  # the configuration first: one line, not a traceback from a node
        check_config(builtin_model=True)
    except ConfigError as error:
        print(f'demo: not started: {error}', file=sys.stderr)
        return 2
    rclpy.init()
    bags = Path(args.bags).resolve()
    nodes = build_nodes(workers=1, record=True, overrides={
        'recorder': [Parameter('output_dir', value=str(bags))]})
    recorder = nodes[-1]
    client_node = Node('demo')
    graph = SpinningGraph(nodes, [client_node])
    status = 0
    try:
        action = ActionClient(client_node, Optimise, '/coordinator/optimise')
        if not action.wait_for_server(timeout_sec=30):
            print('demo: the graph did not come up', file=sys.stderr)
            return 1
        print(f'graph up: {", ".join(n.get_name() for n in nodes)} '
              f'(ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}, loopback only)', flush=True)
        outputs = []
        for scenario in args.scenarios:
            print(f'\n== {scenario}: {args.n_vars} variables, simplified-model gradients',
                  flush=True)
            closed_before = len(recorder.session.closed_bags)
            handle = wait_future(action.send_goal_async(
                Optimise.Goal(scenario=scenario, n_vars=args.n_vars,
                              gradient_source='simplified'),
                feedback_callback=lambda fb: print('  ' + format_feedback(fb.feedback),
                                                   flush=True)), 60)
            result = wait_future(handle.get_result_async()).result
            # a run that stops on the iteration limit (the ride problem on the Belgian
            # paving, whose tyre-hop constraints the simplified models place only
            # roughly) is reported, not an error of the demo
            status |= 0 if result.success or optimiser_stopped(result.message) else 1
            wait_for_bag(recorder, closed_before)
            bag = recorder.session.closed_bags[-1]
            plots = write_plots(bag, bag / 'plots')
            outputs.append((scenario, result, bag, plots))
        print()
        for scenario, result, bag, plots in outputs:
            print(report(scenario, result))
            print(f'  bag: {bag}')
            print(f'  plots: {", ".join(str(p) for p in plots)}')
            print(f'  inspect: .venv/bin/inspect_bag {bag}')
    except KeyboardInterrupt:  # Ctrl-C: the recorder still closes the run's bag below
        print('\ndemo: interrupted', file=sys.stderr)
        status = 130
    finally:
        graph.shutdown(interrupted=status == 130)
        rclpy.try_shutdown()
    print(f'\ndemo_wall_time_s: {time.perf_counter() - start:.1f}')
    return status


if __name__ == '__main__':
    sys.exit(main())
