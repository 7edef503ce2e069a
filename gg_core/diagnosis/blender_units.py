"""What a hidden effect of `gg synth` (Blender settings, gg_core/synth/effects.py) means in our simulator's
parameters: the benchmark scores refitted parameters against it, and the own-simulator captures
(resimulated.py) use it to set their hidden terms. Numpy only: the command line imports it at start-up."""
from __future__ import annotations

import numpy as np


def truth_parameters(truth: dict) -> dict[str, float | list[float]]:
    """What the hidden effect means in our parameters, where that is well defined.

    air_drag: Blender's cloth solver applies -0.01 air_damping v per vertex with time in frames and its per-vertex
    mass, i.e. mass damping alpha = 0.01 air_damping fps / vertex_mass (1/s); the diagnosis estimates the total
    (the baseline's default 1/s included). stiff_patch: Blender scales its spring
    stiffnesses, ours the StVK Lame parameters: comparable only approximately. friction: Blender's collision
    response (collision.cc) takes min(0.01 friction v_n, |v_t|) off the tangential velocity where it stops the
    normal approach v_n, i.e. Coulomb mu = 0.01 friction against the collision impulse; ours acts against the
    penalty's normal force, so this too is approximate (the estimate is the total: the baseline's 0.5 included).
    Wind strength has no counterpart in our units and is not scored."""
    effect, params = truth["effect"]["name"], truth["effect"]["params"]
    if effect == "air_drag":
        cloth = truth["material"]["blender_cloth"]
        return {"mass_damping.alpha": 0.01 * float(params["air_damping"]) * float(truth["preset"]["fps"])
                / float(cloth["mass"])}
    if effect == "gravity":
        g = np.array(truth["material"]["gravity"])
        return {"gravity_offset.delta_g": [float(g[0]), float(g[2])]}          # horizontal part (the tilt)
    if effect == "friction":
        return {"body_friction.mu": 0.01 * float(params["friction"])}
    if effect == "shrink":
        return {"region.rest_scale": 1.0 - float(params["factor"])}
    if effect == "stiff_patch":
        factor = float(params["factor"])                                     # Blender springs vs StVK: approx.
        return {"region.stretch_scale": factor, "region.bending_scale": factor}
    return {}
