"""Reproduction of the paper's simulations (Job, Melo, Sokolow, Sen, PRL 94, 178002, 2005).

`reproduce(out_dir, quick=False)` writes the three figures, their data and the numbers
beside the paper's (`hertzchain reproduce --out DIR`). `run_setups` simulates a list of
setups in one vmapped call (e.g. wall materials, whose modulus and Poisson ratio change
together).
"""

from .batch import run_setups, stack_setups
from .constants import PAPER, PaperValue
from .experiments import FULL_PLAN, QUICK_PLAN, Plan
from .reproduce import reproduce

__all__ = ["FULL_PLAN", "PAPER", "PaperValue", "Plan", "QUICK_PLAN", "reproduce", "run_setups",
           "stack_setups"]
