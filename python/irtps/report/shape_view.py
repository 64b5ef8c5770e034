"""The report's 3-D view of the shape: the reconstructed surface (and the true one beside it,
when there is ground truth) as triangle meshes drawn by a small WebGL viewer inside the page,
rotatable and zoomable, coloured by albedo or by the normals' angular error. The meshes are
embedded in the page (base64), the viewer is inline: the page stays one file that works
offline.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from html import escape

import numpy as np

from irtps._shared.checks import check_array, check_mask
from irtps.errors import ArgumentError
from irtps.model.camera import Camera
from irtps.report.display import albedo_to_rgb
from irtps.report.figures import ERROR_COLOURS

__all__ = ["MAX_VERTICES", "ShapeMesh", "shape_mesh", "shape_view_html", "surface_colours"]

#: The most vertices a mesh of the view has: the maps are sampled every n-th pixel to stay
#: under it (16-bit indices; a page of a megabyte or two).
MAX_VERTICES = 30000
#: The grey of a mesh without colour of its own (the true surface under the error colours).
GREY = 180


@dataclass(frozen=True)
class ShapeMesh:
    """A mesh of the 3-D view.

    Attributes
    ----------
    name : str
        Its label in the view ("reconstruction", "truth").
    positions : numpy.ndarray
        float32 (N, 3) world points.
    triangles : numpy.ndarray
        uint16 (M, 3) vertex indices, counter-clockwise seen from the camera.
    colours : dict of str to numpy.ndarray
        uint8 (N, 3) sRGB colours by colouring ("albedo", "error").
    """

    name: str
    positions: np.ndarray
    triangles: np.ndarray
    colours: dict[str, np.ndarray]


def shape_mesh(
    name: str,
    camera: Camera,
    height: np.ndarray,
    mask: np.ndarray,
    colours: dict[str, np.ndarray],
    *,
    breaks: np.ndarray | None = None,
) -> ShapeMesh | None:
    """A height map's surface as a mesh for the view: each kept pixel's surface point
    (`irtps.model.camera.Camera.surface_points`, through the pinhole of a perspective camera),
    every n-th pixel so that at most `MAX_VERTICES` are kept, two triangles per 2 x 2 block of
    kept pixels inside the mask.

    Parameters
    ----------
    name : str
    camera : Camera
        The camera the height map was seen by.
    height : numpy.ndarray
        (H, W) heights.
    mask : numpy.ndarray
        (H, W) bool.
    colours : dict of str to numpy.ndarray
        (H, W, 3) sRGB colours in [0, 1] by colouring.
    breaks : numpy.ndarray, optional
        (H, W) bool: pixels at a depth discontinuity; no triangle spans one.

    Returns
    -------
    ShapeMesh or None
        None when no 2 x 2 block of kept pixels lies inside the mask.

    Raises
    ------
    ArgumentError
        Naming the argument: `mask` empty or not (H, W), `height` or `breaks` of another shape.
    """
    mask = check_mask(mask, nonempty=True)
    height = check_array("height", height, mask.shape)
    stride = max(1, int(np.ceil(np.sqrt(mask.sum() / MAX_VERTICES))))
    while mask[::stride, ::stride].sum() > MAX_VERTICES:  # the ceiling above is exact but for rounding
        stride += 1
    points = camera.surface_points(height)[::stride, ::stride]
    kept = mask[::stride, ::stride]
    index = np.full(kept.shape, -1, dtype=np.int64)
    index[kept] = np.arange(int(kept.sum()))
    blocks = kept[:-1, :-1] & kept[1:, :-1] & kept[:-1, 1:] & kept[1:, 1:]
    if breaks is not None:
        blocks &= ~_pooled(check_mask(breaks, mask.shape, name="breaks"), stride, blocks.shape)
    if not blocks.any():
        return None
    top_left, bottom_left = index[:-1, :-1][blocks], index[1:, :-1][blocks]
    top_right, bottom_right = index[:-1, 1:][blocks], index[1:, 1:][blocks]
    triangles = np.concatenate(
        [np.stack([top_left, bottom_left, top_right], axis=1), np.stack([top_right, bottom_left, bottom_right], axis=1)]
    )
    sampled = {key: (np.clip(value[::stride, ::stride][kept], 0, 1) * 255).round() for key, value in colours.items()}
    return ShapeMesh(
        name=name,
        positions=points[kept].astype(np.float32),
        triangles=triangles.astype(np.uint16),
        colours={key: value.astype(np.uint8) for key, value in sampled.items()},
    )


def surface_colours(
    albedo: np.ndarray | None, mask: np.ndarray, error_deg: np.ndarray | None, error_scale_deg: float | None
) -> dict[str, np.ndarray]:
    """A surface's colourings for the view: its albedo as the report shows it (grey without
    one), and its angular error in the report's error colours from 0 to `error_scale_deg`
    (grey without one).

    Parameters
    ----------
    albedo : numpy.ndarray or None
        (H, W, 3) linear RGB.
    mask : numpy.ndarray
        (H, W) bool.
    error_deg : numpy.ndarray or None
        (H, W) angular error in degrees.
    error_scale_deg : float or None
        The error that the top of the colour scale marks.

    Returns
    -------
    dict of str to numpy.ndarray
        ``"albedo"`` and ``"error"``: (H, W, 3) sRGB in [0, 1].
    """
    mask = check_mask(mask, nonempty=True)
    grey = np.full((*mask.shape, 3), GREY / 255.0)
    shown = grey if albedo is None else albedo_to_rgb(albedo, mask)[0]
    error = grey
    if error_deg is not None and error_scale_deg:
        error = ERROR_COLOURS(np.nan_to_num(np.clip(error_deg / error_scale_deg, 0.0, 1.0)))[..., :3]
    return {"albedo": shown, "error": error}


def shape_view_html(meshes: list[ShapeMesh], caption: str) -> str:
    """The view's HTML: a canvas, its controls, the meshes as JSON and the viewer's script.

    Parameters
    ----------
    meshes : list of ShapeMesh
        Drawn side by side, the first at the centre of the view.
    caption : str

    Returns
    -------
    str
        A ``<figure>`` element.

    Raises
    ------
    ArgumentError
        Naming `meshes`: empty, or holding something that is not a `ShapeMesh`.
    """
    if not meshes or not all(isinstance(mesh, ShapeMesh) for mesh in meshes):
        raise ArgumentError("meshes", f"expected a non-empty list of ShapeMesh, got {meshes!r:.60}")
    payload = {
        "meshes": [
            {
                "name": mesh.name,
                "positions": _base64(mesh.positions.astype("<f4")),
                "triangles": _base64(mesh.triangles.astype("<u2")),
                "colours": {key: _base64(value) for key, value in mesh.colours.items()},
            }
            for mesh in meshes
        ]
    }
    data = json.dumps(payload, separators=(",", ":")).replace("</", "<\\/")
    buttons = "".join(
        f'<label><input type="radio" name="irtps-colouring" value="{key}"{" checked" if key == "albedo" else ""}> '
        f"{label}</label> "
        for key, label in (("albedo", "albedo"), ("error", "angular error"))
        if any(key in mesh.colours for mesh in meshes)
    )
    return (
        '<figure class="wide" id="shape-view">'
        '<canvas id="irtps-shape" width="960" height="540" '
        'style="width:100%;max-width:960px;border:1px solid #ccc;touch-action:none"></canvas>'
        f'<div class="controls">Colour: {buttons}<button type="button" id="irtps-shape-reset">the camera\'s view</button> '
        '<button type="button" id="irtps-shape-turned">turned</button></div>'
        f"<figcaption>{escape(caption)}</figcaption>"
        f'<script type="application/json" id="irtps-shape-data">{data}</script>'
        f"<script>{_VIEWER}</script>"
        "</figure>"
    )


def _base64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


def _pooled(flags: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """Per 2 x 2 block of the sampled grid, whether any pixel it spans is flagged."""
    rows, columns = flags.shape
    padded = np.zeros((-(-rows // stride) * stride + stride, -(-columns // stride) * stride + stride), dtype=bool)
    padded[:rows, :columns] = flags
    cells = np.asarray(
        padded.reshape(padded.shape[0] // stride, stride, padded.shape[1] // stride, stride).any(axis=(1, 3))
    )
    spans = cells[:-1, :-1] | cells[1:, :-1] | cells[:-1, 1:] | cells[1:, 1:]
    return spans[: shape[0], : shape[1]]


#: The viewer: WebGL 1, one draw per mesh; drag to turn, wheel or pinch to zoom. It marks the
#: canvas with the triangles drawn (``data-drawn``) once it has drawn them.
_VIEWER = r"""
(() => {
  const canvas = document.getElementById("irtps-shape");
  const gl = canvas.getContext("webgl", {antialias: true, preserveDrawingBuffer: true});
  if (!gl) {
    const note = document.createElement("p");
    note.textContent = "This browser has no WebGL: the 3-D view is not shown.";
    canvas.replaceWith(note);
    return;
  }
  const bytes = (text) => Uint8Array.from(atob(text), (c) => c.charCodeAt(0)).buffer;
  const data = JSON.parse(document.getElementById("irtps-shape-data").textContent);
  const shader = (type, source) => {
    const s = gl.createShader(type); gl.shaderSource(s, source); gl.compileShader(s); return s;
  };
  const program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, `
    attribute vec3 position; attribute vec3 normal; attribute vec3 colour;
    uniform mat4 view; uniform mat4 projection; varying vec3 shade;
    void main() {
      vec3 n = normalize((view * vec4(normal, 0.0)).xyz);
      float light = 0.3 + 0.7 * abs(n.z);
      shade = colour * light;
      gl_Position = projection * view * vec4(position, 1.0);
    }`));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, `
    precision mediump float; varying vec3 shade;
    void main() { gl_FragColor = vec4(shade, 1.0); }`));
  gl.linkProgram(program);
  gl.useProgram(program);
  const low = [Infinity, Infinity, Infinity], high = [-Infinity, -Infinity, -Infinity];
  const meshes = data.meshes.map((mesh) => {
    const p = new Float32Array(bytes(mesh.positions));
    const t = new Uint16Array(bytes(mesh.triangles));
    for (let i = 0; i < p.length; i += 3) for (let a = 0; a < 3; a++) {
      low[a] = Math.min(low[a], p[i + a]); high[a] = Math.max(high[a], p[i + a]);
    }
    const n = new Float32Array(p.length);
    for (let i = 0; i < t.length; i += 3) {
      const [a, b, c] = [t[i] * 3, t[i + 1] * 3, t[i + 2] * 3];
      const u = [p[b] - p[a], p[b + 1] - p[a + 1], p[b + 2] - p[a + 2]];
      const v = [p[c] - p[a], p[c + 1] - p[a + 1], p[c + 2] - p[a + 2]];
      const f = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
      for (const k of [a, b, c]) for (let d = 0; d < 3; d++) n[k + d] += f[d];
    }
    const buffer = (array, target) => {
      const b = gl.createBuffer(); gl.bindBuffer(target, b); gl.bufferData(target, array, gl.STATIC_DRAW); return b;
    };
    const colours = {};
    for (const key in mesh.colours) {
      const c = new Uint8Array(bytes(mesh.colours[key]));
      colours[key] = buffer(Float32Array.from(c, (x) => x / 255), gl.ARRAY_BUFFER);
    }
    return {p: buffer(p, gl.ARRAY_BUFFER), n: buffer(n, gl.ARRAY_BUFFER), t: buffer(t, gl.ELEMENT_ARRAY_BUFFER),
            count: t.length, colours, shift: 0};
  });
  const width = high[0] - low[0];
  meshes.forEach((mesh, k) => { mesh.shift = k * 1.15 * width; });
  const centre = [low[0] + 0.5 * width * (1 + 1.15 * (meshes.length - 1)), 0.5 * (low[1] + high[1]), 0.5 * (low[2] + high[2])];
  const radius = 0.5 * Math.hypot(width * (1 + 1.15 * (meshes.length - 1)), high[1] - low[1], high[2] - low[2]) || 1;
  const start = [0.35, -0.75];  // turned and tilted: the relief shows (the button gives the camera's view)
  let [yaw, pitch] = start, distance = 2.6 * radius, colouring = "albedo";
  const location = (name) => gl.getAttribLocation(program, name);
  const draw = () => {
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(1, 1, 1, 1); gl.enable(gl.DEPTH_TEST); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    const near = Math.max(distance - 2 * radius, distance * 0.01), far = distance + 2 * radius;
    const f = 1 / Math.tan(0.35), aspect = canvas.width / canvas.height;
    gl.uniformMatrix4fv(gl.getUniformLocation(program, "projection"), false,
      [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0]);
    const [cy, sy, cp, sp] = [Math.cos(yaw), Math.sin(yaw), Math.cos(pitch), Math.sin(pitch)];
    let drawn = 0;
    for (const mesh of meshes) {
      const x = -centre[0] + mesh.shift, y = -centre[1], z = -centre[2];
      const tx = cy * x + sy * z, ty = sp * sy * x + cp * y - sp * cy * z, tz = -cp * sy * x + sp * y + cp * cy * z - distance;
      gl.uniformMatrix4fv(gl.getUniformLocation(program, "view"), false,
        [cy, sp * sy, -cp * sy, 0, 0, cp, sp, 0, sy, -sp * cy, cp * cy, 0, tx, ty, tz, 1]);
      for (const [name, b] of [["position", mesh.p], ["normal", mesh.n], ["colour", mesh.colours[colouring] || mesh.colours.albedo]]) {
        gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.enableVertexAttribArray(location(name));
        gl.vertexAttribPointer(location(name), 3, gl.FLOAT, false, 0, 0);
      }
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.t);
      gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_SHORT, 0);
      drawn += mesh.count / 3;
    }
    canvas.dataset.drawn = String(drawn);
  };
  let last = null;
  canvas.addEventListener("pointerdown", (e) => { last = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { last = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!last) return;
    yaw += 0.01 * (e.clientX - last[0]); pitch = Math.max(-1.5, Math.min(1.5, pitch + 0.01 * (e.clientY - last[1])));
    last = [e.clientX, e.clientY]; draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault(); distance = Math.max(0.2 * radius, Math.min(20 * radius, distance * Math.exp(0.001 * e.deltaY))); draw();
  }, {passive: false});
  document.getElementById("irtps-shape-reset").addEventListener("click", () => { yaw = 0; pitch = 0; distance = 2.6 * radius; draw(); });
  document.getElementById("irtps-shape-turned").addEventListener("click", () => { [yaw, pitch] = start; distance = 2.6 * radius; draw(); });
  for (const input of document.querySelectorAll('input[name="irtps-colouring"]')) {
    input.addEventListener("change", () => { colouring = input.value; draw(); });
  }
  draw();
})();
"""
