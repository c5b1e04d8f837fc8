"""Toric-space visibility maps (S-maps and V-maps) with three interchangeable backends.

Paper: occlusion-anticipation-toric-space.md section 4.1. ``base`` holds the interface (MapWindow,
OccluderScene, ShadowVelocityMaps, the MapBackend protocol); ``gl`` computes the maps by the
paper's deferred projection through EGL (moderngl), ``embree`` by ray casting (embreex), ``native``
by ray casting in camdirector._native (the compiled frame path's: the same bits on every x86-64
machine; `choose_backend` never picks it). Tests hold them against each other
(tests/geometry/toric_maps/test_backends.py).

Typical use, once per map update (pipeline/toric/anticipation_map.py consumes the result)::

    scene = OccluderScene(static_meshes_world)            # plus add_dynamic(...) per moving object
    backend = make_backend(choose_backend(scene.triangle_count, probe_gl_renderer()), scene)
    window = MapWindow.around(torus, theta, phi, WindowSettings(), lattice=previous_window)
    maps = backend.compute(torus, window, sample_points_world, exclude_ids=owners,
                           previous_torus=torus_before, dt_s=dt)
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Unpack

from camdirector.geometry.toric_maps.base import (
    DynamicOccluder,
    MapBackend,
    MapWindow,
    OccluderScene,
    ShadowVelocityMaps,
    WindowSettings,
)

if TYPE_CHECKING:  # gl imports moderngl, which only the "gl" backend needs
    from camdirector.geometry.toric_maps.gl import GLMapSettingsArgs

__all__ = [
    "DynamicOccluder",
    "MapBackend",
    "MapWindow",
    "OccluderScene",
    "ShadowVelocityMaps",
    "WindowSettings",
    "SOFTWARE_RENDERERS",
    "GL_MAX_TRIANGLES_ON_CPU",
    "choose_backend",
    "make_backend",
    "probe_gl_renderer",
]

# GL_RENDERER substrings of software rasterizers: GL runs on the CPU there and competes with Embree.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "lavapipe", "software rasterizer")

# Above this many scene triangles (at 64 x 64 maps), on a software GL renderer, ray casting is the
# faster backend. Measured by `python -m load_tests.maps_bench` on the 2-core CPU machine: see
# choose_backend for the numbers.
GL_MAX_TRIANGLES_ON_CPU = 10_000


def choose_backend(triangle_count: int, renderer_string: str | None, resolution: int = 64) -> str:
    """ "gl" or "embree": the faster backend for a scene of ``triangle_count`` triangles.

    renderer_string: GL_RENDERER of the EGL context (probe_gl_renderer()), None when EGL is
    unavailable. resolution: map texels per side. Rule:

    - no EGL -> embree;
    - a hardware GPU -> gl (DESIGN.md: rasterization is nearly free there);
    - a software rasterizer (llvmpipe) -> gl up to GL_MAX_TRIANGLES_ON_CPU * (resolution / 64)^2
      triangles, embree above. llvmpipe's cost grows with triangles (about 0.12 ms per 1,000 for an
      amortized 2-map update), Embree's with rays and hardly with triangles (about 2 ms per 2 maps
      at 64 x 64 from 800 to 56,000 triangles), hence the crossover grows with the ray count.

    Measured on the 2-core CPU machine (load_tests/maps_bench.py, forest scene with 30 moving
    trees, three runs, other work on the machine): at 64 x 64 the 2-map update (every 0.1 s)
    crosses over between 8,700 and 15,500 triangles (last run: 1.95 vs 2.07 ms at 8,736, 2.27 vs
    2.03 ms at 10,976), a full 10-map refresh (first update, after a cut) between 5,400 and 11,000;
    at 128 x 128 between 56,000 and 110,000 (2 maps) and 29,000 and 56,000 (10 maps), where the
    rule says 40,000. The constant weighs the 2-map update, which is what runs in steady state.

    The hardware branch, measured on an NVIDIA H200 through its own EGL driver (2026-12-04, the same
    benchmark): GL is faster at every size swept, with no crossover. The 2-map update at 64 x 64
    took 0.83-1.10 ms against Embree's 2.5-3.1 ms from 800 to 8,700 triangles; at 128 x 128 it took
    1.5-4.2 ms against 9.7-9.9 ms up to 110,000 triangles. GL's shadows agree with Embree's on 0.9948
    of the texels there, as they do under llvmpipe.
    """
    if not renderer_string:
        return "embree"
    renderer = renderer_string.lower()
    if any(name in renderer for name in SOFTWARE_RENDERERS):
        limit = GL_MAX_TRIANGLES_ON_CPU * (max(int(resolution), 1) / 64.0) ** 2
        return "gl" if triangle_count <= limit else "embree"
    return "gl"


@functools.lru_cache(maxsize=1)
def probe_gl_renderer() -> str | None:
    """GL_RENDERER of an EGL context (created and released once per process), or None without EGL."""
    try:
        from camdirector.geometry.gl_context import egl_context

        ctx = egl_context()
    except Exception:  # no EGL, no driver: the caller falls back to ray casting
        return None
    try:
        return str(ctx.info.get("GL_RENDERER", "")) or None
    finally:
        ctx.release()


def make_backend(name: str, scene: OccluderScene, **settings: Unpack[GLMapSettingsArgs]) -> MapBackend:
    """A backend by name ("gl", "embree" or "native") over ``scene``; keyword settings go to GLMapSettings."""
    if name == "native":
        from camdirector.geometry.toric_maps.native import NativeMapBackend

        return NativeMapBackend(scene)
    if name == "embree":
        from camdirector.geometry.toric_maps.embree import EmbreeMapBackend

        return EmbreeMapBackend(scene)
    if name == "gl":
        from camdirector.geometry.toric_maps.gl import GLMapBackend, GLMapSettings

        return GLMapBackend(scene, GLMapSettings(**settings))
    raise ValueError(f"unknown map backend {name!r} (expected 'gl', 'embree' or 'native')")
