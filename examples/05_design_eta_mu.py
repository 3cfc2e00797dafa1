# %% [markdown]
# # 5. Which experiments separate viscous damping from track friction?
#
# The paper fits two dissipation mechanisms: viscoelastic damping η at the contacts and
# Coulomb friction μ m g of the beads on the track. Both lower and broaden the pulse, so a
# poorly chosen experiment confuses them. Before recording anything, the Fisher
# information of the fit's own residuals (`fitting.design`) predicts the standard errors
# of η, μ and the speed constant C and their correlation (Cramér–Rao) for any plan: impact
# velocities, recorded channels, noise, sampling. Here: for the paper's chain (21 steel
# beads, R = 13 mm) with η = 1.7 µs, μ = 0.12, μ* = 0.03, 0.5 N noise, 1 µs sampling.
#
# 1. Each single recording (one impact velocity, one channel): how well does it pin η and
#    μ, and how strongly are they correlated?
# 2. The D-optimal plan of 4 recordings against a paper-like plan (one impact at 0.3 m/s,
#    contacts 6 and 11 and the wall).
#
# Nuisances (striker velocity, trigger offset, gains) are fixed here, as in `hertzchain
# fit`'s default. Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a small, fast version; outputs go to
# `HERTZCHAIN_EXAMPLE_OUT` (default `out/examples`).

# %%
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import hertzchain as hc  # noqa: E402
from fitting import design as fd  # noqa: E402
from hertzchain.io.atomic import save_figure, write_json  # noqa: E402

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples"))

values = {"eta_s": 1.7e-6, "mu": 0.12, "mu_star": 0.03}
setup = hc.ChainSetup(eta_s=values["eta_s"], mu=values["mu"], mu_star=values["mu_star"])
velocities = [0.1, 0.4] if SMALL else [0.03, 0.06, 0.1, 0.2, 0.4, 0.8]
channels = ["contact_6", "contact_15", "wall"] if SMALL else [
    "contact_2", "contact_6", "contact_10", "contact_15", "contact_19", "wall"]
paper_plan = [(0.3, "contact_6"), (0.3, "contact_11"), (0.3, "wall")]
run = dict(noise_std_n=0.5, sample_interval_s=2e-6 if SMALL else 1e-6,
           t_end_s=1.6e-3 if SMALL else 2.5e-3)

# %% [markdown]
# One call simulates every candidate (velocity x channel) and its Jacobian; the D-optimal
# search (greedy, then exchanges) then works on the per-recording Fisher blocks, and
# `evaluate` predicts any subset of the candidates.

# %%
optimization = fd.optimize_plan(
    setup, ("eta_s", "mu", "C"), candidate_velocities_m_s=velocities, candidate_channels=channels,
    size=4 if not SMALL else 3, values=values, criterion="D", baseline_units=paper_plan,
    progress=False, **run,
)
print("recommended:", ", ".join(f"{c} at {v:g} m/s" for v, c in optimization.chosen))
for p in ("eta_s", "mu", "C"):
    before = optimization.baseline.relative_stderr[p]
    after = optimization.recommended.relative_stderr[p]
    print(f"  {p}: paper-like plan {100 * before:.3g} %  ->  recommended {100 * after:.3g} %")

# %% [markdown]
# Single recordings: relative standard errors of η and μ (with C fitted as well) and their
# correlation. A recording that cannot determine all three at once is left blank.

# %%
grid_velocities = optimization.candidates["velocities_m_s"]
channels = optimization.candidates["channels"]
shape = (len(grid_velocities), len(channels))
sigma_eta, sigma_mu, corr = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
for i, v in enumerate(grid_velocities):
    for j, c in enumerate(channels):
        try:
            single = optimization.evaluate([(v, c)])
        except fd.DesignError:
            continue
        sigma_eta[i, j] = 100 * single.relative_stderr["eta_s"]
        sigma_mu[i, j] = 100 * single.relative_stderr["mu"]
        corr[i, j] = single.correlation[0, 1]

figure, axes = plt.subplots(1, 3, figsize=(15, 4.2))
for ax, data, title, cmap, norm in (
    (axes[0], sigma_eta, "σ(η)/η of one recording (%)", "viridis", matplotlib.colors.LogNorm()),
    (axes[1], sigma_mu, "σ(μ)/μ of one recording (%)", "viridis", matplotlib.colors.LogNorm()),
    (axes[2], corr, "correlation of η and μ", "RdBu_r", matplotlib.colors.Normalize(-1, 1)),
):
    image = ax.imshow(data, cmap=cmap, norm=norm, aspect="auto", origin="lower")
    ax.set_xticks(range(len(channels)), [c.replace("contact_", "c") for c in channels])
    ax.set_yticks(range(len(grid_velocities)), [f"{v:g}" for v in grid_velocities])
    ax.set_xlabel("recorded channel")
    ax.set_ylabel("impact velocity (m/s)")
    ax.set_title(title, fontsize=10)
    for (i, j), value in np.ndenumerate(data):
        if np.isfinite(value):
            ax.text(j, i, f"{value:.2g}", ha="center", va="center", fontsize=7, color="w")
    figure.colorbar(image, ax=ax)
for v, c in optimization.chosen:
    axes[2].add_patch(plt.Rectangle((channels.index(c) - 0.5, grid_velocities.index(v) - 0.5), 1, 1,
                                    fill=False, lw=2, ec="k"))
figure.suptitle("paper's chain, η = 1.7 µs, μ = 0.12, 0.5 N noise; boxes: D-optimal plan", fontsize=10)
figure.tight_layout()
save_figure(figure, OUT / "05_design_single_recordings.png", dpi=110)

comparison = fd.plot_design(optimization.recommended, baseline=optimization.baseline,
                            title="paper-like plan vs D-optimal plan")
save_figure(comparison, OUT / "05_design_plans.png", dpi=110)
write_json(OUT / "05_design.json", optimization.to_json())
print("wrote", OUT / "05_design_single_recordings.png", OUT / "05_design_plans.png", OUT / "05_design.json")

# %% [markdown]
# Reading the maps: the best single recordings for each parameter, and the least
# correlated one (a plan that combines recordings whose η-μ correlations differ separates
# the two mechanisms best; that is what the D-optimal search exploits).

# %%
for name, data in (("eta_s", sigma_eta), ("mu", sigma_mu)):
    i, j = np.unravel_index(np.nanargmin(data), data.shape)
    print(f"best single recording for {name}: {channels[j]} at {grid_velocities[i]:g} m/s "
          f"({data[i, j]:.3g} %)")
i, j = np.unravel_index(np.nanargmin(np.abs(corr)), corr.shape)
print(f"least eta-mu correlation: {channels[j]} at {grid_velocities[i]:g} m/s ({corr[i, j]:+.2f})")

# %% [markdown]
# The prediction is local: it holds at the assumed η, μ, C and noise, and should be re-made
# with the values of a first fit before the next round of measurements.
