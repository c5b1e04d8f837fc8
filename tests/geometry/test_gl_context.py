"""geometry.gl_context: moderngl's EGL context and a program's uniforms, typed."""

from __future__ import annotations

import moderngl

from camdirector.geometry.gl_context import egl_context, uniform

_VERTEX_SHADER = """
#version 330
uniform vec3 u_offset;
in vec3 in_position;
void main() { gl_Position = vec4(in_position + u_offset, 1.0); }
"""
_FRAGMENT_SHADER = """
#version 330
uniform float u_level;
out vec4 f_color;
void main() { f_color = vec4(u_level); }
"""


def test_a_uniform_found_by_name_takes_and_gives_back_its_value():
    ctx = egl_context()
    try:
        program = ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        offset, level = uniform(program, "u_offset"), uniform(program, "u_level")
        assert isinstance(offset, moderngl.Uniform) and isinstance(level, moderngl.Uniform)
        offset.value = (1.0, 2.0, 3.0)
        level.value = 0.5
        assert uniform(program, "u_offset").value == (1.0, 2.0, 3.0)
        assert uniform(program, "u_level").value == 0.5
        program.release()
    finally:
        ctx.release()
