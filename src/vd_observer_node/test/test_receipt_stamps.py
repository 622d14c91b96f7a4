"""Headerless inputs against played bags, and inputs whose stamps never meet.

`ReceiptStamps` stamps a headerless message with the node clock while the stamped inputs run
on it (a car), and with its receipt on the stamped inputs' clock when they do not (a bag
played without /clock); `MatchCheck` reports inputs that arrive but never make a set, once
in the log and on every status until a set matches.
"""

from __future__ import annotations

from typing import Any

import pytest
from vd_observer_node.bag.typestore import serialize
from vd_observer_node.inputs.mapping import mapping_from_dict
from vd_observer_node.nodes.raw_io import (
    MATCH_WAIT_NS,
    SAME_CLOCK_NS,
    InputWatch,
    MatchCheck,
    ReceiptStamps,
    input_matcher,
    mapped_input,
    merge_status,
)
from vd_observer_node.testing.standard_bags import (
    JOINTS,
    STANDARD_MAPPING,
    float64_array,
    joint_state,
    odometry,
)

NS = 1_000_000_000
MS = 1_000_000
#: a node clock on 2026-11-28 (wall time) [ns]
WALL = 1_795_900_000 * NS


def test_on_the_node_clock_a_headerless_input_is_stamped_with_the_node_clock() -> None:
    stamps = ReceiptStamps('wheels')
    assert stamps.stamp('torques', WALL) == WALL  # nothing stamped yet: the node clock
    # a car: the wheel sensor stamps by the same clock, 4 ms before the node receives it
    stamps.note('wheels', WALL + 6 * MS, WALL + 10 * MS)
    stamps.note('speed', 5 * NS, WALL + 11 * MS)  # not the reference: ignored
    assert not stamps.translating
    assert stamps.stamp('torques', WALL + 12 * MS) == WALL + 12 * MS
    # a wheel stamp 0.9 s behind its receipt is still on the node's clock
    stamps.note('wheels', WALL + 100 * MS, WALL + 1_000 * MS)
    assert not stamps.translating
    assert stamps.stamp('torques', WALL + 1_001 * MS) == WALL + 1_001 * MS


def test_against_a_bag_played_without_clock_a_receipt_is_put_on_the_bags_clock() -> None:
    stamps = ReceiptStamps('wheels')
    # the bag's wheel stamp 1.000 s arrives at wall time WALL
    stamps.note('wheels', NS, WALL)
    assert stamps.translating and stamps.offset_ns == NS - WALL
    # 4 ms later on the node clock: 1.004 s on the bag's
    assert stamps.stamp('torques', WALL + 4 * MS) == NS + 4 * MS
    # the next wheel message is delivered 3 ms late: its base is earlier than the last
    # torque stamp, which must not go back
    stamps.note('wheels', NS + 10 * MS, WALL + 13 * MS)
    assert stamps.stamp('torques', WALL + 13 * MS) == NS + 10 * MS
    assert stamps.stamp('torques', WALL + 13 * MS) == NS + 10 * MS + 1
    assert stamps.stamp('engine', WALL + 13 * MS) == NS + 10 * MS  # each input its own
    # the bag's end at 21 s, then it loops: its stamps start over 20 s back: a new time line
    stamps.note('wheels', 21 * NS, WALL + 20 * NS)
    assert stamps.stamp('torques', WALL + 20 * NS + MS) == 21 * NS + MS
    stamps.note('wheels', NS, WALL + 20 * NS + 10 * MS)
    assert stamps.stamp('torques', WALL + 20 * NS + 12 * MS) == NS + 2 * MS
    # the player's /clock arrives (use_sim_time): the node clock is the bag's again
    stamps.note('wheels', 2 * NS, 2 * NS + MS)
    assert not stamps.translating
    assert stamps.stamp('torques', 2 * NS + 3 * MS) == 2 * NS + 3 * MS
    assert SAME_CLOCK_NS == NS


def _standard_callbacks(
    clock: list[int], got: list[tuple[int, dict[str, Any]]]
) -> tuple[dict[str, Any], Any, InputWatch]:
    """The pipeline's mapped subscriptions of the standard bag's mapping ('latest')."""
    mapping = mapping_from_dict(STANDARD_MAPPING)
    specs = mapping.used_specs
    names = [s.name for s in specs]
    matcher = input_matcher(mapping, names, 100, NS // 10, NS // 10)
    watch = InputWatch([s.topic for s in specs], NS)
    counts = {'undecodable': 0}
    callbacks = {
        s.name: mapped_input(
            s,
            matcher,
            lambda stamp, m: got.append((stamp, m)),
            counts,
            watch,
            lambda: clock[0],
            radius=0.3,
        )
        for s in specs
    }
    return callbacks, matcher, watch


@pytest.mark.parametrize('translate', [True, False])
def test_a_played_bags_sensors_and_a_headerless_torque_make_sets_without_sim_time(
    translate: bool,
) -> None:
    """The standard bag's three inputs as a player delivers them to a node on the wall
    clock: 100 Hz wheels and torque, 50 Hz odometry, bag stamps from 1 s. Every wheel stamp
    whose odometry has arrived gets a set, with the torque received last before the wheels.
    Stamped by the node clock instead (as before, issue 41): not one set."""
    clock = [WALL]
    got: list[tuple[int, dict[str, Any]]] = []
    callbacks, matcher, _ = _standard_callbacks(clock, got)
    if not translate:
        matcher.receipts.same_clock_ns = 2**62
    speeds = [10.0, -10.0, 10.0, -10.0]
    for k in range(100):  # 1 s, 1 ms steps; each message arrives 0.2 ms after its stamp
        t_ms = 1_000 + k * 10
        clock[0] = WALL + (k * 10) * MS + MS // 5
        callbacks['wheel_speeds'](serialize(joint_state(t_ms * MS, list(JOINTS), (), speeds)))
        clock[0] += 3 * MS
        if k % 2 == 0:
            callbacks['body_speed'](serialize(odometry((t_ms + 3) * MS, 3.0)))
        clock[0] += 3 * MS
        callbacks['wheel_torques'](serialize(float64_array([float(k), 0.0, 0.0, 0.0])))
    if not translate:
        # every wheel stamp the odometry released is dropped: no torque stamped before it
        assert got == [] and matcher.counts()['unmatched_dropped'] == 99
        return
    assert matcher.receipts.translating
    # sets wait for an odometry stamp at or after the wheel's: all but the last two
    assert len(got) == 98, (len(got), matcher.counts())
    for stamp, full in got:
        k = (stamp // MS - 1_000) // 10
        assert full['wheel_torques'][1][0] == k - 1  # the torque of the previous 10 ms
    assert matcher.counts()['unmatched_dropped'] == 1  # the first wheel stamp: no torque yet


def test_the_check_names_inputs_whose_stamps_never_meet_and_what_to_set() -> None:
    check = MatchCheck(['wheels', 'speed'], 'exact')
    check.topics.update(wheels='/joint_states', speed='/odom')
    check.pushed('wheels', NS, 0, False)
    assert check.status(MATCH_WAIT_NS + NS) == ''  # the odometry not heard from yet
    check.pushed('speed', NS + 3 * MS, NS, False)
    check.pushed('wheels', NS + 10 * MS, 3 * NS // 2, False)
    assert check.status(NS + NS // 4) == ''  # 1.25 s since the first input
    note = check.status(MATCH_WAIT_NS)  # from the first input: 2 s
    assert note.startswith('no input set matched for 2 s: the newest stamps of speed (/odom)')
    assert '-0.007 s from those of wheels (/joint_states)' in note
    assert 'alignment: latest (inputs.alignment: latest)' in note
    # the odometry silent for longer than the wait: the watch reports that topic instead
    assert check.status(NS + MATCH_WAIT_NS + 1) == ''
    check.pushed('speed', 2 * NS, 4 * NS, False)
    check.pushed('wheels', 2 * NS, 4 * NS, True)  # a set: cleared
    assert check.status(4 * NS + MATCH_WAIT_NS - 1) == ''
    # a late last input: the first set gets a quarter of the wait after it came
    late = MatchCheck(['wheels', 'speed'], 'latest', NS // 2)
    for second in range(4):
        late.pushed('wheels', second * NS, second * NS, False)
    late.pushed('speed', 3 * NS, 3 * NS, False)
    assert late.status(3 * NS + MATCH_WAIT_NS // 4 - 1) == ''
    assert late.status(3 * NS + MATCH_WAIT_NS // 4).startswith(
        'no input set matched for 4 s'
    )  # 3.5

    latest = MatchCheck(['wheels', 'torques'], 'latest', NS // 2)
    latest.headerless.add('torques')
    latest.pushed('wheels', NS, 0, False)
    latest.pushed('torques', WALL, 0, False)
    note = latest.status(MATCH_WAIT_NS)
    assert note.startswith('no input set matched for 2 s: the newest stamps of torques ')
    assert 'use_sim_time:=true' in note
    near = MatchCheck(['wheels', 'speed'], 'latest', NS // 10)
    near.pushed('wheels', NS, 0, False)
    near.pushed('speed', NS - NS // 5, 0, False)
    assert 'raise max_age (inputs.max_age)' in near.status(MATCH_WAIT_NS)


def test_the_report_is_logged_once_and_on_every_status_until_a_set_matches() -> None:
    logged: list[str] = []
    clock = [WALL]
    got: list[tuple[int, dict[str, Any]]] = []
    _, matcher, watch = _standard_callbacks(clock, got)
    # as mapped_input wires them; the pushes themselves are the matcher's
    check = watch.check
    assert check is matcher.check
    for name, stamp in (('wheel_speeds', NS), ('body_speed', 500 * NS), ('wheel_torques', NS)):
        check.pushed(name, stamp, 0, False)
    levels = []
    for second in range(1, 5):
        now = second * NS
        check.pushed('wheel_speeds', NS + now, now, False)
        check.pushed('body_speed', 500 * NS + now, now, False)
        check.pushed('wheel_torques', NS + now, now, False)
        for name in ('/joint_states', '/odom', '/can/wheel_torques'):
            watch.seen(name, now)
        level, message, _ = merge_status(0, 'ok', watch, now, log=logged.append)
        levels.append(level)
        assert ('no input set matched' in message) == (second >= 2), message
    assert levels == [0, 1, 1, 1]
    assert len(logged) == 1 and 'body_speed (/odom) +499 s' in logged[0], logged
    check.pushed('wheel_speeds', 7 * NS, 6 * NS, True)
    for name in ('/joint_states', '/odom', '/can/wheel_torques'):
        watch.seen(name, 6 * NS)
    assert merge_status(0, 'ok', watch, 6 * NS, log=logged.append)[:2] == (0, 'ok')
    assert len(logged) == 1


def test_the_estimator_nodes_wheel_states_set_the_time_base_of_its_headerless_torques() -> None:
    """The estimator node's driving input is the observer's WheelStates (`aligned_input`):
    given the node clock, its stamps put the headerless torques' receipts on the bag's clock."""
    from vd_observer_node.bag.cdr_message import MessageCodec
    from vd_observer_node.nodes.raw_io import LatestMatcher, aligned_input

    matcher = LatestMatcher(['states', 'torques'], 100, None, NS // 10)
    got: list[tuple[int, dict[str, Any]]] = []
    counts = {'undecodable': 0}
    clock = [WALL]
    states = aligned_input(
        'vd_msgs/msg/WheelStates', 'states', matcher, lambda s, m: got.append((s, m)), counts,
        lambda: clock[0],
    )  # fmt: skip
    codec = MessageCodec('vd_msgs/msg/WheelStates')
    states(codec.encode(NS, [0.0] * 12))
    assert matcher.receipts.translating
    assert matcher.receipts.stamp('torques', WALL + 2 * MS) == NS + 2 * MS
    # without the node clock (the other nodes' derived inputs) nothing is noted
    other = LatestMatcher(['states', 'torques'], 100, None, NS // 10)
    aligned_input('vd_msgs/msg/WheelStates', 'states', other, lambda s, m: None, counts)(
        codec.encode(NS, [0.0] * 12)
    )
    assert other.receipts.offset_ns is None and counts['undecodable'] == 0
