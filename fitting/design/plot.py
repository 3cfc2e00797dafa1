"""The figure of a design's predicted relative uncertainties."""

from __future__ import annotations

import numpy as np

from ..parameters import public_label
from .plan import DesignResult


def plot_design(result: DesignResult, *, baseline: DesignResult | None = None, title: str | None = None):
    """Predicted relative standard errors (bars, log scale) and the correlation matrix."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (bars, matrix) = plt.subplots(1, 2, figsize=(10, 4))
    x = np.arange(len(result.params))
    width = 0.38 if baseline is not None else 0.6
    if baseline is not None:
        bars.bar(x - width / 2, [100 * baseline.relative_stderr[p] for p in result.params], width,
                 label="before (given plan)", color="tab:gray")
    bars.bar(x + (width / 2 if baseline is not None else 0),
             [100 * result.relative_stderr[p] for p in result.params], width,
             label="recommended plan" if baseline is not None else "plan", color="tab:blue")
    names = [public_label(p) for p in result.params]
    bars.set_xticks(x, names)
    bars.set_yscale("log")
    bars.set_ylabel("predicted standard error (% of value)")
    bars.legend(fontsize=8)
    bars.set_title(title or "Cramér–Rao standard errors")
    image = matrix.imshow(result.correlation, vmin=-1, vmax=1, cmap="RdBu_r")
    matrix.set_xticks(x, names)
    matrix.set_yticks(x, names)
    for i in range(len(x)):
        for j in range(len(x)):
            matrix.text(j, i, f"{result.correlation[i, j]:.2f}", ha="center", va="center", fontsize=8)
    matrix.set_title("predicted correlation")
    figure.colorbar(image, ax=matrix)
    figure.tight_layout()
    return figure
