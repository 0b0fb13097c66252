"""Ride optimisations through the graph on road files given with the goal (tune --road).

The sett paving of config/road.yaml, written out as an OpenCRG file by PyOpenCRG and as
a CSV file, drives the workers' full model and the gradient evaluator's pitch-plane
model; the bag's run configuration records the file and its SHA-256.
"""

from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros

SAMPLES = 6  # eq. 25 samples: fewer than the paper's 30 to keep the test short
TRACK_M = 1.486  # Defender 110 track, config/road.yaml


@pytest.fixture(scope='module')
def sett_files(tmp_path_factory):
    """The configured sett paving (450 m, the ride run's road) as .crg and .csv files."""
    from suspension_tuning.vehicle import road as road_mod
    from suspension_tuning.vehicle.road_files import write_crg, write_csv

    folder = tmp_path_factory.mktemp('roads')
    profile = road_mod.synthesise_tracks(road_mod.load_road_spec('belgian_paving'))
    return {'crg': str(write_crg(profile, folder / 'sett.crg', TRACK_M)),
            'csv': str(write_csv(profile, folder / 'sett.csv'))}


def test_ride_optimisation_through_the_graph_on_crg_and_csv_road_files(
        ros_context, sett_files, tmp_path):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.graph import SpinningGraph, build_nodes
    from suspension_tuning.inspect_bag import summary
    from suspension_tuning.paths import config_dir, file_sha256
    from suspension_tuning.tune import goal_road

    nodes = build_nodes(workers=1, record=True, context=ros_context, overrides={
        'gradient_evaluator': [Parameter('calibration_dir', value=str(tmp_path / 'cal'))],
        'coordinator': [Parameter('calibration_samples', value=SAMPLES),
                        Parameter('final_telemetry', value=False)],
        'recorder': [Parameter('output_dir', value=str(tmp_path / 'bags')),
                     Parameter('discovery_period_s', value=0.1)]})
    client_node = Node('road_graph_client', context=ros_context)
    graph = SpinningGraph(nodes, [client_node])
    results = {}
    try:
        client = ActionClient(client_node, Optimise, '/coordinator/optimise')
        assert client.wait_for_server(timeout_sec=10.0)
        # one iteration each: the road reaches the full model and the simplified one
        for kind, gradient in (('crg', 'simplified'), ('csv', 'full')):
            handle = wait(client.send_goal_async(Optimise.Goal(
                scenario='ride', n_vars=2, gradient_source=gradient, max_iterations=1,
                road=sett_files[kind])), 30.0)
            results[kind] = wait(handle.get_result_async(), 300.0).result
        # one recorded run of the centre (tune --evaluate) on the CSV road
        handle = wait(client.send_goal_async(Optimise.Goal(
            scenario='ride', n_vars=2, gradient_source='evaluate', road=sett_files['csv'])),
            30.0)
        evaluated = wait(handle.get_result_async(), 120.0).result
        bad = wait(client.send_goal_async(Optimise.Goal(
            scenario='ride', n_vars=2, gradient_source='full', max_iterations=1,
            road=str(tmp_path / 'no_such_road.crg'))), 30.0)
        refused = wait(bad.get_result_async(), 60.0).result
        # the ASAM belgian block cut after 500 of its 1001 data rows, repetition asked
        # (tune --road cut.crg --repeat-road): refused, naming the rows
        block = config_dir() / 'roads' / 'belgian_block.crg'
        data = block.read_bytes()
        start = data.index(b'\n', data.index(b'$$$$')) + 1
        (tmp_path / 'cut.crg').write_bytes(data[:start + 500 * ((len(data) - start) // 1001)])
        cut = wait(client.send_goal_async(Optimise.Goal(
            scenario='ride', n_vars=2, gradient_source='full', max_iterations=1,
            road=goal_road(str(tmp_path / 'cut.crg'), repeat=True))), 30.0)
        truncated = wait(cut.get_result_async(), 60.0).result
    finally:
        graph.shutdown()  # the recorder closes the run's bag
    for result in results.values():
        assert len(result.history) >= 1 and np.isfinite(result.history[0].f), result.message
        assert result.n_full_runs >= 1
    # The same road in both files (CRG in doubles, CSV to 9 digits): the same first
    # iterate's objective, to the CSV's rounding.
    assert results['csv'].history[0].f == pytest.approx(results['crg'].history[0].f, rel=1e-6)
    assert results['crg'].n_calibration_runs == SAMPLES
    assert not refused.success and 'no_such_road.crg: no such file' in refused.message
    assert not truncated.success and truncated.n_full_runs == 0
    assert ('cut.crg: the header (reference_line_start_u 730 to reference_line_end_u 740 m, '
            'reference_line_increment 0.01 m) gives 1001 data rows, 10 m; the data has 500 '
            'rows') in truncated.message
    # the evaluation: one full run at the centre, the optimisation's first iterate
    assert evaluated.success and evaluated.n_full_runs == 1 and len(evaluated.history) == 1
    assert evaluated.f == results['csv'].history[0].f
    bags = sorted(Path(tmp_path / 'bags').iterdir())
    assert len(bags) == 3, bags  # the refused goal never started a run
    for bag, kind in zip(bags, ('crg', 'csv', 'csv')):
        road = summary(bag)['run_config']['ride_road']
        assert road['source'] == 'goal' and road['file'] == sett_files[kind]
        assert road['sha256'] == file_sha256(sett_files[kind])
