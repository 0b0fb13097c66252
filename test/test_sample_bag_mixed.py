"""The closed-loop mixed run kept in bags/sample_mixed (regenerate_sample_bag.py --mixed):
a recorded run in which the valves switch, with everything the Foxglove layout plots."""

import json
from pathlib import Path

import numpy as np

from suspension_tuning.paths import config_dir

SAMPLE = Path(__file__).resolve().parents[1] / 'bags' / 'sample_mixed'


def test_mixed_sample_bag_is_a_recorded_run_whose_valves_switch_after_their_delay():
    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.inspect_bag import summary

    info = summary(SAMPLE)
    assert info['complete'] and info['run_config']['scenario'] == 'mixed'
    assert info['run_config']['gradient_source'] == 'evaluate'
    assert info['optimum']['n_full_runs'] == 1  # one full-model run, no optimisation
    contents = read_messages(SAMPLE)

    def front_spring(topic):
        messages = [decode(contents, m) for m in contents.on(topic)]
        return (np.array([m.step for m in messages]),
                np.array([m.front_spring for m in messages]))

    steps, command = front_spring('/suspension/valve_command')
    state_steps, state = front_spring('/suspension/valve_state')
    np.testing.assert_array_equal(steps, state_steps)  # one answer per control step
    switched_command = steps[1:][np.diff(command) != 0]
    switched_state = steps[1:][np.diff(state) != 0]
    assert switched_command.size >= 2  # into the handling state and back
    assert switched_state.size == switched_command.size
    # the valve state follows its command 50-100 ms later (paper section 3), at the
    # controller's 10 ms period (config/valve_controller.yaml): 5-10 steps
    delay_steps = switched_state - switched_command
    assert np.all((delay_steps >= 5) & (delay_steps <= 10)), delay_steps


def test_mixed_sample_bag_holds_every_topic_the_foxglove_layout_plots():
    from suspension_tuning.inspect_bag import summary

    layout = json.loads((config_dir() / 'foxglove_layout.json').read_text())
    topics = {path['value'].split('.')[0] for config in layout['configById'].values()
              for path in config['paths']}
    recorded = summary(SAMPLE)['topics']
    for topic in topics:
        assert recorded.get(topic, {}).get('count', 0) > 0, topic
