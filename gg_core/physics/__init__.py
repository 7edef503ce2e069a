"""Differentiable cloth physics: energies, force library, implicit simulator, material fitting.

The incremental potential of one implicit-Euler step is a sum of named terms. Each term has a torch energy
(differentiable in positions and parameters: fitting, diagnosis) and a fast numpy/numba path that adds its
gradient and a positive semi-definite Hessian approximation to the solver's block-sparse system.

- material.py  HOOD's per-vertex material values, defaults, ranges, latent mapping
- cloth.py     a garment's rest state (rest lengths, 2D rest shapes, masses, hinges) and material
- terms.py     the Term contract, per-step inputs (StepInputs), the solver's assembly buffers (System)
- energies.py  base terms: inertia, gravity, StVK stretching, dihedral bending, body collision
- forces.py    the force library (friction, drag, wind, damping, anisotropy, ...) and the term registry
- kernels.py   numba kernels: element assembly, Gauss-Seidel preconditioned CG
- solver.py    Newton minimization of one step
- contact.py   closest points on the posed body, contact planes, penetration statistics
- simulator.py the Simulator interface (step, rollout) and the implicit simulator
- fitting.py   teacher-forced implicit-differentiation fitting of material, rest lengths, term parameters
- blender_cloth.py  Blender's cloth modifier as a reference simulator (bpy subprocess worker)
"""
