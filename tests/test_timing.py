"""PolicyClock: the order of plant updates, perception updates and the policy latch."""

import pytest

from corn_drake.timing import PolicyClock


def test_perception_runs_after_the_last_plant_update_and_before_the_latch():
    clock = PolicyClock(0.1, 0.0125)
    for n in range(1, 2000):
        last_plant_update = n * clock.substeps * clock.time_step
        perception = clock.perception_offset + n * clock.period
        assert last_plant_update < perception < clock.boundary(n)
        # and no plant update in between
        assert clock.boundary(n) - last_plant_update < clock.time_step


def test_each_policy_step_spans_exactly_substeps_plant_updates():
    clock = PolicyClock(0.1, 0.0125)
    assert clock.substeps == 8
    for n in range(0, 500):
        t0, t1 = clock.boundary(n), clock.boundary(n + 1)
        updates = [m for m in range(0, 8 * 600) if t0 < m * clock.time_step < t1]
        assert len(updates) == 8


@pytest.mark.parametrize("period, step", [(0.1, 0.03), (0.1, 0.0), (0.01, 0.0125)])
def test_bad_periods_are_refused(period, step):
    with pytest.raises(ValueError, match="policy_period"):
        PolicyClock(period, step)
