"""The contract every energy term follows, the per-step inputs they read, and the solver's assembly buffers.

A term is one named contribution to the incremental potential of an implicit-Euler step
E(x) = sum_terms E_term(x), minimized over the end-of-step positions x. Each term provides
- `energy(x, step, rest)` in torch: differentiable in x and in its parameters / the cloth's material and rest
  lengths (fitting, implicit differentiation, residual-force diagnosis use this), batched over leading dims;
- `assemble(x, step, num, system)` in numpy/numba: its energy, and when a System is given its gradient and a
  PSD Hessian approximation (the fast forward solver uses this).
Tests check the two against each other and the torch gradient against finite differences.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
import torch

from . import kernels
from .cloth import Numeric, Rest


@dataclass
class StepInputs:
    """Everything one step reads besides the unknown end positions x. Arrays are numpy [V,...] for the solver or
    torch [..., V, ...] (leading batch dims = frames) for fitting. Contact planes are those of the body at the
    end of the step; `contact_force` is the normal force magnitude that friction uses, held fixed within a solve:
    prepared from the start state; with SolverOptions.friction_at_end, ImplicitSimulator.solve replaces it by the
    force at its own end state."""

    dt: float
    x_prev: Any            # [V,3] positions at the start of the step
    v_prev: Any            # [V,3] velocities at the start of the step
    pin_target: Any        # [V,3] end positions of pinned vertices (ignored elsewhere)
    contact_active: Any    # [V] float 1/0
    contact_point: Any     # [V,3] closest body point, moved with the body to the end of the step
    contact_normal: Any    # [V,3] outward body normal there
    contact_motion: Any    # [V,3] displacement of that body point over the step
    contact_distance: Any  # [V] signed distance to the body at the start of the step (0 without contact)
    contact_force: Any     # [V] friction's normal force (N), held fixed in the step's potential
    normal_prev: Any       # [V,3] unit cloth vertex normals at the start of the step

    _ARRAYS: ClassVar[tuple[str, ...]] = ("x_prev", "v_prev", "pin_target", "contact_active", "contact_point",
                                          "contact_normal", "contact_motion", "contact_distance", "contact_force",
                                          "normal_prev")

    def to_torch(self) -> "StepInputs":
        return replace(self, **{k: torch.as_tensor(np.asarray(getattr(self, k)), dtype=torch.float64)
                                for k in self._ARRAYS})

    @staticmethod
    def stack(steps: list["StepInputs"]) -> "StepInputs":
        """Batch steps of equal dt into torch tensors with a leading frame dimension."""
        dts = {s.dt for s in steps}
        if len(dts) != 1:
            raise ValueError("steps to batch must share dt")
        return StepInputs(dt=steps[0].dt, **{k: torch.stack([torch.as_tensor(np.asarray(getattr(s, k)),
                                                                              dtype=torch.float64) for s in steps])
                                             for k in StepInputs._ARRAYS})

    @property
    def x_inertial(self) -> Any:
        return self.x_prev + self.dt * self.v_prev


class System:
    """Gradient and block-sparse PSD Hessian of the incremental potential, filled by the terms' assemble()."""

    def __init__(self, num: Numeric) -> None:
        self.num = num
        n, p, f = len(num.mass), len(num.pairs), len(num.faces)
        self.grad = np.zeros((n, 3))
        self.hdiag = np.zeros((n, 3, 3))
        self.hpair = np.zeros((p, 3, 3))
        self.face_dpsi = np.zeros((f, 3))
        self.face_d2psi = np.zeros((f, 3, 3))
        self._face_used = False

    def add_vertex(self, grad: np.ndarray, hess: np.ndarray | None = None, iso: np.ndarray | None = None) -> None:
        """Per-vertex gradient [V,3] with Hessian blocks [V,3,3] and/or an isotropic diagonal [V]."""
        self.grad += grad
        if hess is not None:
            self.hdiag += hess
        if iso is not None:
            idx = np.arange(3)
            self.hdiag[:, idx, idx] += iso[:, None]

    def add_face_q(self, dpsi: np.ndarray | None, d2psi: np.ndarray) -> None:
        """Face energies psi(q) of the squared-edge-length changes q: derivative [F,3] (None if the term already
        added it to `face_dpsi`) and PSD second derivative [F,3,3]; summed over terms, assembled in finalize()."""
        if dpsi is not None:
            self.face_dpsi += dpsi
        self.face_d2psi += d2psi
        self._face_used = True

    def add_edge(self, x: np.ndarray, dphi: np.ndarray, d2phi: np.ndarray) -> None:
        """Edge-length energies phi(l): first and second derivative per edge [E]."""
        kernels.edge_assemble(x, self.num.edges, dphi, d2phi, self.grad, self.hdiag, self.hpair)

    def finalize(self, x: np.ndarray) -> None:
        if self._face_used:
            n = self.num
            kernels.face_q_assemble(x, n.faces, n.face_pairs, self.face_dpsi, self.face_d2psi,
                                    self.grad, self.hdiag, self.hpair)


class Term(ABC):
    """One named contribution to the incremental potential. Subclasses set `name`, `defaults` (parameter name ->
    default value, floats or 3-vectors) and document the physical meaning in their docstring. Scalar parameters
    are magnitudes (a negative damping would feed energy in), so a term refuses negative or non-finite values."""

    name: ClassVar[str]
    defaults: ClassVar[dict[str, Any]] = {}
    limits: ClassVar[dict[str, float]] = {}     # upper physical limits of positive parameters (fits stay below)

    def __init__(self, **params: Any) -> None:
        unknown = set(params) - set(self.defaults)
        if unknown:
            raise ValueError(f"term '{self.name}' has no parameters {sorted(unknown)}; it has {sorted(self.defaults)}")
        self.params: dict[str, torch.Tensor] = {
            k: torch.tensor(params.get(k, v), dtype=torch.float64) for k, v in self.defaults.items()}
        for key, value in self.params.items():
            if not bool(torch.isfinite(value).all()) or (value.ndim == 0 and float(value) < 0.0):
                raise ValueError(f"term '{self.name}' parameter {key}={value.tolist()} is not physical: scalar "
                                 f"parameters are magnitudes (coefficients, stiffnesses, times, margins) and must be "
                                 f"finite and >= 0; vectors (directions, velocities) finite")

    @classmethod
    def meaning(cls) -> str:
        return " ".join((cls.__doc__ or "").split())

    def p(self, key: str) -> np.ndarray | float:
        """Parameter value for the numpy path."""
        value = self.params[key]      # item(): a fifth of detach().numpy()'s cost, called per term per energy
        return value.item() if value.dim() == 0 else value.detach().numpy().astype(np.float64)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "params": {k: v.detach().tolist() for k, v in self.params.items()},
                "meaning": self.meaning()}

    @abstractmethod
    def energy(self, x: torch.Tensor, step: StepInputs, rest: Rest) -> torch.Tensor:
        """Torch energy, summed over vertices/elements: shape = x.shape[:-2]."""

    @abstractmethod
    def assemble(self, x: np.ndarray, step: StepInputs, num: Numeric, system: System | None) -> float:
        """Numpy energy; with a system, also add the gradient and a PSD Hessian approximation to it."""
