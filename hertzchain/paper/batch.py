"""Many setups in one vmapped solve: the engine of the paper's sweeps.

`simulate_batch` sweeps the outer product of scalar fields. The paper's wall materials
change two fields together (Young's modulus and Poisson ratio), so the reproduction stacks
an explicit list of setups instead and vmaps `solve` over it. One time grid serves the
whole batch: the step resolves the shortest contact of the most demanding setup.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..chain import ChainSetup
from ..integrate import Recording, check_yield, solve_stacked, stack_setups
from ..timegrid import (
    DEFAULT_STEPS_PER_CONTACT,
    TimeGrid,
    choose_time_grid,
    shortest_contact_time_s,
)
from ..traces import Traces


def batch_time_grid(
    setups: Sequence[ChainSetup],
    *,
    t_end_s: float,
    sample_interval_s: float,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
) -> TimeGrid:
    """A time grid fine enough for every setup of the list (its shortest contact time)."""
    shortest = min(shortest_contact_time_s(setup) for setup in setups)
    steps = max(1, math.ceil(sample_interval_s / (shortest / steps_per_contact)))
    return choose_time_grid(
        setups[0], t_end_s=t_end_s, sample_interval_s=sample_interval_s,
        dt_s=sample_interval_s / steps,
    )


def run_setups(
    setups: Sequence[ChainSetup],
    *,
    t_end_s: float,
    sample_interval_s: float = 1e-6,
    contacts: Sequence[int] = (),
    record_all: bool = False,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
    on_yield: str = "ignore",
) -> Traces:
    """Simulate a list of setups in one vmapped call.

    **Arguments:**

    - `setups`: `ChainSetup`s with the same number of beads, end and sensor beads.
    - `t_end_s`, `sample_interval_s`: recorded duration and sampling interval, s.
    - `contacts`: paper-numbered contacts recorded as `contact_K` (the wall always is).
    - `record_all`: also record every contact force, position and velocity.
    - `steps_per_contact`: resolution of the shortest contact of the batch.
    - `on_yield`: `"warn"`, `"raise"` or `"ignore"` (default: the paper's wall forces at
      its impact speeds stay below yield; sweeps to large speeds may not).

    **Returns:** `Traces` whose arrays have a leading axis of length `len(setups)`.
    """
    stacked = stack_setups(setups)
    grid = batch_time_grid(
        setups, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
        steps_per_contact=steps_per_contact,
    )
    recording = Recording(tuple(int(k) for k in contacts), bool(record_all))
    for k in recording.contacts:
        if not 0 <= k < setups[0].n_beads:
            raise ValueError(
                f"contacts: contact {k} is not in the chain (0..{setups[0].n_beads - 1})."
            )
    traces = solve_stacked(stacked, grid, recording)
    check_yield(traces, on_yield)
    return traces
