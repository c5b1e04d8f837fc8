"""moderngl as the geometry package uses it, typed where its stub is wrong or wider than our use.

`egl_context()`: a standalone GL context through EGL, which needs no X display (Mesa's llvmpipe on
machines without a GPU, the GPU's driver where there is one). `uniform(program, name)`: one of a
program's plain uniforms by name.
"""

from __future__ import annotations

from typing import cast

import moderngl


def egl_context() -> moderngl.Context:
    """A new standalone EGL context; raises what moderngl raises where EGL or a driver is missing."""
    # moderngl's stub annotates **settings as Dict[str, Any] where each setting is a plain value.
    return moderngl.create_standalone_context(backend="egl")  # type: ignore[arg-type]


def uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    """The plain uniform `name` of `program`. moderngl types a member lookup as any kind of member
    (uniform, uniform block, attribute, varying); the kind is the shader's, and callers name plain
    uniforms."""
    return cast(moderngl.Uniform, program[name])
