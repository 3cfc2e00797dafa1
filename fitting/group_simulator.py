"""The compiled simulation of one group of a `fitting.model.Problem`: the batched kernel
where it runs the physics (else `solve` under `vmap`), with a custom JVP that
differentiates the simulator once per experiment."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from hertzchain.batched import contact_law, kernel_flags, record_batched

from .forward_model import FAST_PATH_PHYSICS, _default_simulate
from .simulation_groups import _Group


def fast_path_flags(problem, group: _Group):
    """The batched kernel's flags for `group`, or None where it takes `solve` under
    `vmap` (a custom forward model, a setup or a freed parameter the kernel lacks)."""
    form = problem.forward.kernel
    if problem.forward.simulate is not _default_simulate and form is None:
        return None
    indices = list(group.global_index) + [int(i) for i in np.ravel(group.local_index[:1])]
    specs = [problem.instances[i].spec for i in indices]
    if any(spec.kind == "setup" and spec.name not in FAST_PATH_PHYSICS for spec in specs):
        return None
    switched_on = {FAST_PATH_PHYSICS[spec.name] for spec in specs if spec.kind == "setup"} - {None}
    if form is not None:
        switched_on |= form.physics({spec.name for spec in specs if spec.kind == "extra"})
    # a fit reads the recorded forces only: no running maxima, no energy books
    flags = kernel_flags(group.setups, switched_on=switched_on)._replace(ledger=False)
    if form is None:
        return flags
    # the law of the chain the extras make (a static field of the setup)
    applied = form.setup(jax.tree_util.tree_map(lambda a: a[0], group.setups), problem.forward.extras_defaults)
    sensors = form.compliant_sensors(group.recording, problem.forward.extras_defaults)
    return flags._replace(law=contact_law(applied), sensors=() if sensors is None else tuple(sensors.beads))


def group_simulator(problem, group: _Group):
    """(simulate, batch): the compiled simulation of `group` of `problem` from its parameter
    values, with the custom JVP that differentiates the simulator once per experiment
    (`batch`: the same without it, for directional derivatives)."""
    global_specs = [problem.instances[i].spec for i in group.global_index]
    local_specs = (
        [problem.instances[i].spec for i in group.local_index[0]] if group.local_index.size else []
    )
    n_global = len(global_specs)
    forward = problem.forward
    flags = fast_path_flags(problem, group)

    def applied(setup, theta_global, theta_local):
        extras = dict(forward.extras_defaults)
        pairs = list(zip(global_specs, theta_global)) + list(zip(local_specs, theta_local))
        for spec, value in sorted(pairs, key=lambda pair: pair[0].stage):
            if spec.kind == "setup":
                setup = spec.apply(setup, value)
            else:
                extras[spec.name] = value
        return setup, extras

    def channels(forces_n, rest, axis):
        # what the channels read at rest (column 0), then the run
        series = jnp.stack([forces_n[name] for name in group.channels], axis=axis)
        start = jnp.broadcast_to(jnp.expand_dims(rest, (-2, -1)), series.shape[:-1] + (1,))
        return jnp.concatenate([start, series], axis=-1)

    def one(setup, theta_global, theta_local):
        setup, extras = applied(setup, theta_global, theta_local)
        traces = forward.simulate(setup, group.grid, group.recording, extras)
        # the static preload, unless the model says otherwise
        return channels(traces.forces_n, getattr(traces, "rest_n", setup.precompression_n), 0)

    # `jax.jit` on the heavy parts: an optimiser traces the residuals many times (init,
    # step, linearisation, covariance); the jitted simulation is traced once per shape
    # and lowered once, which cuts a fit's compile time severalfold.
    # Every function below takes C parameter sets at once (a leading axis: theta_global
    # (C, n_global), theta_local (C, n_experiments, n_local)) and returns
    # (C, n_experiments, n_channels, n_samples + 1); a fit passes C = 1, the posterior's
    # chains C > 1 (one simulation of C x n_experiments chains on the batched kernel).
    if flags is None:
        per_experiment = jax.vmap(one, in_axes=(0, None, 0))

        @jax.jit
        def batch(theta_global, theta_local):
            return jax.vmap(per_experiment, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)

        def jac_one(setup, theta_global, local):
            def f(p):
                out = one(setup, p[:n_global], p[n_global:])
                return out, out

            return jax.jacfwd(f, has_aux=True)(jnp.concatenate([theta_global, local]))

        @jax.jit
        def jacobian(theta_global, theta_local):
            per_chain = jax.vmap(jac_one, in_axes=(0, None, 0))
            return jax.vmap(per_chain, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)
    else:
        form = forward.kernel

        @jax.jit
        def batch(theta_global, theta_local):
            chains, experiments = theta_local.shape[:2]
            per_experiment = jax.vmap(applied, in_axes=(0, None, 0))
            setups, extras = jax.vmap(per_experiment, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)
            # chains x experiments on the kernel's batch axis
            setups, extras = jax.tree_util.tree_map(
                lambda a: jnp.broadcast_to(a, (chains, experiments) + jnp.shape(a)[2:]).reshape(
                    (chains * experiments,) + jnp.shape(a)[2:]), (setups, extras))
            if form is None:
                recording = group.recording
            else:
                recording = form.recording(group.recording)
                setups = jax.vmap(form.setup)(setups, extras)
            # one sample per loop iteration: a fit's batch is small, so the loop overhead
            # that longer unrolled blocks hide matters less than their compile time
            # (fit benchmark: 20 steps per block compiled in 6.7 s, one sample of 6 in 3.4 s,
            # the same run time)
            sensors = None if form is None else form.compliant_sensors(group.recording, extras)
            traces = record_batched(setups, group.grid, recording, flags,
                                    block_steps=group.grid.steps_per_sample, compliant_sensors=sensors)
            if form is None:
                out = channels(traces.forces_n, setups.precompression_n, 1)
            else:
                read = jax.vmap(form.readings, in_axes=(0, 0, 0, None, None))
                out = channels(*read(traces.forces_n, setups, extras, group.grid, group.recording), 1)
            return out.reshape((chains, experiments) + out.shape[1:])

        @jax.jit
        def jacobian(theta_global, theta_local):
            # Experiments and parameter sets are independent, so one tangent that moves
            # a parameter of every experiment and every set at once gives each its own
            # derivative.
            def f(p):
                out = batch(theta_global + p[:n_global], theta_local + p[n_global:])
                return out, out

            return jax.jacfwd(f, has_aux=True)(jnp.zeros(n_global + theta_local.shape[2]))

    @jax.custom_jvp
    def simulate(theta_global, theta_local):
        return batch(theta_global, theta_local)

    @simulate.defjvp
    def simulate_jvp(primals, tangents):
        theta_global, theta_local = primals
        d_global, d_local = tangents
        if n_global + theta_local.shape[2] == 0:
            out = batch(theta_global, theta_local)
            return out, jnp.zeros_like(out)

        jac, out = jacobian(theta_global, theta_local)
        chains, experiments = theta_local.shape[:2]
        direction = jnp.concatenate(
            [jnp.broadcast_to(d_global[:, None, :], (chains, experiments, n_global)), d_local], axis=2
        )
        return out, jnp.einsum("cexsp,cep->cexs", jac, direction)

    return simulate, batch
