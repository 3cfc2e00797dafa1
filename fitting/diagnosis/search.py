"""The state one diagnosis shares between its steps: the problem with every candidate's
strengths, its columns, folds and noise; the steps themselves are the mixins it joins."""

from __future__ import annotations

import numpy as np

from hertzchain.progress import Progress

from .. import effects as fx
from ..data import Experiment
from ..fit import initial_values, make_problem
from ..model import Problem
from ..parameters import ParameterInstance, get_spec, public_label
from .candidates import _Candidates
from .evaluator import _Evaluator
from .heldout import _HeldOut
from .protocol import DiagnosisError, noise_estimate_variance
from .refits import _Refits
from .screening import _Screening


class _Search(_Refits, _Candidates, _Screening, _HeldOut):
    """State shared by the steps of one diagnosis."""

    def __init__(self, experiments: list[Experiment], *, free, nuisances, steps_per_contact, candidates,
                 min_share, report):
        n_beads = {e.trace.n_beads for e in experiments}
        if len(n_beads) != 1:
            raise DiagnosisError(
                f"all files must describe chains of the same length (got {sorted(n_beads)} beads); "
                "diagnose one chain at a time."
            )
        self.n_beads = n_beads.pop()
        self.library = fx.library(self.n_beads)
        # the power-law contacts equal Hertz's at a force typical of the data: the geometric
        # mean of the files' largest forces
        reference_force_n = float(np.exp(np.mean([np.log(max(max(float(np.max(e.data(c))) for c in e.channels),
                                                              1e-3)) for e in experiments])))
        forward = fx.effects_forward_model(self.n_beads, steps_per_contact, reference_force_n=reference_force_n)
        base_params = tuple(nuisances) + tuple(free)
        seed = make_problem(experiments, tuple(map(public_label, base_params)), forward=forward)
        self.base_start = initial_values(seed)
        covered = {fx.COVERED_BY[name] for name in free if name in fx.COVERED_BY}
        has_contacts = any(k for e in experiments for k in (c.startswith("contact_") for c in e.channels))
        names = [c for c in (candidates or fx.EFFECT_NAMES) if c not in covered]
        if not has_contacts and "sensor_dynamics" in names:
            names.remove("sensor_dynamics")
        self.candidates = names
        self.skipped = sorted(covered)
        extra = []
        for effect in self.library.values():
            for name in effect.parameters:
                extra.append(ParameterInstance(get_spec(name), label=name[len(fx.PREFIX):]))
        instances = tuple(seed.instances) + tuple(extra)
        self.problem = Problem(seed.experiments, instances, seed.base_setups, forward)
        self.labels = list(self.problem.labels)
        p = len(self.labels)
        self.lower = np.array([max(i.spec.lower, 0.0) if i.spec.lower < 0 and i.spec.lower > -1e-20
                               else i.spec.lower for i in self.problem.instances])
        self.upper = np.array([i.spec.upper for i in self.problem.instances])
        n_base = len(seed.instances)
        self.base_columns = list(range(n_base))
        self.effect_columns = {
            name: [self.labels.index(par[len(fx.PREFIX):]) for par in effect.parameters]
            for name, effect in self.library.items()
        }
        def variant(plastic=False, **law):
            return Problem(seed.experiments, instances, seed.base_setups,
                           fx.effects_forward_model(self.n_beads, steps_per_contact, plastic=plastic,
                                                    reference_force_n=reference_force_n, **law))

        elastic, power = variant(), variant(power_law=True)
        # what the C++ kernel runs: rigid sensor beads, without and with the dashpot effect
        twins, dashpot_twins = ({self.problem: variant(plastic=True, compliant_sensors=False, dashpot=dashpot),
                                 elastic: variant(compliant_sensors=False, dashpot=dashpot),
                                 power: variant(power_law=True, compliant_sensors=False, dashpot=dashpot)}
                                for dashpot in (False, True))
        self.evaluate = _Evaluator(self.problem, elastic, self.effect_columns["plasticity"],
                                   power, self.effect_columns["contact_exponent"], twins=twins,
                                   dashpot_twins=dashpot_twins,
                                   compliance_columns=[self.labels.index(name)
                                                       for name in ("sensor_coupling", "sensor_rate")],
                                   dashpot_column=self.labels.index("dashpot_n_s_m"))
        x0 = np.zeros(p)
        x0[:n_base] = self.base_start
        for i, inst in enumerate(self.problem.instances[:n_base]):
            x0[i] = float(np.clip(x0[i], inst.spec.lower * (1 + 1e-12) if inst.spec.lower > 0 else inst.spec.lower,
                                  inst.spec.upper))
        self.x0 = x0
        self.n = self.problem.n_residuals
        self.min_share = min_share
        self.report = Progress(None, "diagnose") if report else None
        self.row_time_fraction = np.concatenate([
            np.asarray(e.time_s) / float(e.time_s[-1]) for e in self.problem.experiments for _ in e.channels
        ])
        slices = self.problem.residual_slices()
        self.file_rows = [np.concatenate([np.arange(s.start, s.stop) for s in sl.values()]) for sl in slices]
        self.file_columns = [
            [i for i, inst in enumerate(self.problem.instances) if inst.experiment == e]
            for e in range(len(self.problem.experiments))
        ]
        self.nuisance_columns = [c for columns in self.file_columns for c in columns]
        amplitude = [max(float(np.max(e.data(c))) for c in e.channels) for e in self.problem.experiments]
        order = np.argsort(amplitude)
        self.folds = [sorted(order[0::2].tolist()), sorted(order[1::2].tolist())] if len(order) >= 2 else []
        self.noise_estimate_variance = noise_estimate_variance(self.problem.experiments)

    def log(self, text: str):
        if self.report is not None:
            self.report.note(text)

    def columns(self, effects) -> list[int]:
        cols = list(self.base_columns)
        for name in effects:
            cols += self.effect_columns[name]
        return cols
