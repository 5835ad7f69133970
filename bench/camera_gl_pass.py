"""The Tello camera model's lens, exposure table and noise as one OpenGL pass, against the CPU passes (issue 25).

A GLSL fragment shader in MuJoCo's own context, after the front render: each output pixel fetches its lens-table
index, the render's pixel there, the exposure table's value for each channel and the frame's noise crop, and adds
them modulo 256, as `TelloCamera.frame` does on the CPU. The script checks that the two give the same pixels, then
times the pass (copying the render to a texture, the draw, the read-back) against the CPU's gather, table and
noise, and a trivial pass (one fetch a pixel) for the renderer's floor. On llvmpipe (no GPU) the pass costs about
three times the CPU's, so the camera model keeps its CPU passes; on a GPU the same shader is the route to a cheaper
frame, and this script tells. Prints the machine and the GL renderer.

    .venv/bin/python bench/camera_gl_pass.py [--reps 100] [--smoke]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
from machine import describe, median_ms, publish  # bench/machine.py, beside this script
from PIL import Image, ImageChops

from vlnpilot.sim import SimConfig, Simulator, drone  # selects the headless GL backend before mujoco loads
from vlnpilot.sim.camera_model import TelloCamera
from vlnpilot.sim.gl_readback import read_rgba

OUT = Path(__file__).parent / "results" / "camera_gl_pass.md"
GAIN = 1.13  # an exposure gain the auto-exposure reaches (any value does: the table is the same on both sides)
NOISE_CROP = 3

VERTEX = """#version 330 core
void main() {  // one triangle covering the viewport
    gl_Position = vec4(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID >> 1) * 4 - 1), 0.0, 1.0);
}"""
MODEL = """#version 330 core
uniform sampler2D render; uniform isampler2D lens; uniform usampler2D table; uniform usampler2DArray noise;
uniform int crop; uniform int width;
out uvec4 color;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);  // output row p.y is the frame's row p.y from the top, as the CPU's
    int i = texelFetch(lens, p, 0).r;  // the lens table's index into the bottom-up render
    uvec4 c = uvec4(round(texelFetch(render, ivec2(i % width, i / width), 0) * 255.0));
    uvec4 exposed = uvec4(texelFetch(table, ivec2(c.r, 0), 0).r, texelFetch(table, ivec2(c.g, 0), 0).r,
                          texelFetch(table, ivec2(c.b, 0), 0).r, texelFetch(table, ivec2(c.a, 0), 0).r);
    color = (exposed + texelFetch(noise, ivec3(p, crop), 0)) & 255u;
}"""
COPY = """#version 330 core
uniform sampler2D render; out vec4 color;
void main() { color = texelFetch(render, ivec2(gl_FragCoord.xy), 0); }"""


def texture(gl: Any, unit: int, target: int) -> int:
    name = gl.glGenTextures(1)
    gl.glActiveTexture(gl.GL_TEXTURE0 + unit)
    gl.glBindTexture(target, name)
    for param in (gl.GL_TEXTURE_MIN_FILTER, gl.GL_TEXTURE_MAG_FILTER):
        gl.glTexParameteri(target, param, gl.GL_NEAREST)
    return name


def target(gl: Any, fmt: int, w: int, h: int) -> int:
    """A framebuffer drawing into a renderbuffer of `fmt`."""
    fbo = gl.glGenFramebuffers(1)
    gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, fbo)
    rb = gl.glGenRenderbuffers(1)
    gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, rb)
    gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, fmt, w, h)
    gl.glFramebufferRenderbuffer(gl.GL_FRAMEBUFFER, gl.GL_COLOR_ATTACHMENT0, gl.GL_RENDERBUFFER, rb)
    return fbo


def program(gl: Any, fragment: str, units: dict[str, int]) -> int:
    from OpenGL.GL import shaders

    prog = shaders.compileProgram(shaders.compileShader(VERTEX, gl.GL_VERTEX_SHADER),
                                  shaders.compileShader(fragment, gl.GL_FRAGMENT_SHADER), validate=False)
    gl.glUseProgram(prog)
    for name, unit in units.items():
        gl.glUniform1i(gl.glGetUniformLocation(prog, name), unit)
    return prog


def cpu_passes(camera: TelloCamera, rgba: np.ndarray, table: list[int]) -> Image.Image:
    """`TelloCamera.frame`'s lens, exposure and noise, as it runs them."""
    h, w = rgba.shape[:2]
    lens = np.take(rgba.view(np.uint32).reshape(-1), camera._lens_table(w, h, True))
    img = Image.frombuffer("RGBX", (w, h), lens, "raw", "RGBX", 0, 1).point(table)
    return ImageChops.add_modulo(img, camera._noise[(w, h)][NOISE_CROP])


class ModelPass:
    """The shader and its textures in the renderer's GL context; `run` makes one frame's lens, table and noise."""

    def __init__(self, renderer: Any, camera: TelloCamera, table: np.ndarray):
        import mujoco  # after the simulator chose the headless GL backend
        from OpenGL import GL as gl

        self.gl, self.mujoco, self.renderer, self.table = gl, mujoco, renderer, table
        w, h = self.size = renderer.width, renderer.height
        renderer._gl_context.make_current()
        gl.glDisable(gl.GL_DEPTH_TEST)
        gl.glDisable(gl.GL_BLEND)
        self.tex_render = texture(gl, 0, gl.GL_TEXTURE_2D)
        gl.glTexImage2D(gl.GL_TEXTURE_2D, 0, gl.GL_RGBA8, w, h, 0, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE, None)
        texture(gl, 1, gl.GL_TEXTURE_2D)
        index = np.ascontiguousarray(camera._lens_table(w, h, True).astype(np.int32).reshape(h, w))
        gl.glTexImage2D(gl.GL_TEXTURE_2D, 0, gl.GL_R32I, w, h, 0, gl.GL_RED_INTEGER, gl.GL_INT, index)
        self.tex_table = texture(gl, 2, gl.GL_TEXTURE_2D)
        gl.glTexImage2D(gl.GL_TEXTURE_2D, 0, gl.GL_R8UI, 256, 1, 0, gl.GL_RED_INTEGER, gl.GL_UNSIGNED_BYTE, table)
        texture(gl, 3, gl.GL_TEXTURE_2D_ARRAY)
        crops = np.stack([np.frombuffer(c.tobytes(), np.uint8).reshape(h, w, 4) for c in camera._noise[(w, h)]])
        gl.glTexImage3D(gl.GL_TEXTURE_2D_ARRAY, 0, gl.GL_RGBA8UI, w, h, len(crops), 0, gl.GL_RGBA_INTEGER,
                        gl.GL_UNSIGNED_BYTE, crops)
        self.fbo_model, self.fbo_copy = target(gl, gl.GL_RGBA8UI, w, h), target(gl, gl.GL_RGBA8, w, h)
        self.prog_copy = program(gl, COPY, {"render": 0})
        self.prog_model = program(gl, MODEL, {"render": 0, "lens": 1, "table": 2, "noise": 3})
        gl.glUniform1i(gl.glGetUniformLocation(self.prog_model, "crop"), NOISE_CROP)
        gl.glUniform1i(gl.glGetUniformLocation(self.prog_model, "width"), w)
        self.vao = gl.glGenVertexArrays(1)
        self.out = np.empty((h, w, 4), np.uint8)

    def run(self) -> np.ndarray:
        """Copy the render to a texture, draw the model, read it back (integer RGBA, top row first)."""
        gl, (w, h) = self.gl, self.size
        self.mujoco.mjr_setBuffer(self.mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.renderer._mjr_context)
        gl.glActiveTexture(gl.GL_TEXTURE0)
        gl.glBindTexture(gl.GL_TEXTURE_2D, self.tex_render)
        gl.glCopyTexSubImage2D(gl.GL_TEXTURE_2D, 0, 0, 0, 0, 0, w, h)
        gl.glActiveTexture(gl.GL_TEXTURE2)
        gl.glBindTexture(gl.GL_TEXTURE_2D, self.tex_table)  # this frame's table
        gl.glTexSubImage2D(gl.GL_TEXTURE_2D, 0, 0, 0, 256, 1, gl.GL_RED_INTEGER, gl.GL_UNSIGNED_BYTE, self.table)
        self._draw(self.fbo_model, self.prog_model)
        gl.glReadPixels(0, 0, w, h, gl.GL_RGBA_INTEGER, gl.GL_UNSIGNED_BYTE, self.out)
        return self.out

    def run_trivial(self) -> None:
        """The renderer's floor: one fetch a pixel, finished, nothing read back."""
        self.gl.glActiveTexture(self.gl.GL_TEXTURE0)
        self.gl.glBindTexture(self.gl.GL_TEXTURE_2D, self.tex_render)
        self._draw(self.fbo_copy, self.prog_copy)
        self.gl.glFinish()

    def _draw(self, fbo: int, prog: int) -> None:
        gl = self.gl
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, fbo)
        gl.glViewport(0, 0, *self.size)
        gl.glUseProgram(prog)
        gl.glBindVertexArray(self.vao)
        gl.glDrawArrays(gl.GL_TRIANGLES, 0, 3)

    def close(self) -> None:
        self.gl.glUseProgram(0)
        self.gl.glBindFramebuffer(self.gl.GL_FRAMEBUFFER, 0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=100, help="timed repetitions of each")
    parser.add_argument("--smoke", action="store_true", help="3 repetitions (for the tests)")
    args = parser.parse_args()
    reps = 3 if args.smoke else args.reps
    with Simulator("cabin", SimConfig(rear_camera=False, camera="tello")) as sim:
        sim.reset()
        r = sim._renderer(sim.config.width, sim.config.height)
        sim._update_view(r, drone.FRONT_CAMERA)
        render = read_rgba(r, sim.model)
        if render is None:
            print("this GL platform gives no read-back to build the pass on", file=sys.stderr)
            return 2
        camera = TelloCamera()
        camera.reset(1)
        camera.frame(render)  # its lens table and noise crops
        lut = np.clip(np.rint(np.arange(256) * GAIN), camera.NOISE_MAX, 255 - camera.NOISE_MAX).astype(np.uint8)
        expected = np.asarray(cpu_passes(camera, render.rgba, lut.tolist() * 4))[..., :3]  # RGBX: the X unused
        shader = ModelPass(r, camera, lut)
        same = np.array_equal(shader.run()[..., :3], expected)
        timings = {"CPU passes (gather, table, noise)":
                   median_ms(lambda: cpu_passes(camera, render.rgba, lut.tolist() * 4), reps),
                   "OpenGL pass (copy, draw, read-back)": median_ms(shader.run, reps),
                   "OpenGL trivial pass (one fetch a pixel, no read-back)": median_ms(shader.run_trivial, reps)}
        renderer_name = shader.gl.glGetString(shader.gl.GL_RENDERER).decode()
        shader.close()
    w, h = render.rgba.shape[1], render.rgba.shape[0]
    lines = ["# The camera model's lens, table and noise as an OpenGL pass", "",
             f"Machine: {describe()}. GL renderer: {renderer_name}. {w}x{h}, median of {reps}.", "",
             f"Same pixels as the CPU passes: {'yes' if same else 'NO'}.", "", "| pass | median, ms |", "|---|---|"]
    lines += [f"| {name} | {ms:.2f} |" for name, ms in timings.items()]
    publish("\n".join(lines) + "\n", OUT, smoke=args.smoke)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
