"""Procedural scene content: shapes, textures, materials."""

__all__ = [
    "albedo", "blender", "bsdf", "build", "noise", "shapes", "spec", "textures",
]
