"""One log line for the settings a node or tool runs with and where each came from (ROS-free).

Issue 26 item 4: a user must see which settings were not the defaults, and why: set in a file
or as parameters, or derived from the measured input rate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

__all__ = ['settings_line']


def settings_line(
    given: Mapping[str, object],
    origin: str,
    derived: Mapping[str, float] | None = None,
    rate_hz: float = math.nan,
    *,
    rest: bool = True,
) -> str:
    """One log line: the settings in use that are not defaults, and where each came from.

    Args:
        given: settings set by the user, by name (e.g. ``'estimator.slope_filter_tau'``).
        origin: where `given` came from (a file's name, 'parameters').
        derived: settings that followed the input rate, by name, [s] or their unit.
        rate_hz: [Hz] the rate they followed.
        rest: end with what the others are ('the rest defaults'); False for a line that
            adds to an earlier one.

    Returns:
        e.g. ``'observer.wheel_lipschitz=100 (replay_100hz.yaml); slope_filter_tau=0.271
        (input rate 50 Hz); the rest defaults'``.
    """
    parts = [
        f'{name}={value:g}' if isinstance(value, float) else f'{name}={value}'
        for name, value in given.items()
    ]
    text = [f'{p} ({origin})' for p in parts]
    text += [
        f'{name}={value:.3g} (input rate {rate_hz:.4g} Hz)'
        for name, value in (derived or {}).items()
    ]
    if rest:
        text.append('the rest defaults' if text else 'defaults')
    return '; '.join(text)
