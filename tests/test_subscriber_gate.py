"""`vd_common.ros.publishing.SubscriberGate`: when a simulator or player may send first."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from vd_common.ros.publishing import SubscriberGate


@dataclass
class FakePublisher:
    topic_name: str
    subscribers: int = 0

    def get_subscription_count(self) -> int:
        return self.subscribers


def test_it_opens_once_each_publisher_has_its_own_minimum_and_the_counts_settled() -> None:
    sensor, truth = FakePublisher('/sensor'), FakePublisher('/truth')
    gate = SubscriberGate([sensor, truth], deadline=100.0, settle_s=1.0, min_subscribers=[2, 1])
    sensor.subscribers = truth.subscribers = 1  # the recorder alone
    assert not gate.ready(0.0)
    assert not gate.ready(5.0)  # settled, but the sensor waits for its second subscriber
    assert gate.missing == ['/sensor']
    sensor.subscribers = 2  # the estimation node arrives
    assert not gate.ready(5.1)  # counts changed: settle again
    assert gate.ready(6.2)
    assert gate.missing == []


def test_it_opens_at_the_deadline_and_names_what_is_missing() -> None:
    sensor = FakePublisher('/sensor', 1)
    gate = SubscriberGate([sensor], deadline=3.0, min_subscribers=2)
    assert not gate.ready(0.0)
    assert gate.ready(3.0)
    assert gate.missing == ['/sensor']


def test_one_minimum_per_publisher_or_one_for_all() -> None:
    with pytest.raises(ValueError, match='one per publisher'):
        SubscriberGate([FakePublisher('/a')], deadline=1.0, min_subscribers=[1, 2])
