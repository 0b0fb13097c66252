"""Register suspension_tuning in the ament index of a virtual environment.

``pip install -e .`` (setuptools' develop mode) honours ``setup.cfg`` and writes the
console scripts to ``<venv>/lib/suspension_tuning/``, as colcon does, but installs no
``data_files``.  ``ros2 run`` (ros2cli) finds a package through the ament index
(``share/ament_index/resource_index/packages/<pkg>`` under a prefix on
``AMENT_PREFIX_PATH``) and its executables in ``<prefix>/lib/<pkg>/``.  This script
completes that layout in the venv:

- ``share/ament_index/resource_index/packages/suspension_tuning`` (marker)
- ``share/suspension_tuning/package.xml``, ``share/suspension_tuning/config/*.yaml``,
  ``config/foxglove_layout.json`` and ``config/roads/`` (the road files config/road.yaml
  names)
- ``bin/<executable>``: links to ``lib/suspension_tuning/<executable>``, so every node
  is also a command on the venv's PATH.

Usage: ``python scripts/install_ament_files.py <venv>``
"""

import shutil
import sys
from importlib.metadata import distribution
from pathlib import Path

PACKAGE = 'suspension_tuning'


def main(venv: str) -> None:
    """Install the ament index marker, package.xml, config and executable links."""
    prefix = Path(venv).resolve()
    root = Path(__file__).resolve().parent.parent
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True, exist_ok=True)
    shutil.copy(root / 'resource' / PACKAGE, index / PACKAGE)
    share = prefix / 'share' / PACKAGE
    (share / 'config').mkdir(parents=True, exist_ok=True)
    shutil.copy(root / 'package.xml', share / 'package.xml')
    for pattern in ('*.yaml', '*.json'):  # configuration files and the Foxglove layout
        for stale in (share / 'config').glob(pattern):
            stale.unlink()
        for config_file in (root / 'config').glob(pattern):
            shutil.copy(config_file, share / 'config' / config_file.name)
    roads = share / 'config' / 'roads'  # road files of config/road.yaml, with their notices
    if roads.is_dir():
        shutil.rmtree(roads)
    shutil.copytree(root / 'config' / 'roads', roads)
    lib = prefix / 'lib' / PACKAGE
    scripts = [ep.name for ep in distribution(PACKAGE).entry_points
               if ep.group == 'console_scripts']
    for name in scripts:
        if not (lib / name).exists():
            sys.exit(f'executable {lib / name} missing: run pip install -e . first')
        link = prefix / 'bin' / name
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(Path('..', 'lib', PACKAGE, name))
    print(f'{PACKAGE}: ament index, and {len(scripts)} executables in {lib} and on PATH')


if __name__ == '__main__':
    if len(sys.argv) != 2:
        sys.exit('usage: install_ament_files.py <venv>')
    main(sys.argv[1])
