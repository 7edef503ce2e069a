"""Minimizer of one step's incremental potential: Newton with block-Jacobi PCG and a backtracking line search.

Why this solver: the potential's minimizer is what the torch energies define, so fitting can differentiate
through it implicitly (fitting.py); a few Newton steps on the PSD Hessian approximation with an inexact
conjugate-gradient solve, preconditioned by a symmetric Gauss-Seidel sweep (3-4x fewer iterations than block
Jacobi on a hanging skirt), was the fastest accurate option measured at 2k vertices on a CPU (see bench_sim).
Pinned vertices are held at `step.pin_target` by removing their degrees of freedom.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels
from .cloth import Numeric
from .terms import StepInputs, System, Term


@dataclass
class SolverOptions:
    """Defaults chosen by measurement on a 2k-vertex skirt on a walking body (bench_sim): three Newton steps
    with a loose inner solve keep penetration and the difference to a fully converged rollout at a few mm."""

    max_newton: int = 3
    step_tol: float = 2e-5     # m: stop once the largest vertex update is below this
    cg_tol: float = 0.05       # relative residual of each inner linear solve
    cg_max: int = 25
    line_search: bool = True
    # friction's normal force from the step's own solution, the step then solved once more with it
    # (ImplicitSimulator.end_contact_force): the diagnosis, whose steps start from observed states, needs it
    friction_at_end: bool = False


@dataclass
class SolveStats:
    newton_iterations: int = 0
    cg_iterations: int = 0
    energy: float = 0.0
    last_step: float = 0.0

    def add(self, more: "SolveStats") -> None:
        """Count a further solve of the same step."""
        self.newton_iterations += more.newton_iterations
        self.cg_iterations += more.cg_iterations
        self.energy, self.last_step = more.energy, more.last_step


def total_energy(terms: list[Term], x: np.ndarray, step: StepInputs, num: Numeric) -> float:
    return sum(t.assemble(x, step, num, None) for t in terms)


def minimize(x0: np.ndarray, step: StepInputs, terms: list[Term], num: Numeric,
             options: SolverOptions | None = None) -> tuple[np.ndarray, SolveStats]:
    """Positions minimizing sum(terms) from the initial guess x0."""
    opt = options or SolverOptions()
    free = num.free
    x = np.where(free[:, None] > 0, x0, step.pin_target).astype(np.float64)
    stats = SolveStats()
    dx = np.zeros_like(x)
    for it in range(opt.max_newton):
        system = System(num)
        energy = sum(t.assemble(x, step, num, system) for t in terms)
        system.finalize(x)
        grad = system.grad * free[:, None]
        dx[:] = 0.0
        stats.cg_iterations += kernels.pcg(system.hdiag, system.hpair, num.pairs, num.sweep, free, -grad, dx,
                                           opt.cg_tol, opt.cg_max)
        alpha = 1.0
        if opt.line_search:
            slope = float((grad * dx).sum())
            if slope >= 0.0:  # not a descent direction (CG stopped early on a bad system): take the gradient step
                dx = -grad / np.maximum(np.einsum("vii->v", system.hdiag)[:, None] / 3.0, 1e-12)
                slope = float((grad * dx).sum())
            while alpha > 1e-3:
                trial = total_energy(terms, x + alpha * dx, step, num)
                if trial <= energy + 1e-4 * alpha * slope:
                    energy = trial
                    break
                alpha *= 0.5
        x += alpha * dx
        stats.newton_iterations = it + 1
        stats.energy = energy
        stats.last_step = float(np.abs(alpha * dx).max())
        if stats.last_step < opt.step_tol:
            break
    return x, stats
