"""The settings log line and the parameters that are not their defaults."""

from __future__ import annotations

import math

from vd_common.settings_log import settings_line


def test_settings_line_names_each_origin() -> None:
    assert settings_line({}, 'parameters') == 'defaults'
    line = settings_line(
        {'observer.wheel_lipschitz': 100.0, 'vehicle_file': '/a/b.yaml'},
        'replay.yaml',
        {'estimator.slope_filter_tau': 0.21147},
        50.0,
    )
    assert line == (
        'observer.wheel_lipschitz=100 (replay.yaml); vehicle_file=/a/b.yaml (replay.yaml); '
        'estimator.slope_filter_tau=0.211 (input rate 50 Hz); the rest defaults'
    )
    assert settings_line({}, '', {'slope_filter_tau': 0.178}, 100.0, rest=False) == (
        'slope_filter_tau=0.178 (input rate 100 Hz)'
    )
    assert (
        settings_line({'x': 1}, 'parameters', None, math.nan)
        == 'x=1 (parameters); the rest defaults'
    )


def test_given_parameters_are_the_ones_not_at_their_defaults() -> None:
    from vd_common.ros.parameters import ParamSpec, given_parameters

    specs = [
        ParamSpec('rate_hz', 1000.0, 'rate'),
        ParamSpec('vehicle_file', '', 'file'),
        ParamSpec('slope_filter_tau', None, 'unset by default'),
        ParamSpec('flag', False, 'flag'),
    ]
    values = {'rate_hz': 100.0, 'vehicle_file': '', 'slope_filter_tau': None, 'flag': True}
    assert given_parameters(specs, values) == {'rate_hz': 100.0, 'flag': True}
    values.update(slope_filter_tau=0.2, rate_hz=1000.0)
    assert given_parameters(specs, values) == {'slope_filter_tau': 0.2, 'flag': True}
