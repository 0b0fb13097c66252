"""A user's FMU is never optimised with another model's numbers.

The FMU here is one the tool has never seen (``HalfCarRide``, built by pythonfmu in the
test session): its own names, gas volumes in cm^3, one road input per axle, no declared
units.  Each test shows one of the ways a wrong answer could have come out silently:
a calibration cached for another model, workers that run different vehicles, a
parameter file that misses a lone worker, a mapping slip, a simplified model that does
not fit.
"""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter
from test_fmu_worker import fmu_parameters, write_mapping

from suspension_tuning.fmu import FmuModel, MappingError
from suspension_tuning.fmu.mapping import parse_mapping
from suspension_tuning.model_identity import builtin_fingerprint, fingerprint
from suspension_tuning.testing import call_service, wait_for_future

sys.path.insert(0, os.path.join(os.path.dirname(__file__), 'fixtures', 'fmu'))
import plate_ride  # noqa: E402  (the test FMUs' model)

SAMPLES = 12  # eq. 25 samples: fewer than the paper's 30 to keep the tests short
MASS_KG = plate_ride.MASS_KG  # sprung mass of the FMU's default vehicle, kg
#: The whole vehicle as the tyres carry it: sprung mass plus 4 x 60 kg unsprung
#: (plate_ride.UNSPRUNG_KG).
VEHICLE_KG = MASS_KG + 4 * plate_ride.UNSPRUNG_KG
CORNERS = ('fl', 'fr', 'rl', 'rr')


def half_car_mapping(volume_unit='cm3', damper_law=0, body_mass_kg=MASS_KG, **ride):
    """The mapping a new user writes for HalfCarRide, following docs/fmu.md."""
    body = {'stop_time_s': 4.0, 'step_size_s': 0.002, 'settle_s': 2.0, 'speed_kmh': 50.0,
            'parameters': {'bodyMass': body_mass_kg, 'damperLaw': damper_law},
            'road': {'wheelbase_m': plate_ride.A_M + plate_ride.B_M,
                     'inputs': {'front': 'roadFront', 'rear': 'roadRear'}},
            'outputs': {'acc_driver': 'accDriver', 'acc_passenger': 'accRear',
                        'tyre_fz': {c: f'tyre{c.upper()}' for c in CORNERS}}}
    body.update(ride)
    return {'vehicle_mass_kg': VEHICLE_KG,
            'design': {'dpsf_front': 'damperGainF', 'dpsf_rear': 'damperGainR',
                       'gas_volume_front': {'name': 'accuVolumeF', 'unit': volume_unit},
                       'gas_volume_rear': {'name': 'accuVolumeR', 'unit': volume_unit}},
            'scenarios': {'ride': body}}


def write(tmp_path, mapping, name='half_car.yaml'):
    return write_mapping(tmp_path, mapping, name)


class Graph:
    """The tuning graph with FMU workers, a client node, spinning (a context manager)."""

    def __init__(self, context, workers, tmp_path, record=False):
        from rclpy.node import Node

        from suspension_tuning.graph import SpinningGraph, build_nodes

        names = ['full_vehicle_sim'] if len(workers) == 1 else [
            f'sim_{i}' for i in range(len(workers))]
        overrides = {name: params for name, params in zip(names, workers)}
        overrides['gradient_evaluator'] = [Parameter('calibration_dir',
                                                     value=str(tmp_path / 'cal'))]
        overrides['coordinator'] = [Parameter('calibration_samples', value=SAMPLES)]
        if record:
            overrides['recorder'] = [Parameter('output_dir', value=str(tmp_path / 'bags')),
                                     Parameter('discovery_period_s', value=0.1),
                                     Parameter('post_run_s', value=0.5)]
        self.nodes = build_nodes(workers=len(workers), record=record, context=context,
                                 overrides=overrides)
        self.client = Node('identity_client', context=context)
        self.graph = SpinningGraph(self.nodes, [self.client])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.graph.shutdown()

    def calibrate(self, **fields):
        from suspension_tuning_interfaces.srv import Calibrate

        client = self.client.create_client(Calibrate, '/gradient_evaluator/calibrate')
        return call_service(client, Calibrate.Request(scenario='ride', n_vars=2,
                                                      n_samples=SAMPLES, **fields), 120.0)

    def optimise(self, **goal):
        from rclpy.action import ActionClient
        from suspension_tuning_interfaces.action import Optimise

        feedback = []
        client = ActionClient(self.client, Optimise, '/coordinator/optimise')
        assert client.wait_for_server(timeout_sec=10.0)
        handle = wait_for_future(client.send_goal_async(
            Optimise.Goal(scenario='ride', n_vars=2, **goal),
            feedback_callback=lambda msg: feedback.append(msg.feedback)), 30.0)
        return wait_for_future(handle.get_result_async(), 300.0).result, feedback


def test_fmu_calibration_is_cached_per_model_and_never_reused_for_another(
        ros_context, fmus, tmp_path):
    """Point 1: the same calibration_dir serves two vehicles; each gets its own samples.

    The second FMU vehicle differs only in its body mass (2000 -> 2200 kg, a fixed
    parameter of the mapping): its calibration must cost its own 12 full runs, and the
    first vehicle's, asked again, comes from the cache.
    """
    light = write(tmp_path, half_car_mapping(), 'light.yaml')
    heavy = write(tmp_path, half_car_mapping(body_mass_kg=MASS_KG + 200.0), 'heavy.yaml')
    answers = []
    for mapping in (light, heavy, light):
        with Graph(ros_context, [fmu_parameters(fmus['half_car'], mapping)], tmp_path) as g:
            answers.append(g.calibrate())
    assert all(a.success for a in answers), [a.error for a in answers]
    assert [a.from_cache for a in answers] == [False, False, True]
    assert [a.n_full_runs for a in answers] == [SAMPLES, SAMPLES, 0]
    fps = [a.model_fingerprint for a in answers]
    assert fps[0] == fps[2] != fps[1]
    assert builtin_fingerprint() not in fps
    # The cache holds one file per model, named by its fingerprint.
    files = sorted(p.name for p in (tmp_path / 'cal').iterdir())
    assert len(files) == 2 and all(any(fp in f for f in files) for fp in fps), files
    # The two vehicles' full-model ranges differ: a shared cache would have mixed them.
    assert answers[0].full_max[0] != answers[1].full_max[0]


def test_fmu_workers_of_different_vehicles_are_refused_with_their_fingerprints(
        ros_context, fmus, tmp_path):
    """Point 2: two workers, 2000 and 2200 kg of body mass: no goal, no calibration."""
    light = write(tmp_path, half_car_mapping(), 'light.yaml')
    heavy = write(tmp_path, half_car_mapping(body_mass_kg=MASS_KG + 200.0), 'heavy.yaml')
    with Graph(ros_context, [fmu_parameters(fmus['half_car'], light),
                             fmu_parameters(fmus['half_car'], heavy)], tmp_path) as g:
        result, _ = g.optimise(gradient_source='full')
        calibration = g.calibrate()
        workers = {n.get_name(): n for n in g.nodes if n.get_name().startswith('sim_')}
        fps = {name: node.model_fingerprint for name, node in workers.items()}
        runs = sum(node.runs for node in workers.values())
    assert fps['sim_0'] != fps['sim_1']
    assert not result.success and result.n_full_runs == 0 and runs == 0
    for text in (result.message, calibration.error):
        assert 'run different models' in text
        assert f'/sim_0: {fps["sim_0"]}' in text and f'/sim_1: {fps["sim_1"]}' in text
    assert not calibration.success


def test_fmu_calibration_refuses_a_caller_of_another_model(ros_context, fmus, tmp_path):
    """The coordinator's fingerprint travels with its calibration request."""
    mapping = write(tmp_path, half_car_mapping())
    with Graph(ros_context, [fmu_parameters(fmus['half_car'], mapping)], tmp_path) as g:
        other = g.calibrate(model_fingerprint=builtin_fingerprint())
    assert not other.success
    assert f'the caller runs model {builtin_fingerprint()}' in other.error


def test_fmu_parameter_file_for_every_node_reaches_a_lone_worker_which_says_its_model(
        fmus, tmp_path, ros_domain_id):
    """Point 3: ``/**:`` (docs/fmu.md) reaches ``full_vehicle_sim`` of ``graph --workers 1``.

    The worker's first log lines name the FMU it runs and its fingerprint.
    """
    mapping = write(tmp_path, half_car_mapping())
    params = tmp_path / 'fmu_workers.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'model': 'fmu', 'fmu_path': fmus['half_car'], 'fmu_mapping': mapping}}}))
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
           'ROS_DOMAIN_ID': str(ros_domain_id)}
    graph = subprocess.Popen(
        [sys.executable, '-m', 'suspension_tuning.graph', '--workers', '1', '--no-record',
         '--ros-args', '--params-file', str(params)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    deadline = time.monotonic() + 60.0
    try:
        while time.monotonic() < deadline:
            line = graph.stdout.readline()
            if not line:
                break
            lines.append(line)
            if 'plausibility check' in line:
                break
    finally:
        graph.send_signal(signal.SIGINT)
        rest, _ = graph.communicate(timeout=30)
    text = ''.join(lines) + rest
    with FmuModel(fmus['half_car'], mapping) as fmu:
        fp = fmu.description()['fingerprint']
    assert '[full_vehicle_sim]: model fmu HalfCarRide.fmu' in text, text
    assert f'fingerprint {fp}' in text
    assert "FMU input 'roadFront' gets the mean of the FL/FR tracks" in text


def test_fmu_mapping_lists_every_problem_at_once():
    """Point 4: four slips in one file, four lines in one error."""
    mapping = half_car_mapping()
    ride = mapping['scenarios']['ride']
    ride['step_size_s'] = -0.002                           # not positive
    ride['outputs']['acc_passenger'] = 'accDriver'         # the driver's seat twice
    ride['outputs']['tyre_fz']['unit'] = 'm/s2'            # not a force
    mapping['design']['gas_volume_rear']['unit'] = 'gallon'  # unknown
    with pytest.raises(MappingError) as error:
        parse_mapping(yaml.safe_dump(mapping))
    text = str(error.value)
    assert '4 problem(s)' in text
    assert 'scenarios.ride.step_size_s: must be > 0' in text
    assert "FMU variable 'accDriver' is mapped to 2 outputs" in text
    assert "scenarios.ride.outputs.tyre_fz.unit: 'm/s2' is not a unit of force" in text
    assert "design.gas_volume_rear.unit: 'gallon'" in text


def test_fmu_mapping_refuses_a_key_given_twice():
    """YAML keeps the last of two equal keys; the mapping refuses them instead."""
    text = re.sub(r'( *)acc_driver: accDriver\n', r'\g<0>\1acc_driver: accRear\n',
                  yaml.safe_dump(half_car_mapping()))
    with pytest.raises(MappingError, match="key 'acc_driver' given twice"):
        parse_mapping(text)


def test_fmu_per_axle_road_input_gets_the_mean_of_the_two_tracks(fmus):
    """Point 4: ``front``/``rear`` inputs carry the mean of the left and right tracks."""
    with FmuModel(fmus['half_car'], parse_mapping(yaml.safe_dump(half_car_mapping()))) as fmu:
        sm = fmu.mapping.scenarios['ride']
        t = np.linspace(0.0, 4.0, 9)
        fed = fmu._road_inputs(sm, t)
        road = fmu.roads['ride']
        x_rear = 0.5 + 50.0 / 3.6 * t  # start_rear_axle_at_m default, speed_kmh
        for column, x in enumerate((x_rear + sm.road.wheelbase_m, x_rear)):
            left, right = (road.elevation(x, track)[0] for track in (0, 1))
            np.testing.assert_allclose(fed[:, column], 0.5 * (left + right), rtol=0,
                                       atol=1e-15)
        assert not np.allclose(left, right)  # the tracks differ: the mean is a real mean
        assert any("'roadRear' gets the mean of the RL/RR tracks" in n for n in fmu.notes)


def test_fmu_plausibility_check_warns_with_numbers_on_a_wrong_volume_unit(fmus):
    """Point 4: ``unit: L`` on a parameter in cm^3 (the FMU declares no unit).

    The FMU starts its accumulators at 300 cm^3; the design's 0.1-0.6 sent as litres
    is a factor 500 below it.  The right unit draws no warning, and the tyres carry
    the vehicle (2240 kg) within 1 %.
    """
    with FmuModel(fmus['half_car'], parse_mapping(yaml.safe_dump(
            half_car_mapping(volume_unit='L')))) as fmu:
        assert any('gas_volume_front' in u and 'taken as L' in u
                   for u in fmu.undeclared_units)
        _, warnings = fmu.plausibility()
    assert any("the design sends 0.1-0.6 (L) to 'accuVolumeF', whose start value in the "
               'FMU is 300: a factor 500 apart' in w for w in warnings), warnings
    with FmuModel(fmus['half_car'], parse_mapping(yaml.safe_dump(half_car_mapping()))) as fmu:
        numbers, warnings = fmu.plausibility()
    assert warnings == []
    assert numbers['ride']['static_load_kg'] == pytest.approx(VEHICLE_KG, rel=0.01)
    # A wrong force unit (kN for an FMU in N) reads the tyres 1000 times too heavy.
    with FmuModel(fmus['half_car'], parse_mapping(yaml.safe_dump(half_car_mapping(
            outputs={'acc_driver': 'accDriver', 'acc_passenger': 'accRear',
                     'tyre_fz': {**{c: f'tyre{c.upper()}' for c in CORNERS},
                                 'unit': 'kN'}})))) as fmu:
        _, warnings = fmu.plausibility()
    assert any(re.search(r'the tyres carry 22\d{5} kg on average, the mapping says '
                         r'vehicle_mass_kg 2240', w) for w in warnings), warnings


def test_fmu_goal_fails_with_advice_when_the_simplified_model_does_not_fit(
        ros_context, fmus, tmp_path):
    """Point 5: a damper gain that softens as it grows (an orifice opening).

    The simplified ride model's damping grows with dpsf, so eq. 25 maps it onto this
    FMU with R^2 below 0 (-0.48 over the 12 samples): the goal stops after the
    calibration, says why and what to do, and the bag keeps the verdict.
    """
    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.inspect_bag import summary
    from suspension_tuning.testing import wait_for_bag

    mapping = write(tmp_path, half_car_mapping(damper_law=1))
    with Graph(ros_context, [fmu_parameters(fmus['half_car'], mapping)], tmp_path,
               record=True) as g:
        result, feedback = g.optimise(gradient_source='simplified')
        bag = wait_for_bag(tmp_path / 'bags')  # closed by the recorder, the run complete
    assert not result.success
    assert result.n_calibration_runs == SAMPLES and result.n_full_runs == 0
    assert 'does not fit this full model' in result.message
    assert '--gradient full' in result.message
    assert 'below the threshold 0.5' in result.message
    notes = [f.note for f in feedback if f.phase == 'calibration_fit']
    assert len(notes) == 1 and notes[0].endswith('threshold 0.5: poor: f'), notes
    assert summary(bag)['run_config']['model_fingerprint'] == result.model_fingerprint
    contents = read_messages(bag, ['/coordinator/optimise/_action/feedback', '/rosout'])
    recorded = [decode(contents, m) for m in contents.messages]
    assert any(getattr(getattr(m, 'feedback', None), 'note', '') == notes[0]
               for m in recorded)
    assert any('does not fit this full model' in getattr(m, 'msg', '') for m in recorded)


def test_fingerprint_ignores_comments_but_not_a_changed_parameter(fmus, tmp_path):
    """The fingerprint is the model, not the file's layout."""
    mapping = half_car_mapping()
    plain = tmp_path / 'plain.yaml'
    plain.write_text(yaml.safe_dump(mapping))
    commented = tmp_path / 'commented.yaml'
    commented.write_text('# my vehicle\n' + yaml.safe_dump(mapping, indent=4))
    heavier = tmp_path / 'heavier.yaml'
    heavier.write_text(yaml.safe_dump(half_car_mapping(body_mass_kg=MASS_KG + 1.0)))
    prints = []
    for path in (plain, commented, heavier):
        with FmuModel(fmus['half_car'], path) as fmu:
            prints.append(fingerprint(fmu.description()))
    assert prints[0] == prints[1] != prints[2]
    assert Path(fmus['half_car']).exists()
