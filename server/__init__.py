"""Realtime director service."""
