"""The model at the data's samples: Catmull-Rom interpolation of the simulated channels,
where each channel's samples lie in the residual vector, and where each residual's sample
comes from (row, time, offset, gain, AC coupling)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def interpolate(values, position):
    """Catmull-Rom cubic interpolation of `values` (n,) at fractional indices `position`.

    Positions outside [0, n-1] take the end values. Differentiable in both arguments
    (C^1 in `position`); the error for a smooth signal is O(h^3) in the sample spacing.
    """
    position = jnp.asarray(position)
    return interpolate_rows(jnp.asarray(values)[None], jnp.zeros(position.shape, jnp.int32), position)


def interpolate_rows(series, rows, position):
    """Catmull-Rom interpolation of `series[rows[j]]` (2-D) at fractional indices `position[j]`.

    The same rule as `interpolate`, for many series at once: one gather per neighbour.
    """
    n = series.shape[-1]
    q = jnp.clip(position, 0.0, n - 1.0)
    i = jnp.clip(jnp.floor(q).astype(jnp.int32), 0, n - 2)
    f = q - i
    flat = series.reshape(-1)
    base = jnp.asarray(rows) * n
    p0 = flat[base + jnp.clip(i - 1, 0, n - 1)]
    p1 = flat[base + i]
    p2 = flat[base + i + 1]
    p3 = flat[base + jnp.clip(i + 2, 0, n - 1)]
    return p1 + 0.5 * f * (
        (p2 - p0) + f * ((2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) + f * (3.0 * (p1 - p2) + p3 - p0))
    )


def residual_slices(experiments) -> list[dict]:
    """Per experiment, channel -> slice of the residual vector: every fitted channel's
    samples, experiment after experiment, in the order of its `channels`."""
    slices, start = [], 0
    for experiment in experiments:
        entry = {}
        for name in experiment.channels:
            n = len(experiment.time_s)
            entry[name] = slice(start, start + n)
            start += n
        slices.append(entry)
    return slices


def sample_layout(problem):
    """Per group, where each residual's sample comes from (numpy, built once).

    For every sample of the group's experiments, in group order: the row of the
    group's (experiments x channels) output it reads, its data time, the indices
    into x of its experiment's trigger offset and its channel's gain (-1: none), and
    whether its channel is AC-coupled.
    `order` maps the concatenation of the groups' samples to the residual layout.
    """
    position = {(e, name): part.start for e, slices in enumerate(residual_slices(problem.experiments))
                for name, part in slices.items()}
    layouts, order = [], []
    for group in problem.groups:
        rows, times, offsets, gains, ac = [], [], [], [], []
        for row, e in enumerate(group.experiments):
            experiment = problem.experiments[e]
            n = len(experiment.time_s)
            offset = problem.offset_index[e]
            for name in experiment.channels:
                rows.append(np.full(n, row * len(group.channels) + group.channels.index(name)))
                times.append(np.asarray(experiment.time_s, dtype=float))
                offsets.append(np.full(n, -1 if offset is None else offset))
                gains.append(np.full(n, problem.gain_index[e].get(name, -1)))
                ac.append(np.full(n, name in experiment.ac_channels))
                order.append(np.arange(position[(e, name)], position[(e, name)] + n))
        layouts.append(tuple(np.concatenate(a) for a in (rows, times, offsets, gains, ac)))
    return layouts, np.argsort(np.concatenate(order))
