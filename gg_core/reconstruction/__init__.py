"""Stage 1 geometry on CPU: the garment's surface in one multi-view frame, from silhouettes and a mask vote.

visual_hull (silhouette signed-distance field on a voxel grid) -> isosurface (marching cubes) -> mask_vote
(per-vertex garment vote over the cameras that see a vertex) -> remesh (isotropic, target vertex count) ->
surface_cut (cut along the vote's 0.5 level, keep the main pieces); template_mesh chains them.
"""
