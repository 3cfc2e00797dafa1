# %% [markdown]
# # 3. Fit eta, mu and C to trace files
#
# Trace files (`hertzchain-trace/1` CSV: a `# key = value` header describing the chain,
# then time and force columns) are what the fitting tools read. Here we make our own:
# the paper's chain with known dissipation (eta = 1.7 us, mu = 0.12), recorded at two
# contacts and the wall by a model oscilloscope with noise, at several impact velocities.
# Then `fitting.fit` recovers eta, mu and the velocity constant C, with standard errors.
#
# Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a small data set; outputs go to
# `HERTZCHAIN_EXAMPLE_OUT` (default `out/examples`).

# %%
import os
from pathlib import Path

import hertzchain as hc
from hertzchain.acquisition import Acquisition, acquire_trace
from hertzchain.io.tracefile import write_trace

import fitting
from fitting.report import write_report

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples"))
TRUE_ETA_S, TRUE_MU = 1.7e-6, 0.12

# %% [markdown]
# ## Synthetic experiments
#
# Simulated finely (every 0.25 us), then recorded every microsecond with 0.3 N of noise.
# The true values travel in the header as free-form `x_true_*` keys.

# %%
velocities_m_s = [0.1] if SMALL else [0.05, 0.15, 0.4, 0.8]
t_end_s = 1.4e-3 if SMALL else 2.0e-3
paths = []
for i, velocity in enumerate(velocities_m_s):
    setup = hc.ChainSetup(eta_s=TRUE_ETA_S, mu=TRUE_MU, striker_velocity_m_s=velocity)
    run = hc.simulate(setup, t_end_s=t_end_s, sample_interval_s=0.25e-6, contacts=(6, 11),
                      on_yield="ignore")
    forces = {name: run.forces_n[name] for name in run.channel_names}
    trace = acquire_trace(setup, run.time_s, forces, Acquisition(noise_std_n=0.3), seed=i,
                          truth={"eta_s": TRUE_ETA_S, "mu": TRUE_MU})
    path = OUT / f"03_shot_{velocity:g}m_s.csv"
    write_trace(path, trace)
    paths.append(path)
print("trace files:", ", ".join(p.name for p in paths))

# %% [markdown]
# ## The fit
#
# Levenberg-Marquardt through the differentiable simulator. The striker velocity and the
# noise level are read from each file's header.

# %%
result = fitting.fit(paths, params=("eta_s", "mu", "C"), start={"eta_s": 1e-6, "mu": 0.05},
                     progress=False)
truth = {"eta_s": TRUE_ETA_S, "mu": TRUE_MU}
for label in result.labels:
    value, error = result.values[label], result.stderr[label]
    line = f"{label:>4} = {value:.6g} +- {error:.2g} {result.units[label]}"
    if label in truth:
        line += f"   (true {truth[label]:g}: {(value - truth[label]) / error:+.1f} standard errors)"
    print(line)
print(f"reduced chi^2 = {result.reduced_chi2:.3f} ({result.dof} degrees of freedom), "
      f"converged: {result.converged}")
for warning in result.warnings:
    print("warning:", warning)

# %% [markdown]
# The report: `fit.json`, parameter and residual CSV files, and plots of data against
# the fitted model.

# %%
written = write_report(result, OUT / "03_fit")
print("wrote", ", ".join(p.name for p in written))
