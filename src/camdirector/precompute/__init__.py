"""Offline computations (camera tracks, motion overview)."""
