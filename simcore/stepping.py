"""A run's step loop: the engine stepped until its scenario ends or the run's last step, every world frame
handed to what reads it. `simcore.pipeline.drive` sets a run's parts up around it. The loop runs for every
step of every run, so it is one of the compiled modules (setup.py `COMPILED`) with the engine it steps and
the metrics it feeds.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sized
from typing import TYPE_CHECKING, Any, Final

from simcore.errors import SimulationError

if TYPE_CHECKING:
    from simcore.evaluation.metrics import MetricsAccumulator
    from simcore.scenario.engine import ScenarioEngine
    from simcore.transport.world import WorldPublisher
    from simcore.world.state import WorldFrame

#: wall seconds between two progress reports of a run (a sweep's run of a tenth of a second reports none: its
#: end is reported anyway; a report from a worker process costs a queue message and a wake-up of the parent)
PROGRESS_INTERVAL_S: Final = 0.5


class FrameReaders:
    """What reads a run's world frames, in the order each frame reaches them: the recording's ground truth
    (`ground_truth`: OSI), the metrics, the closed loop (the frame's time: its nodes may go on), the world
    publisher (the ROS topics), perception, V2X. None for a part the run does not have."""

    def __init__(
        self,
        world: WorldPublisher,
        metrics: MetricsAccumulator | None = None,
        *,
        ground_truth: Callable[[WorldFrame], None] | None = None,
        closed_loop: Any = None,
        perception: Any = None,
        v2x: Any = None,
    ) -> None:
        self.world = world
        #: the publisher's consumers, a live collection (the publisher is no compiled class: read once here)
        self.consumers: Sized = world.consumers
        self.metrics = metrics
        self.ground_truth = ground_truth
        self.closed_loop = closed_loop
        self.perception = perception
        self.v2x = v2x

    def take(self, frame: WorldFrame) -> None:
        if self.ground_truth is not None:
            self.ground_truth(frame)
        if self.metrics is not None:
            self.metrics.update(frame)
        if self.closed_loop is not None:
            self.closed_loop.published(frame.time)
        if self.consumers:  # (what `publish` checks first: the call is skipped too)
            self.world.publish(frame)
        if self.perception is not None:
            self.perception.step(frame)
        if self.v2x is not None:
            self.v2x.step(frame)


def step_to_end(
    engine: ScenarioEngine,
    readers: FrameReaders | None,
    max_steps: int,
    frame: WorldFrame | None,
    *,
    closed_loop: Any = None,
    observe: Callable[[ScenarioEngine], None] | None = None,
    progress: Callable[[int, float], None] | None = None,
    index: int = 0,
    deadline: float | None = None,
    timeout_seconds: object = None,
) -> WorldFrame | None:
    """Step `engine` until it ends or reaches step `max_steps`; with `readers`, a frame per step to them (else
    the engine only advances). Before each step the closed loop (if any) waits for its external entities'
    nodes; after it, `observe` sees the engine and `progress` gets (index, simulated seconds) every
    PROGRESS_INTERVAL_S. Past the wall-clock `deadline` (checked every 100 steps) the run ends with a
    SimulationError naming `timeout_seconds`. Returns the last frame (`frame`, the initial one, when no step
    made one)."""
    next_report = time.monotonic() + PROGRESS_INTERVAL_S
    while not engine.ended and engine.step_index < max_steps:
        if closed_loop is not None:
            closed_loop.wait((b.name for b in engine.bodies.values() if b.external), engine.time)
        if readers is not None:
            frame = engine.step()
            readers.take(frame)
        else:
            engine.advance()
        if observe is not None:
            observe(engine)
        if progress is not None and time.monotonic() >= next_report:
            next_report = time.monotonic() + PROGRESS_INTERVAL_S
            progress(index, engine.time)
        if deadline is not None and engine.step_index % 100 == 0 and time.monotonic() > deadline:
            raise SimulationError(
                f"run exceeded execution.timeoutSeconds={timeout_seconds} at simulated t={engine.time:.1f} s"
            )
    return frame
