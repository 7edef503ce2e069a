"""Smooth reparameterization of vertex positions for gradient-based mesh fitting ("large steps").

Nicolet, Jacobson and Jakob, "Large Steps in Inverse Rendering of Geometry" (SIGGRAPH Asia 2021): optimize
u = (I + lam L) x instead of the vertices x, with L the mesh's combinatorial graph Laplacian. An optimizer
step on u moves x by (I + lam L)^-1 times the step, which spreads each vertex's gradient over its
neighbourhood: photometric gradients on a few pixels become smooth deformations instead of noisy per-vertex
jitter, and the fit can take large steps without tangling the mesh. lam = 0 is the plain vertex fit.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import splu

from ..geometry.topology import build_topology


def smoothing_matrix(faces: np.ndarray, n_vertices: int, lam: float) -> sp.csc_matrix:
    """I + lam (D - A) over the mesh edges (symmetric positive definite for lam >= 0)."""
    edges = build_topology(faces, n_vertices).edges
    i, j = np.concatenate((edges[:, 0], edges[:, 1])), np.concatenate((edges[:, 1], edges[:, 0]))
    adjacency = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return (sp.identity(n_vertices) + lam * (sp.diags(degree) - adjacency)).tocsc()


class SmoothParam:
    """x = (I + lam L)^-1 u, differentiable in u (the system is symmetric: the backward pass is the same solve)."""

    def __init__(self, faces: np.ndarray, n_vertices: int, lam: float) -> None:
        self.lam = float(lam)
        self.matrix = smoothing_matrix(faces, n_vertices, self.lam)
        self.solver = splu(self.matrix)

    def encode(self, x: np.ndarray) -> np.ndarray:
        """u of vertex positions x [V, 3]."""
        return self.matrix @ np.asarray(x, np.float64)

    def decode(self, u: torch.Tensor) -> torch.Tensor:
        """Vertex positions [V, 3] of the parameters u [V, 3]."""
        return _Solve.apply(u, self.solver)


class UniformAdam(torch.optim.Optimizer):
    """Adam whose second moment is one scalar per tensor (the max over its entries), as Nicolet et al. use with
    the smooth parameterization: a vertex with a weak, noisy gradient then moves little, where per-entry Adam
    would normalize its noise up to a full-size step."""

    def __init__(self, params, lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        super().__init__(params, {"lr": lr, "betas": betas, "eps": eps})

    @torch.no_grad()
    def step(self, closure=None):
        for group in self.param_groups:
            b1, b2 = group["betas"]
            for p in group["params"]:
                if p.grad is None:
                    continue
                state = self.state[p]
                if not state:
                    state["step"], state["m"], state["v"] = 0, torch.zeros_like(p), p.new_zeros(())
                state["step"] += 1
                state["m"].mul_(b1).add_(p.grad, alpha=1 - b1)
                state["v"].mul_(b2).add_(p.grad.square().max(), alpha=1 - b2)
                m_hat = state["m"] / (1 - b1 ** state["step"])
                v_hat = state["v"] / (1 - b2 ** state["step"])
                p.sub_(group["lr"] * m_hat / (v_hat.sqrt() + group["eps"]))


class _Solve(torch.autograd.Function):
    @staticmethod
    def forward(ctx, u: torch.Tensor, solver) -> torch.Tensor:
        ctx.solver = solver
        return torch.from_numpy(solver.solve(u.detach().double().numpy())).to(u.dtype)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        return torch.from_numpy(ctx.solver.solve(grad.detach().double().numpy())).to(grad.dtype), None
