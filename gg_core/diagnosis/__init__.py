"""Missing-physics diagnosis: residual forces of the fitted simulator on observed motion, where and when they
appear, which physically named force explains them, and proof on held-out sequences (REFERENCE.md §6)."""
