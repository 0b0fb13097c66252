"""ament_python package ``suspension_tuning`` (see README.md)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'suspension_tuning'

# Executables: `ros2 run suspension_tuning <name>` (installed to lib/suspension_tuning
# by setup.cfg under colcon; scripts/install_ament_files.py links them there in the venv).
CONSOLE_SCRIPTS = [
    'full_vehicle_sim = suspension_tuning.nodes.full_vehicle_sim:main',
    'valve_controller = suspension_tuning.nodes.valve_controller:main',
    'gradient_evaluator = suspension_tuning.nodes.gradient_evaluator:main',
    'coordinator = suspension_tuning.nodes.coordinator:main',
    'recorder = suspension_tuning.nodes.recorder:main',
    'replay = suspension_tuning.nodes.replay:main',
    'inspect_bag = suspension_tuning.inspect_bag:main',
    'graph = suspension_tuning.graph:main',
    'tune = suspension_tuning.tune:main',
    'study = suspension_tuning.study:main',
    'road = suspension_tuning.road_tool:main',
]

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        # configuration files and the Foxglove layout (config/foxglove_layout.json)
        (f'share/{PACKAGE}/config', glob('config/*.yaml') + glob('config/*.json')),
        # road files that config/road.yaml names (with their licence notices)
        (f'share/{PACKAGE}/config/roads', glob('config/roads/*')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='suspension_tuning maintainers',
    maintainer_email='maintainers@suspension-tuning.dev',
    description='Dynamic-Q tuning of the 4S4 suspension of a Land Rover Defender 110.',
    license='Apache-2.0',
    # The testing kit's fixtures for any pytest session with the package installed.
    entry_points={'console_scripts': CONSOLE_SCRIPTS,
                  'pytest11': ['suspension_tuning = suspension_tuning.testing.pytest_plugin']},
)
