"""Primitive meshes (geometry/meshes.py) stood up along +Y: the portable way (the compiled frame
path's: axes swapped exactly) and the product's (the Python path's, as always) give the same
triangles, the vertices within rounding of each other, and the portable ones exactly the +Z
mesh's turned."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from camdirector.geometry import meshes

PRIMITIVES = {  # how meshes.py makes each (portable or not), and how trimesh makes it along +Z
    "capsule": (
        lambda p: meshes.capsule(0.3, 1.8, portable=p),
        lambda: trimesh.creation.capsule(1.8 - 2.0 * 0.3, 0.3, count=[16, 8]),
    ),
    "cylinder": (lambda p: meshes.cylinder(0.4, 1.2, portable=p), lambda: trimesh.creation.cylinder(0.4, 1.2, sections=24)),
}


@pytest.mark.parametrize("name", PRIMITIVES)
def test_a_portable_primitive_stands_up_exactly_and_as_the_product(name):
    build, made_along_z = PRIMITIVES[name]
    portable, product = build(True), build(False)
    np.testing.assert_array_equal(portable.faces, product.faces)
    np.testing.assert_allclose(portable.vertices, product.vertices, rtol=0, atol=1e-15)
    z_up = made_along_z().vertices
    np.testing.assert_array_equal(portable.vertices, np.stack([z_up[:, 0], z_up[:, 2], -z_up[:, 1]], axis=1))
    assert portable.vertices[:, 1].max() == pytest.approx(-portable.vertices[:, 1].min())  # centred on the origin, along +Y
