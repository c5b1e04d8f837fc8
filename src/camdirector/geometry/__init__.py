"""Shared low-level geometry: meshes, transforms, Toric math, ray casting, rendering."""
