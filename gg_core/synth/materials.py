"""Blender shader node trees for the garment (procedural, UV-bound fabric patterns), the skin and the studio.

Runs inside the bpy worker only. Patterns live in UV space so they move with the cloth: the
registration and appearance stages get real texture to track, at a scale of millimetres to centimetres.
"""
from __future__ import annotations

import bpy

from .fabrics import Look


class _Graph:
    """Small helper that creates and links nodes of one material."""

    def __init__(self, name: str) -> None:
        self.material = bpy.data.materials.new(name)
        self.material.use_nodes = True
        self.tree = self.material.node_tree
        self.bsdf = self.tree.nodes["Principled BSDF"]

    def node(self, kind: str, **inputs: object) -> bpy.types.Node:
        node = self.tree.nodes.new(kind)
        for key, value in inputs.items():
            if isinstance(value, bpy.types.NodeSocket):
                self.tree.links.new(value, node.inputs[key])
            else:
                node.inputs[key].default_value = value
        return node

    def link(self, output: bpy.types.NodeSocket, socket: bpy.types.NodeSocket) -> None:
        self.tree.links.new(output, socket)

    def mix(self, factor: bpy.types.NodeSocket, a: object, b: object) -> bpy.types.NodeSocket:
        node = self.tree.nodes.new("ShaderNodeMix")
        node.data_type = "RGBA"
        sockets = {s.identifier: s for s in node.inputs}
        self.link(factor, sockets["Factor_Float"])
        for ident, value in (("A_Color", a), ("B_Color", b)):
            if isinstance(value, bpy.types.NodeSocket):
                self.link(value, sockets[ident])
            else:
                sockets[ident].default_value = (*value, 1.0)
        return next(s for s in node.outputs if s.identifier == "Result_Color")

    def math(self, op: str, a: object, b: object) -> bpy.types.NodeSocket:
        node = self.tree.nodes.new("ShaderNodeMath")
        node.operation = op
        for i, value in enumerate((a, b)):
            if isinstance(value, bpy.types.NodeSocket):
                self.link(value, node.inputs[i])
            else:
                node.inputs[i].default_value = value
        return node.outputs[0]


def fabric_material(look: Look, uv_scale: float) -> bpy.types.Material:
    """Principled BSDF with a pattern at `look.repeats_per_metre` (UVs are metres divided by `uv_scale`)."""
    g = _Graph(f"fabric_{look.pattern}")
    uv = g.node("ShaderNodeTexCoord").outputs["UV"]
    scale = look.repeats_per_metre * uv_scale
    base, accent = tuple(look.base_color), tuple(look.accent_color)
    dark = tuple(0.55 * c for c in base)
    if look.pattern == "print":
        dots = g.node("ShaderNodeTexVoronoi", Vector=uv, Scale=scale, Randomness=0.6).outputs["Distance"]
        dot_mask = g.math("LESS_THAN", dots, 0.28)
        stripes = g.node("ShaderNodeTexWave", Vector=uv, Scale=scale * 0.35, Distortion=0.0)
        stripes.bands_direction = "DIAGONAL"
        stripe_mask = g.math("GREATER_THAN", stripes.outputs["Factor"], 0.85)
        color = g.mix(stripe_mask, g.mix(dot_mask, base, accent), dark)
        height = g.math("MAXIMUM", dot_mask, stripe_mask)
    elif look.pattern == "weave":
        warp = g.node("ShaderNodeTexWave", Vector=uv, Scale=scale, Distortion=0.6)
        weft = g.node("ShaderNodeTexWave", Vector=uv, Scale=scale, Distortion=0.6)
        warp.bands_direction, weft.bands_direction = "X", "Y"
        over = g.node("ShaderNodeTexChecker", Vector=uv, Scale=scale * 2).outputs["Factor"]
        height = g.math("ADD", g.math("MULTIPLY", warp.outputs["Factor"], over),
                        g.math("MULTIPLY", weft.outputs["Factor"], g.math("SUBTRACT", 1.0, over)))
        color = g.mix(height, g.mix(over, dark, tuple(0.6 * c for c in accent)), g.mix(over, base, accent))
    else:  # fuzzy: fibre noise in colour and relief, plus sheen for the soft rim of fur and fleece
        fibres = g.node("ShaderNodeTexNoise", Vector=uv, Scale=scale, Detail=15.0, Roughness=0.75)
        clumps = g.node("ShaderNodeTexNoise", Vector=uv, Scale=scale * 0.15, Detail=4.0)
        color = g.mix(g.math("POWER", clumps.outputs["Fac"], 3.0), g.mix(fibres.outputs["Fac"], dark, base),
                      accent)
        height = fibres.outputs["Fac"]
        g.bsdf.inputs["Sheen Roughness"].default_value = 0.6
        g.link(color, g.bsdf.inputs["Sheen Tint"])
    bump = g.node("ShaderNodeBump", Height=height, Strength=0.6 if look.pattern == "fuzzy" else 0.25,
                  Distance=0.002)
    g.link(color, g.bsdf.inputs["Base Color"])
    g.link(bump.outputs["Normal"], g.bsdf.inputs["Normal"])
    g.bsdf.inputs["Roughness"].default_value = look.roughness
    g.bsdf.inputs["Sheen Weight"].default_value = look.sheen
    g.bsdf.inputs["Specular IOR Level"].default_value = 0.45
    return g.material


def plain_material(name: str, color: tuple[float, float, float], roughness: float,
                   specular: float = 0.5) -> bpy.types.Material:
    g = _Graph(name)
    g.bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    g.bsdf.inputs["Roughness"].default_value = roughness
    g.bsdf.inputs["Specular IOR Level"].default_value = specular
    return g.material
