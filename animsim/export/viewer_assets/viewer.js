// animsim viewer: plays the animation embedded in this page with WebGL 2, offline.
// Nothing here fetches anything: the data sits in the JSON block above, arrays as
// base64 (zlib-compressed where it pays), decoded with the browser's own
// DecompressionStream.
"use strict";
(function () {
  const root = document.getElementById("animsim-root");
  const errorBox = document.getElementById("as-error");
  const api = { ready: false, errors: [], panels: 0, frameCount: 0 };
  window.animsimViewer = api;

  function fail(message) {
    api.errors.push(String(message));
    errorBox.textContent = "animsim viewer: " + message;
  }

  // ---------------------------------------------------------------- decoding

  function base64Bytes(text) {
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  async function inflate(bytes) {
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  const TYPED = { u8: Uint8Array, u16: Uint16Array, u32: Uint32Array, f32: Float32Array, f64: Float64Array };

  async function decode(desc) {
    if (!desc) return null;
    let bytes = base64Bytes(desc.b64);
    if (desc.z) bytes = await inflate(bytes);
    const copy = bytes.slice().buffer; // aligned for every element size
    return new TYPED[desc.dtype](copy);
  }

  // Dead particles get this coordinate; the shaders drop such points.
  const DEAD = 1e30;
  const QUANT_DEAD = 65535;
  const QUANT_MAX = 65534;

  // Undo the Python side's delta_shuffle: low bytes, then high bytes, of frame-to-frame differences.
  function unshuffleDeltas(bytes, frames) {
    const count = bytes.length / 2;
    const q = new Uint16Array(count);
    for (let i = 0; i < count; i++) q[i] = bytes[i] | (bytes[count + i] << 8);
    const stride = frames ? count / frames : 0;
    for (let i = stride; i < count; i++) q[i] = (q[i] + q[i - stride]) & 0xffff;
    return q;
  }

  async function decodePositions(desc, frames) {
    const raw = await decode(desc);
    const q = desc.enc === "delta16" ? unshuffleDeltas(raw, frames) : raw;
    const lo = desc.lo, hi = desc.hi;
    const out = new Float32Array(q.length);
    const scale = [0, 1, 2].map((a) => (hi[a] - lo[a]) / QUANT_MAX);
    for (let i = 0; i < q.length; i += 3) {
      if (q[i] === QUANT_DEAD) {
        out[i] = DEAD; out[i + 1] = DEAD; out[i + 2] = DEAD;
      } else {
        out[i] = lo[0] + q[i] * scale[0];
        out[i + 1] = lo[1] + q[i + 1] * scale[1];
        out[i + 2] = lo[2] + q[i + 2] * scale[2];
      }
    }
    return out;
  }

  // ------------------------------------------------------------------ matrices (column-major)

  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
  function scale3(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }

  function mul(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++)
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
        o[c * 4 + r] = s;
      }
    return o;
  }

  function lookAt(eye, target, up) {
    const f = norm(sub(target, eye));
    const s = norm(cross(f, up));
    const u = cross(s, f);
    return new Float32Array([
      s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
      -dot(s, eye), -dot(u, eye), dot(f, eye), 1,
    ]);
  }

  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2);
    return new Float32Array([
      f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, (2 * far * near) / (near - far), 0,
    ]);
  }

  function ortho(halfW, halfH, near, far) {
    return new Float32Array([
      1 / halfW, 0, 0, 0, 0, 1 / halfH, 0, 0, 0, 0, -2 / (far - near), 0, 0, 0, -(far + near) / (far - near), 1,
    ]);
  }

  // Rigid transform from a position and a unit quaternion [w, x, y, z].
  function model(p, q) {
    const w = q[0], x = q[1], y = q[2], z = q[3];
    return new Float32Array([
      1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y), 0,
      2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x), 0,
      2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y), 0,
      p[0], p[1], p[2], 1,
    ]);
  }

  // ------------------------------------------------------------------ shape geometry (local frame)

  function circle(out, a, b, r, c, segs) {
    // A circle of radius r in the plane spanned by unit axes a, b, centred at c: as line segments.
    for (let i = 0; i < segs; i++) {
      const t0 = (2 * Math.PI * i) / segs, t1 = (2 * Math.PI * (i + 1)) / segs;
      out.push(...add(c, add(scale3(a, r * Math.cos(t0)), scale3(b, r * Math.sin(t0)))));
      out.push(...add(c, add(scale3(a, r * Math.cos(t1)), scale3(b, r * Math.sin(t1)))));
    }
  }

  const X = [1, 0, 0], Y = [0, 1, 0], Z = [0, 0, 1], O = [0, 0, 0];

  function sphereLines(r) {
    const out = [];
    circle(out, X, Z, r, O, 48);
    circle(out, X, Y, r, O, 48);
    circle(out, Y, Z, r, O, 48);
    for (const h of [-0.6, 0.6]) circle(out, X, Z, r * Math.sqrt(1 - h * h), [0, r * h, 0], 32);
    return out;
  }

  function boxLines(h) {
    const out = [];
    const corner = (i) => [(i & 1 ? 1 : -1) * h[0], (i & 2 ? 1 : -1) * h[1], (i & 4 ? 1 : -1) * h[2]];
    for (let i = 0; i < 8; i++)
      for (const bit of [1, 2, 4]) if (!(i & bit)) out.push(...corner(i), ...corner(i | bit));
    return out;
  }

  function boxTriangles(h) {
    const out = [];
    const faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    const corner = (i) => [(i & 1 ? 1 : -1) * h[0], (i & 2 ? 1 : -1) * h[1], (i & 4 ? 1 : -1) * h[2]];
    for (const f of faces) out.push(...corner(f[0]), ...corner(f[1]), ...corner(f[2]), ...corner(f[0]), ...corner(f[2]), ...corner(f[3]));
    return out;
  }

  function capsuleLines(r, half) {
    // Axis along local y: two rings at the cylinder's ends, four side lines, and the two caps' arcs.
    const out = [];
    circle(out, X, Z, r, [0, half, 0], 40);
    circle(out, X, Z, r, [0, -half, 0], 40);
    for (const a of [X, Z, scale3(X, -1), scale3(Z, -1)]) out.push(...scale3(a, r).map((v, i) => v + [0, half, 0][i]), ...scale3(a, r).map((v, i) => v + [0, -half, 0][i]));
    const segs = 16;
    for (const a of [X, Z]) {
      for (const sgn of [1, -1]) {
        for (let i = 0; i < segs; i++) {
          const t0 = (Math.PI * i) / segs, t1 = (Math.PI * (i + 1)) / segs;
          const p = (t) => add(add(scale3(a, r * Math.cos(t)), scale3(Y, sgn * r * Math.sin(t))), [0, sgn * half, 0]);
          out.push(...p(t0), ...p(t1));
        }
      }
    }
    return out;
  }

  function niceStep(x) {
    const p = Math.pow(10, Math.floor(Math.log10(x)));
    for (const m of [1, 2, 5, 10]) if (m * p >= x) return m * p;
    return 10 * p;
  }

  // A plane as a finite grid, centred where the scene's centre projects onto it.
  function planeGeometry(shape, centre, radius) {
    const n = norm(shape.normal);
    const helper = Math.abs(n[0]) < 0.9 ? X : Y;
    const u = norm(cross(n, helper)), v = cross(n, u);
    const c0 = sub(centre, scale3(n, dot(sub(centre, shape.point), n)));
    const ext = 1.6 * radius;
    const step = niceStep(ext / 6);
    const k = Math.ceil(ext / step);
    const lines = [];
    for (let i = -k; i <= k; i++) {
      lines.push(...add(c0, add(scale3(u, i * step), scale3(v, -k * step))), ...add(c0, add(scale3(u, i * step), scale3(v, k * step))));
      lines.push(...add(c0, add(scale3(v, i * step), scale3(u, -k * step))), ...add(c0, add(scale3(v, i * step), scale3(u, k * step))));
    }
    const e = k * step;
    const q = (a, b) => add(c0, add(scale3(u, a), scale3(v, b)));
    const tris = [...q(-e, -e), ...q(e, -e), ...q(e, e), ...q(-e, -e), ...q(e, e), ...q(-e, e)];
    return { lines, tris };
  }

  // ------------------------------------------------------------------ GL programs

  const POINT_VS = `#version 300 es
in vec3 a_pos; in vec4 a_col; in float a_size; in float a_pin;
uniform mat4 u_mvp; uniform float u_pxScale; uniform float u_defPx;
out vec4 v_col; out float v_pin; out float v_px;
void main() {
  v_col = a_col; v_pin = a_pin; v_px = 1.0;
  if (abs(a_pos.x) > 1e29) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 0.0; return; }
  gl_Position = u_mvp * vec4(a_pos, 1.0);
  float s = (a_size > 0.0) ? a_size * u_pxScale / gl_Position.w : u_defPx;
  if (a_pin > 0.5) s = max(s, 1.8 * u_defPx);
  gl_PointSize = clamp(s, 2.0, 96.0);
  v_px = gl_PointSize;
}`;
  const POINT_FS = `#version 300 es
precision mediump float;
in vec4 v_col; in float v_pin; in float v_px; out vec4 o;
void main() {
  vec2 d = gl_PointCoord * 2.0 - 1.0;
  float r2 = dot(d, d);
  if (v_pin > 0.5) {
    // Pinned: a square with an orange rim, so it reads as fixed even among many dots.
    float m = max(abs(d.x), abs(d.y));
    o = m > 0.6 ? vec4(1.0, 0.62, 0.1, 1.0) : vec4(v_col.rgb * 0.7, 1.0);
    return;
  }
  if (r2 > 1.0) discard;
  // Coverage falls off over the last pixel of the radius: a round edge without multisampling.
  float edge = clamp((1.0 - sqrt(r2)) * 0.5 * v_px, 0.0, 1.0);
  o = vec4(v_col.rgb * (1.0 - 0.3 * r2), v_col.a * edge);
}`;
  const LINE_VS = `#version 300 es
in vec3 a_pos; uniform mat4 u_mvp;
void main() {
  if (abs(a_pos.x) > 1e29) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); return; }
  gl_Position = u_mvp * vec4(a_pos, 1.0);
}`;
  const LINE_FS = `#version 300 es
precision mediump float; uniform vec4 u_col; out vec4 o;
void main() { o = u_col; }`;

  function isSoftware(gl) {
    const info = gl.getExtension("WEBGL_debug_renderer_info");
    const name = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : String(gl.getParameter(gl.RENDERER));
    return /swiftshader|llvmpipe|softpipe|software/i.test(name);
  }

  function compile(gl, vs, fs) {
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
      gl.attachShader(prog, sh);
    }
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
    const loc = (n) => gl.getUniformLocation(prog, n);
    const attr = (n) => gl.getAttribLocation(prog, n);
    return { prog, loc, attr };
  }

  // ------------------------------------------------------------------ camera (shared by every panel)

  const camera = { view: "3d", az: 30, el: 20, zoom: 1, pan: [0, 0, 0] };
  let world = { centre: [0, 0, 0], radius: 1, up: [0, 1, 0], upName: "y" };

  function cameraMatrix(aspect) {
    const c = add(world.centre, camera.pan);
    const R = world.radius;
    if (camera.view === "3d") {
      const az = (camera.az * Math.PI) / 180, el = (camera.el * Math.PI) / 180;
      const up = world.up;
      // Horizontal axes: x and the third axis (z for y-up, -y for z-up), so azimuth 0 looks along -z / +y.
      const h1 = X, h2 = world.upName === "z" ? [0, -1, 0] : Z;
      const dir = add(add(scale3(h1, Math.cos(el) * Math.sin(az)), scale3(h2, Math.cos(el) * Math.cos(az))), scale3(up, Math.sin(el)));
      const fov = (35 * Math.PI) / 180;
      const dist = (0.75 * R / Math.sin(fov / 2)) / camera.zoom; // the bounding sphere is loose: frame a little tighter
      const eye = add(c, scale3(dir, dist));
      const proj = perspective(fov, aspect, Math.max(dist - 4 * R, dist * 1e-3), dist + 4 * R);
      return { mvp: mul(proj, lookAt(eye, c, up)), proj };
    }
    // Each flat view looks from the positive side of its third axis, the first axis to the
    // right and the second up (as `animsim render` draws them). For xz and zy that is a mirror
    // image (looking down +y with z up puts x to the left; looking down -x with y up puts z to
    // the left), so their first axis is flipped back.
    const setup = { xy: [Z, Y, 1], xz: [Y, Z, -1], yz: [X, Z, 1], zy: [X, Y, -1] }[camera.view];
    const eye = add(c, scale3(setup[0], 3 * R));
    const half = (1.08 * R) / camera.zoom;
    const proj = ortho(half * Math.max(aspect, 1), half / Math.min(aspect, 1), 0.01 * R, 6 * R);
    const mirror = new Float32Array([setup[2], 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
    return { mvp: mul(mul(mirror, proj), lookAt(eye, c, setup[1])), proj };
  }

  // Screen drag -> world pan, in the plane facing the camera.
  function panBy(dx, dy, height) {
    let right, up;
    if (camera.view === "3d") {
      const az = (camera.az * Math.PI) / 180, el = (camera.el * Math.PI) / 180;
      const h1 = X, h2 = world.upName === "z" ? [0, -1, 0] : Z;
      const dir = add(add(scale3(h1, Math.cos(el) * Math.sin(az)), scale3(h2, Math.cos(el) * Math.cos(az))), scale3(world.up, Math.sin(el)));
      right = norm(cross(scale3(dir, -1), world.up));
      up = cross(right, scale3(dir, -1));
    } else {
      const setup = { xy: [X, Y], xz: [X, Z], yz: [Y, Z], zy: [Z, Y] }[camera.view];
      right = setup[0]; up = setup[1];
    }
    const metresPerPx = (2.16 * world.radius) / camera.zoom / height;
    camera.pan = add(camera.pan, add(scale3(right, -dx * metresPerPx), scale3(up, dy * metresPerPx)));
  }

  // ------------------------------------------------------------------ panels

  const SPRING_COL = [0.6, 0.6, 0.6, 1.0];
  const DEFAULT_COL = [0.2, 0.6, 1.0, 1.0];
  const PLANE_LINE = [0.42, 0.42, 0.42, 1.0];
  const PLANE_FILL = [0.35, 0.35, 0.35, 0.25];
  const SHAPE_LINE = [0.85, 0.75, 0.45, 1.0];

  class Panel {
    constructor(data, index, container) {
      this.data = data;
      this.index = index;
      this.times = Float64Array.from(data.times);
      this.frames = this.times.length;
      this.n = data.n;
      const el = document.createElement("div");
      el.className = "as-panel";
      el.dataset.panel = String(index);
      el.innerHTML = '<canvas class="as-gl"></canvas><div class="as-label"></div><div class="as-mark"></div><canvas class="as-energy"></canvas><div class="as-cursor"></div><div class="as-evalue"></div>';
      container.appendChild(el);
      this.el = el;
      this.canvas = el.querySelector("canvas.as-gl");
      this.energyCanvas = el.querySelector("canvas.as-energy");
      el.querySelector(".as-label").textContent = data.label;
      this.mark = el.querySelector(".as-mark");
      this.cursor = el.querySelector(".as-cursor");
      this.energyValue = el.querySelector(".as-evalue");
      this.lastFrame = -1;
    }

    async load() {
      const d = this.data;
      this.pos = await decodePositions(d.pos, this.frames);
      this.springs = await decode(d.springs);
      // springs that tear are last: frame k draws the first springDrawn[k] of them
      this.springDrawn = await decode(d.spring_drawn);
      this.pinned = await decode(d.pinned);
      this.colors = await decode(d.colors);
      this.sizes = await decode(d.sizes);
      // Per particle (the same every frame): uploaded once; per frame: the frame's slice each time.
      this.colorsPerFrame = !!(d.colors && d.colors.per_frame);
      this.sizesPerFrame = !!(d.sizes && d.sizes.per_frame);
    }

    initGL() {
      let gl = this.canvas.getContext("webgl2", { antialias: true, alpha: false });
      if (!gl) throw new Error("this browser has no WebGL 2, which the viewer needs");
      this.software = isSoftware(gl);
      if (this.software) {
        // Multisampling costs a software renderer (no GPU) more than all the drawing:
        // without it the points stay smooth (their edge is blended in the shader), lines go hard.
        const fresh = document.createElement("canvas");
        fresh.className = this.canvas.className;
        this.canvas.replaceWith(fresh);
        this.canvas = fresh;
        gl = fresh.getContext("webgl2", { antialias: false, alpha: false });
      }
      this.gl = gl;
      this.pointProg = compile(gl, POINT_VS, POINT_FS);
      this.lineProg = compile(gl, LINE_VS, LINE_FS);
      const n = this.n;
      this.posBuf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, this.posBuf);
      gl.bufferData(gl.ARRAY_BUFFER, Math.max(n, 1) * 12, gl.DYNAMIC_DRAW);
      if (this.colors) {
        this.colBuf = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, this.colBuf);
        gl.bufferData(gl.ARRAY_BUFFER, this.colorsPerFrame ? Math.max(n, 1) * 4 : this.colors, gl.DYNAMIC_DRAW);
      }
      if (this.sizes) {
        this.sizeBuf = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, this.sizeBuf);
        gl.bufferData(gl.ARRAY_BUFFER, this.sizesPerFrame ? Math.max(n, 1) * 4 : this.sizes, gl.DYNAMIC_DRAW);
      }
      if (this.pinned) {
        this.pinBuf = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, this.pinBuf);
        gl.bufferData(gl.ARRAY_BUFFER, Float32Array.from(this.pinned), gl.STATIC_DRAW);
      }
      this.springCount = this.springs ? this.springs.length / 2 : 0;
      if (this.springCount) {
        this.springBuf = gl.createBuffer();
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.springBuf);
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, this.springs, gl.STATIC_DRAW);
      }
      // One VAO for the particles (points, and springs through the element buffer).
      const pp = this.pointProg;
      this.vao = gl.createVertexArray();
      gl.bindVertexArray(this.vao);
      const aPos = pp.attr("a_pos");
      gl.bindBuffer(gl.ARRAY_BUFFER, this.posBuf);
      gl.enableVertexAttribArray(aPos);
      gl.vertexAttribPointer(aPos, 3, gl.FLOAT, false, 0, 0);
      const aCol = pp.attr("a_col");
      if (this.colBuf) {
        gl.bindBuffer(gl.ARRAY_BUFFER, this.colBuf);
        gl.enableVertexAttribArray(aCol);
        gl.vertexAttribPointer(aCol, 4, gl.UNSIGNED_BYTE, true, 0, 0);
      } else gl.vertexAttrib4f(aCol, ...DEFAULT_COL);
      const aSize = pp.attr("a_size");
      if (this.sizeBuf) {
        gl.bindBuffer(gl.ARRAY_BUFFER, this.sizeBuf);
        gl.enableVertexAttribArray(aSize);
        gl.vertexAttribPointer(aSize, 1, gl.FLOAT, false, 0, 0);
      } else gl.vertexAttrib1f(aSize, 0);
      const aPin = pp.attr("a_pin");
      if (aPin >= 0) {
        if (this.pinBuf) {
          gl.bindBuffer(gl.ARRAY_BUFFER, this.pinBuf);
          gl.enableVertexAttribArray(aPin);
          gl.vertexAttribPointer(aPin, 1, gl.FLOAT, false, 0, 0);
        } else gl.vertexAttrib1f(aPin, 0);
      }
      if (this.springBuf) gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.springBuf);
      gl.bindVertexArray(null);
      // The line program reads positions at the same attribute slot through its own VAO.
      this.springVao = gl.createVertexArray();
      gl.bindVertexArray(this.springVao);
      const lPos = this.lineProg.attr("a_pos");
      gl.bindBuffer(gl.ARRAY_BUFFER, this.posBuf);
      gl.enableVertexAttribArray(lPos);
      gl.vertexAttribPointer(lPos, 3, gl.FLOAT, false, 0, 0);
      if (this.springBuf) gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.springBuf);
      gl.bindVertexArray(null);
      this.shapes = (this.data.shapes || []).map((s) => this.makeShape(s));
    }

    makeShape(s) {
      const gl = this.gl;
      let geo;
      if (s.kind === "plane") geo = planeGeometry(s, world.centre, world.radius);
      else if (s.kind === "sphere") geo = { lines: sphereLines(s.radius), tris: [] };
      else if (s.kind === "box") geo = { lines: boxLines(s.half_extents), tris: boxTriangles(s.half_extents) };
      else if (s.kind === "capsule") geo = { lines: capsuleLines(s.radius, s.half_length), tris: [] };
      else throw new Error("unknown shape kind " + s.kind);
      const mk = (arr) => {
        if (!arr.length) return null;
        const vao = gl.createVertexArray();
        gl.bindVertexArray(vao);
        const buf = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, buf);
        gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(arr), gl.STATIC_DRAW);
        const loc = this.lineProg.attr("a_pos");
        gl.enableVertexAttribArray(loc);
        gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
        gl.bindVertexArray(null);
        return { vao, count: arr.length / 3 };
      };
      const isPlane = s.kind === "plane";
      return {
        spec: s,
        lines: mk(geo.lines),
        tris: mk(geo.tris),
        lineCol: s.color ? [s.color[0], s.color[1], s.color[2], 1] : isPlane ? PLANE_LINE : SHAPE_LINE,
        fillCol: s.color ? [s.color[0], s.color[1], s.color[2], 0.25 * (s.color[3] ?? 1)] : PLANE_FILL,
      };
    }

    shapeModel(spec, k) {
      if (spec.kind === "plane") return null;
      const p = spec.position || [0, 0, 0];
      const q = spec.orientation || [1, 0, 0, 0];
      const pk = p.length > 3 ? p.slice(3 * Math.min(k, p.length / 3 - 1), 3 * Math.min(k, p.length / 3 - 1) + 3) : p;
      const qk = q.length > 4 ? q.slice(4 * Math.min(k, q.length / 4 - 1), 4 * Math.min(k, q.length / 4 - 1) + 4) : q;
      return model(pk, qk);
    }

    resize() {
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr));
      const h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
      if (this.canvas.width !== w || this.canvas.height !== h) {
        this.canvas.width = w;
        this.canvas.height = h;
        return true;
      }
      return false;
    }

    // The frame shown at time t: the last one at or before t (frozen after a failure).
    frameAt(t) {
      const T = this.times;
      if (!T.length) return -1;
      let lo = 0, hi = T.length - 1;
      if (t >= T[hi]) return hi;
      while (lo < hi) {
        const mid = (lo + hi + 1) >> 1;
        if (T[mid] <= t + 1e-9) lo = mid; else hi = mid - 1;
      }
      return lo;
    }

    draw(t, force) {
      const k = this.frameAt(t);
      const frozen = this.data.status !== "ok" && this.frames > 0 && t > this.times[this.frames - 1] + 1e-9;
      this.mark.classList.toggle("on", frozen);
      this.el.classList.toggle("frozen", frozen);
      if (frozen) this.mark.textContent = this.data.mark;
      const resized = this.resize();
      // A page that was hidden (a collapsed notebook cell) gets its plot drawn once it has a size.
      if (this.data.energy && Math.max(1, Math.round(this.energyCanvas.clientWidth * (window.devicePixelRatio || 1))) !== this.energyW) this.prepareEnergy();
      if (k !== this.lastFrame || force || resized) this.drawScene(k);
      this.lastFrame = k;
      this.drawEnergy(k, t);
    }

    drawScene(k) {
      const gl = this.gl;
      const n = this.n;
      gl.viewport(0, 0, this.canvas.width, this.canvas.height);
      gl.clearColor(0.12, 0.12, 0.12, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      const { mvp, proj } = cameraMatrix(this.canvas.width / this.canvas.height);
      gl.enable(gl.DEPTH_TEST);
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
      const lp = this.lineProg;
      gl.useProgram(lp.prog);
      // Shapes' outlines first.
      for (const s of this.shapes) {
        const m = this.shapeModel(s.spec, k);
        gl.uniformMatrix4fv(lp.loc("u_mvp"), false, m ? mul(mvp, m) : mvp);
        if (s.lines) {
          gl.uniform4fv(lp.loc("u_col"), s.lineCol);
          gl.bindVertexArray(s.lines.vao);
          gl.drawArrays(gl.LINES, 0, s.lines.count);
        }
      }
      if (k >= 0 && n > 0) {
        gl.bindBuffer(gl.ARRAY_BUFFER, this.posBuf);
        gl.bufferSubData(gl.ARRAY_BUFFER, 0, this.pos, k * n * 3, n * 3);
        if (this.colBuf && this.colorsPerFrame) {
          gl.bindBuffer(gl.ARRAY_BUFFER, this.colBuf);
          gl.bufferSubData(gl.ARRAY_BUFFER, 0, this.colors, k * n * 4, n * 4);
        }
        if (this.sizeBuf && this.sizesPerFrame) {
          gl.bindBuffer(gl.ARRAY_BUFFER, this.sizeBuf);
          gl.bufferSubData(gl.ARRAY_BUFFER, 0, this.sizes, k * n, n);
        }
        const drawn = this.springDrawn ? this.springDrawn[k] : this.springCount;
        this.springsShown = drawn;
        if (drawn) {
          gl.uniformMatrix4fv(lp.loc("u_mvp"), false, mvp);
          gl.uniform4fv(lp.loc("u_col"), SPRING_COL);
          gl.bindVertexArray(this.springVao);
          gl.drawElements(gl.LINES, drawn * 2, gl.UNSIGNED_INT, 0);
        }
        const pp = this.pointProg;
        gl.useProgram(pp.prog);
        gl.uniformMatrix4fv(pp.loc("u_mvp"), false, mvp);
        const dpr = window.devicePixelRatio || 1;
        gl.uniform1f(pp.loc("u_pxScale"), (proj[5] * this.canvas.height) / 2);
        gl.uniform1f(pp.loc("u_defPx"), 6 * dpr * Math.min(1, Math.max(0.5, this.canvas.width / (480 * dpr))));
        // Translucent particle systems do not write depth, so they blend instead of cutting holes.
        gl.depthMask(!this.colors);
        gl.bindVertexArray(this.vao);
        gl.drawArrays(gl.POINTS, 0, n);
        gl.depthMask(true);
      }
      // Translucent fills last, without writing depth.
      gl.useProgram(lp.prog);
      gl.depthMask(false);
      for (const s of this.shapes) {
        if (!s.tris) continue;
        const m = this.shapeModel(s.spec, k);
        gl.uniformMatrix4fv(lp.loc("u_mvp"), false, m ? mul(mvp, m) : mvp);
        gl.uniform4fv(lp.loc("u_col"), s.fillCol);
        gl.bindVertexArray(s.tris.vao);
        gl.drawArrays(gl.TRIANGLES, 0, s.tris.count);
      }
      gl.depthMask(true);
      gl.bindVertexArray(null);
    }

    // -------------------------------------------------------------- energy plot

    prepareEnergy() {
      const e = this.data.energy;
      const c = this.energyCanvas;
      if (!e) {
        // A trajectory without its scene has no energy: no plot rather than an empty box.
        c.style.display = "none";
        this.plotBox = null;
        return;
      }
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(1, Math.round(c.clientWidth * dpr)), h = Math.max(1, Math.round(c.clientHeight * dpr));
      c.width = w;
      c.height = h;
      this.energyW = w;
      const bg = document.createElement("canvas");
      bg.width = w;
      bg.height = h;
      const g = bg.getContext("2d");
      g.fillStyle = "#262626";
      g.fillRect(0, 0, w, h);
      if (!e || !this.frames) {
        g.fillStyle = "#999";
        g.font = `${11 * dpr}px sans-serif`;
        g.fillText("no frames", 8 * dpr, h / 2);
        this.plotBox = null;
        c.getContext("2d").drawImage(bg, 0, 0);
        return;
      }
      const series = [["kinetic", "#4ea3ff"], ["potential", "#ffa24e"], ["total", "#f0f0f0"]].filter(([k]) => e[k]);
      let lo = Infinity, hi = -Infinity;
      for (const [k] of series) for (const v of e[k]) if (Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      if (!Number.isFinite(lo)) { lo = 0; hi = 1; }
      if (hi - lo < 1e-12 * Math.max(1, Math.abs(hi))) { hi += 0.5; lo -= 0.5; }
      const pad = 0.06 * (hi - lo);
      lo -= pad; hi += pad;
      const L = 46 * dpr, R = 8 * dpr, T = 16 * dpr, B = 16 * dpr;
      const tEnd = Math.max(scene.tEnd, 1e-9);
      const box = { L, R, T, B, w, h, lo, hi, tEnd };
      this.plotBox = box;
      const xOf = (t) => L + ((w - L - R) * t) / tEnd;
      const yOf = (v) => T + ((h - T - B) * (hi - v)) / (hi - lo);
      g.strokeStyle = "#444";
      g.lineWidth = 1;
      g.strokeRect(L, T, w - L - R, h - T - B);
      g.fillStyle = "#aaa";
      g.font = `${10 * dpr}px sans-serif`;
      g.textAlign = "right";
      g.fillText(fmt(hi - pad), L - 3 * dpr, T + 8 * dpr);
      g.fillText(fmt(lo + pad), L - 3 * dpr, h - B);
      g.fillText("J", L - 3 * dpr, (T + h - B) / 2 + 4 * dpr);
      g.textAlign = "left";
      g.fillText("t (s) 0", L, h - 3 * dpr);
      g.textAlign = "right";
      g.fillText(fmt(tEnd), w - R, h - 3 * dpr);
      let lx = L + 4 * dpr;
      g.textAlign = "left";
      for (const [k, col] of series) {
        g.strokeStyle = col;
        g.lineWidth = (k === "total" ? 1.8 : 1.2) * dpr;
        g.beginPath();
        let started = false;
        e[k].forEach((v, i) => {
          if (!Number.isFinite(v)) return;
          const x = xOf(this.times[i]), y = yOf(v);
          if (started) g.lineTo(x, y); else { g.moveTo(x, y); started = true; }
        });
        g.stroke();
        g.fillStyle = col;
        g.fillText(k, lx, 11 * dpr);
        lx += g.measureText(k).width + 10 * dpr;
      }
      c.getContext("2d").drawImage(bg, 0, 0);
      this.cursor.style.top = `${(c.offsetTop + T / dpr).toFixed(1)}px`;
      this.cursor.style.height = `${((h - T - B) / dpr).toFixed(1)}px`;
      this.cursor.style.display = "block";
      this.energyValue.style.top = `${(c.offsetTop + 1).toFixed(1)}px`;
      this.energyCursor = -2;
    }

    drawEnergy(k, t) {
      // The plot is drawn once; only a positioned line and a label move, so playing costs no canvas work.
      const b = this.plotBox;
      if (!b) return;
      const key = Math.round(t * 1e6);
      if (key === this.energyCursor) return;
      this.energyCursor = key;
      const dpr = window.devicePixelRatio || 1;
      const x = (b.L + ((b.w - b.L - b.R) * Math.min(t, b.tEnd)) / b.tEnd) / dpr;
      this.cursor.style.transform = `translateX(${x.toFixed(1)}px)`;
      const e = this.data.energy;
      this.energyValue.textContent = k >= 0 && e && e.total && Number.isFinite(e.total[k]) ? "E = " + fmt(e.total[k]) + " J" : "";
    }
  }

  function fmt(v) {
    if (!Number.isFinite(v)) return String(v);
    const a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(2);
    return Number(v.toPrecision(4)).toString();
  }

  // ------------------------------------------------------------------ the player

  const scene = { tEnd: 0, times: new Float64Array(0) };
  const panels = [];
  const state = { t: 0, playing: false, speed: 1, last: null, dirty: true, benchmark: false };
  const stats = { intervals: [], draws: [], last: null, recording: false };
  const slider = document.getElementById("as-slider");
  const playButton = document.getElementById("as-play");
  const timeLabel = document.getElementById("as-time");

  function frameIndexAt(t) {
    const T = scene.times;
    let lo = 0, hi = T.length - 1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (T[mid] <= t + 1e-9) lo = mid; else hi = mid - 1;
    }
    return lo;
  }

  function setPlaying(on) {
    state.playing = on;
    state.last = null;
    playButton.innerHTML = on ? "&#10074;&#10074; pause" : "&#9654; play";
  }

  function setTime(t) {
    state.t = Math.min(Math.max(t, 0), scene.tEnd);
    slider.value = String(frameIndexAt(state.t));
    timeLabel.textContent = "t = " + state.t.toFixed(2) + " s";
  }

  function tick(now) {
    if (stats.recording) {
      if (stats.last !== null) stats.intervals.push(now - stats.last);
      stats.last = now;
    }
    if (state.playing) {
      if (state.last !== null) {
        let t = state.t + ((now - state.last) / 1000) * state.speed;
        if (t > scene.tEnd) t = scene.tEnd > 0 ? t % scene.tEnd : 0;
        setTime(t);
      }
      state.last = now;
    }
    const force = state.dirty || state.benchmark;
    const t0 = performance.now();
    for (const p of panels) p.draw(state.t, force);
    if (state.benchmark) {
      // Wait for the drawing to finish, so the time below is the whole frame's work.
      for (const p of panels) p.gl.finish();
      stats.draws.push(performance.now() - t0);
    }
    state.dirty = false;
    requestAnimationFrame(tick);
  }

  function bindControls() {
    playButton.addEventListener("click", () => setPlaying(!state.playing));
    slider.addEventListener("input", () => {
      setPlaying(false);
      setTime(scene.times[Number(slider.value)] || 0);
    });
    document.getElementById("as-speed").addEventListener("change", (ev) => { state.speed = Number(ev.target.value); });
    const viewSel = document.getElementById("as-view");
    viewSel.value = camera.view;
    viewSel.addEventListener("change", (ev) => { camera.view = ev.target.value; resetCamera(false); });
    document.getElementById("as-reset").addEventListener("click", () => resetCamera(true));
    root.tabIndex = 0;
    root.addEventListener("keydown", (ev) => {
      if (ev.target.tagName === "SELECT") return;
      if (ev.key === " ") { setPlaying(!state.playing); ev.preventDefault(); }
      else if (ev.key === "ArrowRight" || ev.key === "ArrowLeft") {
        setPlaying(false);
        const i = frameIndexAt(state.t) + (ev.key === "ArrowRight" ? 1 : -1);
        setTime(scene.times[Math.min(Math.max(i, 0), scene.times.length - 1)]);
        ev.preventDefault();
      }
    });
    window.addEventListener("resize", () => { for (const p of panels) p.prepareEnergy(); state.dirty = true; });
    for (const p of panels) bindMouse(p.canvas);
  }

  function resetCamera(all) {
    camera.zoom = 1;
    camera.pan = [0, 0, 0];
    if (all) { camera.az = 30; camera.el = 20; }
    state.dirty = true;
  }

  function bindMouse(canvas) {
    let drag = null;
    canvas.addEventListener("contextmenu", (ev) => ev.preventDefault());
    canvas.addEventListener("pointerdown", (ev) => {
      drag = { x: ev.clientX, y: ev.clientY, pan: ev.button === 2 || ev.shiftKey || camera.view !== "3d" };
      canvas.setPointerCapture(ev.pointerId);
    });
    canvas.addEventListener("pointermove", (ev) => {
      if (!drag) return;
      const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
      drag.x = ev.clientX;
      drag.y = ev.clientY;
      if (drag.pan) panBy(dx, dy, canvas.clientHeight);
      else {
        camera.az -= dx * 0.4;
        camera.el = Math.min(89, Math.max(-89, camera.el + dy * 0.4));
      }
      state.dirty = true;
    });
    const end = () => { drag = null; };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    canvas.addEventListener("wheel", (ev) => {
      camera.zoom = Math.min(200, Math.max(0.05, camera.zoom * Math.exp(-ev.deltaY * 0.0015)));
      state.dirty = true;
      ev.preventDefault();
    }, { passive: false });
    canvas.addEventListener("dblclick", () => resetCamera(true));
  }

  function sceneBounds(data) {
    let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const p of data.panels) {
      if (!p.pos.empty) for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], p.pos.lo[a]); hi[a] = Math.max(hi[a], p.pos.hi[a]); }
      for (const s of p.shapes || []) {
        if (s.kind === "plane") continue;
        const pos = s.position || [0, 0, 0];
        const r = s.radius !== undefined ? s.radius + (s.half_length || 0) : Math.hypot(...(s.half_extents || [0, 0, 0]));
        for (let i = 0; i + 2 < pos.length; i += 3)
          for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], pos[i + a] - r); hi[a] = Math.max(hi[a], pos[i + a] + r); }
      }
    }
    if (!Number.isFinite(lo[0])) { lo = [-0.5, -0.5, -0.5]; hi = [0.5, 0.5, 0.5]; }
    const centre = [0, 1, 2].map((a) => (lo[a] + hi[a]) / 2);
    const radius = Math.max(0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), 1e-3);
    return { centre, radius };
  }

  async function start() {
    const data = JSON.parse(document.getElementById("animsim-data").textContent);
    document.getElementById("as-title").textContent = data.title || "";
    const up = data.up === "z" ? "z" : "y";
    world = { ...sceneBounds(data), up: up === "z" ? Z : Y, upName: up };
    camera.view = data.view || "3d";
    const container = document.getElementById("as-panels");
    if (data.panels.length > 1) container.style.gridTemplateColumns = `repeat(${Math.min(data.panels.length, 4)}, minmax(220px, 1fr))`;
    else container.classList.add("single");
    data.panels.forEach((d, i) => panels.push(new Panel(d, i, container)));
    await Promise.all(panels.map((p) => p.load()));
    // The shared clock: the longest panel's frame times (a failed run stops early).
    let longest = panels[0];
    for (const p of panels) if (p.frames > longest.frames) longest = p;
    scene.times = longest.times.length ? longest.times : Float64Array.from([0]);
    scene.tEnd = Math.max(data.duration || 0, scene.times[scene.times.length - 1]);
    slider.max = String(scene.times.length - 1);
    for (const p of panels) { p.initGL(); p.prepareEnergy(); }
    bindControls();
    setTime(0);
    Object.assign(api, {
      ready: true,
      panels: panels.length,
      frameCount: scene.times.length,
      play: () => setPlaying(true),
      pause: () => setPlaying(false),
      setFrame: (i) => { setPlaying(false); setTime(scene.times[Math.min(Math.max(i, 0), scene.times.length - 1)]); },
      time: () => state.t,
      // RGBA bytes of panel i as drawn now (redrawn and read in one go, so the drawing buffer is still there).
      pixels: (i) => {
        const p = panels[i];
        p.drawScene(p.frameAt(state.t));
        const gl = p.gl, w = p.canvas.width, h = p.canvas.height;
        const buf = new Uint8Array(w * h * 4);
        gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, buf);
        let bin = "";
        for (let k = 0; k < buf.length; k += 0x8000) bin += String.fromCharCode.apply(null, buf.subarray(k, k + 0x8000));
        return { width: w, height: h, rgba: btoa(bin) };
      },
      software: () => panels.some((p) => p.software),
      // Decoded position of particle j in frame k of panel i (null when not alive), to check the decoding.
      position: (i, k, j) => {
        const p = panels[i], o = (k * p.n + j) * 3;
        return p.pos[o] >= DEAD ? null : [p.pos[o], p.pos[o + 1], p.pos[o + 2]];
      },
      labels: () => panels.map((p) => p.el.querySelector(".as-label").textContent),
      marks: () => panels.map((p) => (p.mark.classList.contains("on") ? p.mark.textContent : "")),
      frameShown: (i) => panels[i].lastFrame,
      springsShown: (i) => panels[i].springsShown,
      setView: (v) => { camera.view = v; document.getElementById("as-view").value = v; resetCamera(false); },
      orbit: (daz, del) => { camera.az += daz; camera.el = Math.min(89, Math.max(-89, camera.el + del)); state.dirty = true; },
      // Timing of requestAnimationFrame callbacks, for measuring playback smoothness.
      // benchmark: redraw every panel on every display frame, not only when the frame changes.
      startStats: (benchmark) => { stats.intervals = []; stats.draws = []; stats.last = null; stats.recording = true; state.benchmark = !!benchmark; },
      stopStats: () => {
        stats.recording = false;
        state.benchmark = false;
        const v = stats.intervals.slice().sort((a, b) => a - b);
        const mean = v.reduce((s, x) => s + x, 0) / Math.max(v.length, 1);
        const d = stats.draws.slice().sort((a, b) => a - b);
        const drawMean = d.reduce((s, x) => s + x, 0) / Math.max(d.length, 1);
        return {
          frames: v.length, mean_ms: mean, p95_ms: v[Math.floor(0.95 * (v.length - 1))] || 0, max_ms: v[v.length - 1] || 0,
          draw_mean_ms: drawMean, draw_p95_ms: d[Math.floor(0.95 * (d.length - 1))] || 0,
        };
      },
    });
    requestAnimationFrame(tick);
  }

  start().catch((err) => fail(err && err.message ? err.message : err));
})();
