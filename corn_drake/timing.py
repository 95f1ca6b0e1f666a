"""When the policy acts, relative to the physics steps.

The plant steps at m * h (h = physics time step). Policy-rate events (the action latch, the
reward's hold) run at offset + n * period with offset = h / 2: half-way between two physics
steps, so they never tie with a plant update (ties made the action's latency 0 or 1 physics
step depending on floating-point rounding of n * 0.1 vs 8n * 0.0125). An episode starts at time
`offset`; the n-th policy step ends at `boundary(n)`, computed exactly as Drake computes its
periodic event times (offset + n * period), so an AdvanceTo there stops right before the latch
and the next action is fixed in time for it. Each action then drives exactly the next
`substeps` plant updates, with no latency.
"""

from __future__ import annotations

import dataclasses


def whole_multiple(period: float, time_step: float) -> bool:
    """Whether `period` is a whole number (>= 1) of physics steps `time_step`: the one rule the
    clock below and the config check (config/scene.PhysicsConfig.RELATIONS) share."""
    ratio = period / time_step if time_step > 0 else 0.0
    return time_step > 0 and abs(ratio - round(ratio)) <= 1e-9 and round(ratio) >= 1


@dataclasses.dataclass(frozen=True)
class PolicyClock:
    period: float
    time_step: float

    def __post_init__(self):
        if not whole_multiple(self.period, self.time_step):
            raise ValueError(f"policy_period {self.period} must be a whole multiple of the physics "
                             f"time_step {self.time_step}")

    @property
    def offset(self) -> float:
        return self.time_step / 2

    @property
    def perception_offset(self) -> float:
        """Offset of per-step perception updates: a quarter step after each policy boundary's
        last plant update (at n * period) and a quarter step before the policy latch reads it."""
        return self.time_step / 4

    @property
    def substeps(self) -> int:
        return round(self.period / self.time_step)

    def boundary(self, n: int) -> float:
        """Time at which policy step n ends (n = 0: the episode's start)."""
        return self.offset + n * self.period


def clock_of(physics) -> PolicyClock:
    """The PolicyClock of a PhysicsConfig."""
    return PolicyClock(physics.policy_period, physics.time_step)
