"""Photometric fitting of a mesh-bound Gaussian garment to multi-view images (stages 1 and 2).

views         View (camera, image, masks, body occluder) and load_views for one frame of a sequence
photometric   SSIM, L_rgb over the loss mask (garment + background), renders with body occlusion
appearance    fit_appearance: Gaussian parameters on a frozen mesh (stage 1's initial appearance), and a
              coarser texture for registration (downsample_texture)
losses        geometric terms of registration: bending, StVK strain, body collision, virtual edges
icp           first-frame alignment: rigid motion of the body under the garment, (scaled) ICP
smooth_param  the smooth vertex parameterization the tracker optimizes ("large steps")
tracker       per-frame optimization of the vertex positions (stage 2)
stereo        multi-view stereo after each frame's fit: the photo-consistency sweep from the fitted mesh
"""
import os

# numba's OpenMP workers (the CPU rasterizer's threading layer) spin-wait after every parallel region and starve
# the torch ops that run between two rasterizer calls: measured 420 ms vs 30 ms per fitting iteration on the tiny
# capture (2 cores). Sleeping workers cost nothing measurable. Must be set before numba's first parallel call.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
