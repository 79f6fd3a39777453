"""The reflex's transmission delay: a ring buffer of past sensory records."""

from __future__ import annotations

from typing import Any

#: Transmission delay of the stretch reflex, s. 20 ms is SCONE's knee reflex delay; the
#: 30 ms of Falisse et al. 2018 and SpasticMyoElbow drove the paper's PID at level 1
#: into a sustained oscillation on this twin (8.75 deg peak to peak over the last second,
#: 6 subjects; 1.07 deg at 20 ms, 0 at 10 ms), which the study's PID does not show.
STRETCH_DELAY_S = 0.02


class DelayLine:
    """Fixed-size ring buffer of what the reflex senses, read ``delay_steps`` samples late.

    ``push(sample)`` stores the present sample (a :class:`~myoexo.spasticity.sensory
    .SensoryRecord`, or any value) and returns the one ``delay_steps`` pushes ago (before
    enough history exists: the oldest sample, i.e. the state is held at its start value). One
    preallocated list; no allocation per step.
    """

    def __init__(self, delay_steps: int) -> None:
        if delay_steps < 0:
            raise ValueError(f"delay_steps = {delay_steps} must be >= 0")
        self.delay_steps = int(delay_steps)
        self._size = self.delay_steps + 1
        self._samples: list[Any] = [None] * self._size
        self._count = 0

    def clear(self) -> None:
        """Forget the history (start of an episode)."""
        self._count = 0

    def state(self) -> tuple[tuple[Any, ...], int]:
        """The whole history, for :meth:`set_state` (e.g. to replay from here in a planner).
        The samples are not copied: a pushed sample is never changed in place."""
        return tuple(self._samples), self._count

    def set_state(self, state: tuple[tuple[Any, ...], int]) -> None:
        """Restore a history taken by :meth:`state` of a line of the same delay."""
        samples, count = state
        if len(samples) != self._size:
            raise ValueError(
                f"a history of {len(samples)} samples does not fit a line of {self._size}"
            )
        self._samples[:], self._count = samples, int(count)

    def push(self, sample: Any) -> Any:
        """Store the present sample; return the delayed one."""
        n = self._size
        count = self._count
        self._samples[count % n] = sample
        count += 1
        self._count = count
        return self._samples[(count - n) % n if count >= n else 0]
