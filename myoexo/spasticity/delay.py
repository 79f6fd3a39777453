"""The reflex's transmission delay: a ring buffer of past knee states."""

from __future__ import annotations

#: Transmission delay of the stretch reflex, s. 20 ms is SCONE's knee reflex delay; the
#: 30 ms of Falisse et al. 2018 and SpasticMyoElbow drove the paper's PID at level 1
#: into a sustained oscillation on this twin (8.75 deg peak to peak over the last second,
#: 6 subjects; 1.07 deg at 20 ms, 0 at 10 ms), which the study's PID does not show.
STRETCH_DELAY_S = 0.02


class DelayLine:
    """Fixed-size ring buffer of the knee state, read ``delay_steps`` samples late.

    ``push(theta_deg, vel_rad_s)`` stores the present sample and returns the one
    ``delay_steps`` pushes ago (before enough history exists: the oldest sample, i.e. the
    state is held at its start value). Two preallocated lists of floats (scalar access is
    faster on lists than on numpy arrays); no allocation per step.
    """

    def __init__(self, delay_steps: int) -> None:
        if delay_steps < 0:
            raise ValueError(f"delay_steps = {delay_steps} must be >= 0")
        self.delay_steps = int(delay_steps)
        self._size = self.delay_steps + 1
        self._theta = [0.0] * self._size
        self._vel = [0.0] * self._size
        self._count = 0

    def clear(self) -> None:
        """Forget the history (start of an episode)."""
        self._count = 0

    def state(self) -> tuple[tuple[float, ...], tuple[float, ...], int]:
        """The whole history, for :meth:`set_state` (e.g. to replay from here in a planner)."""
        return tuple(self._theta), tuple(self._vel), self._count

    def set_state(self, state: tuple[tuple[float, ...], tuple[float, ...], int]) -> None:
        """Restore a history taken by :meth:`state` of a line of the same delay."""
        theta, vel, count = state
        if len(theta) != self._size or len(vel) != self._size:
            raise ValueError(
                f"a history of {len(theta)} samples does not fit a line of {self._size}"
            )
        self._theta[:], self._vel[:], self._count = theta, vel, int(count)

    def push(self, theta_deg: float, vel_rad_s: float) -> tuple[float, float]:
        """Store the present state; return the delayed one ``(theta_deg, vel_rad_s)``."""
        n = self._size
        count = self._count
        i = count % n
        self._theta[i] = theta_deg
        self._vel[i] = vel_rad_s
        count += 1
        self._count = count
        j = (count - n) % n if count >= n else 0
        return self._theta[j], self._vel[j]
