"""Gaussian Garments headless core: capture I/O, Gaussian texture and rasterizer, cloth physics, stages.

Never imports bpy (except the bake and synth workers, which run inside the bpy module) so the
core runs anywhere. Modules reached by the Blender add-on (capture/, geometry/meshio, storage,
diagnosis/report_regions) use numpy and stdlib only (tests/test_architecture.py walks their imports).
"""
__version__ = "0.1.0"

import os as _os

# torch's bundled libgomp and the system libgomp behind numba's parallel kernels are two OpenMP
# runtimes in one process; with the default wait policy each spins for milliseconds after every
# parallel region and steals the cores the other needs (3-5x slower renders measured on 2 cores).
# Only effective before either runtime loads, i.e. when gg_core is imported before torch/numba.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
