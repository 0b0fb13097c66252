"""Where the package's configuration lives, in a source tree or an installed package."""

from __future__ import annotations

from pathlib import Path


def config_dir() -> Path:
    """The ``config/`` folder: the source tree's, else the installed share folder's.

    An editable install (``make setup``) reads the repository's ``config/``; a colcon
    install reads ``share/suspension_tuning/config`` through the ament index.
    """
    source = Path(__file__).resolve().parents[1] / 'config'
    if source.is_dir():
        return source
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory('suspension_tuning')) / 'config'
