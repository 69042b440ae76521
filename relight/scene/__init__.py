"""Procedural scene content: shapes, textures, materials."""
