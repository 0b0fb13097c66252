"""docs/testing.md shows the example project's files as they are."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_testing_guide_quotes_the_example_project_verbatim():
    text = (ROOT / 'docs' / 'testing.md').read_text()
    quoted = re.findall(r'`(examples/[^`]+)`[^\n]*:\n+```\w*\n(.*?)```', text, flags=re.S)
    assert {path for path, _ in quoted} == {
        'examples/custom_valve_controller/lateral_valves.py',
        'examples/custom_valve_controller/test_lateral_valves.py',
        'examples/custom_valve_controller/pytest.ini'}
    for path, block in quoted:
        assert block == (ROOT / path).read_text(), f'docs/testing.md quotes an old {path}'
