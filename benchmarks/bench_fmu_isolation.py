"""FMU throughput: designs per second in child processes and in the worker's own process.

Prints ``name: value`` lines.  The FMU is the tests' PlateRide (test/fixtures/fmu: the
seven-DOF ride model in Python behind pythonfmu, road under each wheel as inputs),
built here; each design is a 4 s ride at 500 Hz (2,000 communication steps) on the
Belgian paving, sent in batches of 6 designs (a calibration chunk, config/graph.yaml).
The isolated figure includes everything the worker pays per design: the task and the
outputs through a pipe, and the child's FMI logger messages.  The first batch of each
is a warm-up (the fork server's imports, the first instance of the FMU).  The
2-process figure runs two designs of a batch at a time (``fmu_processes: 2``).
"""

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from suspension_tuning.fmu import FmuModel, parse_mapping
from suspension_tuning.fmu.isolated import IsolatedFmuModel

FIXTURES = Path(__file__).resolve().parent.parent / 'test' / 'fixtures' / 'fmu'
BATCH = 6  # designs per request: config/graph.yaml's calibration_chunk
BATCHES = 8  # timed requests per mode: 48 designs
CORNERS = ('fl', 'fr', 'rl', 'rr')


def mapping():
    """PlateRide's mapping: a 4 s ride (W_b settles in 0.56 s, comfort.py)."""
    sys.path.insert(0, str(FIXTURES))
    import plate_ride

    design = {'dpsf_front': 'dpsfFront', 'dpsf_rear': 'dpsfRear',
              'gas_volume_front': {'name': 'gasVolumeFront', 'unit': 'L'},
              'gas_volume_rear': {'name': 'gasVolumeRear', 'unit': 'L'}}
    ride = {'stop_time_s': 4.0, 'step_size_s': 0.002, 'settle_s': 2.0, 'speed_kmh': 50.0,
            'road': {'wheelbase_m': plate_ride.A_M + plate_ride.B_M,
                     'start_rear_axle_at_m': 0.5,
                     'inputs': {c: f'zRoad{c.upper()}' for c in CORNERS}},
            'outputs': {'acc_driver': 'seatDriverAz', 'acc_passenger': 'seatPassengerAz',
                        'tyre_fz': {**{c: f'Fz{c.upper()}' for c in CORNERS}, 'unit': 'kN'}}}
    return parse_mapping(yaml.safe_dump({'design': design, 'scenarios': {'ride': ride}}))


def main() -> None:
    from pythonfmu.builder import FmuBuilder

    designs = np.random.default_rng(30).uniform(0.0, 1.0, (BATCH * BATCHES, 2))
    with tempfile.TemporaryDirectory() as tmp:
        fmu_path = FmuBuilder.build_FMU(FIXTURES / 'PlateRide.py', dest=tmp,
                                        project_files=[FIXTURES / 'plate_ride.py'])
        ride = mapping()
        models = {'in_process': FmuModel(fmu_path, ride),
                  'isolated': IsolatedFmuModel(fmu_path, ride),
                  'isolated_2_processes': IsolatedFmuModel(fmu_path, ride, processes=2)}
        seconds = dict.fromkeys(models, 0.0)
        try:
            for fmu in models.values():
                fmu.evaluate('ride', designs[:BATCH])  # warm-up
            # The modes take turns batch by batch: a machine shared with other work
            # slows them alike.
            for batch in np.split(designs, BATCHES):
                for name, fmu in models.items():
                    start = time.perf_counter()
                    fmu.evaluate('ride', batch)
                    seconds[name] += time.perf_counter() - start
        finally:
            for fmu in models.values():
                fmu.close()
    rate = {name: len(designs) / s for name, s in seconds.items()}
    print(f'cores: {len(os.sched_getaffinity(0))}')
    print(f'fmu_design_steps: {int(4.0 / 0.002)}')
    print(f'fmu_designs_per_s_in_process: {rate["in_process"]:.2f}')
    print(f'fmu_designs_per_s_isolated: {rate["isolated"]:.2f}')
    print(f'fmu_isolated_over_in_process: {rate["isolated"] / rate["in_process"]:.3f}')
    print(f'fmu_designs_per_s_isolated_2_processes: {rate["isolated_2_processes"]:.2f}')


if __name__ == '__main__':
    main()
