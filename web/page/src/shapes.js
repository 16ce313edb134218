// What the page draws, computed without WebGL: the posed skeletons' instances (a unit
// cylinder per bone, a unit sphere per joint, a flattened sphere per shadow disc) and the
// camera of a pane, following the study window (window/src/scene.rs) number for number.
// render.js turns these into draw calls.

/** Bone colour (window: BONE_COLOR), linear 0-1 as written to the target. */
export const BONE_COLOR = [0.78, 0.8, 0.86, 1.0];
/** Joint colour (window: JOINT_COLOR). */
export const JOINT_COLOR = [0.93, 0.55, 0.22, 1.0];

/** Floats per instance: position (3), rotation quaternion x y z w (4), scale (3), colour (4). */
export const INSTANCE_FLOATS = 14;

/**
 * A unit cylinder along +y from 0 to 1, radius 1, open ends (window: cylinder_mesh):
 * interleaved position and normal (6 floats a vertex) and triangle indices, counter-clockwise
 * seen from outside.
 */
export function cylinderMesh(segments) {
  const v = [];
  const idx = [];
  for (let s = 0; s <= segments; s++) {
    const a = (s / segments) * 2 * Math.PI;
    const x = Math.cos(a);
    const z = Math.sin(a);
    for (const y of [0, 1]) v.push(x, y, z, x, 0, z);
  }
  for (let s = 0; s < segments; s++) {
    const b = s * 2;
    idx.push(b, b + 1, b + 2, b + 1, b + 3, b + 2);
  }
  return { vertices: new Float32Array(v), indices: new Uint16Array(idx) };
}

/** A unit sphere of `rings` × `sectors` quads (window: sphere_mesh). */
export function sphereMesh(rings, sectors) {
  const v = [];
  const idx = [];
  for (let r = 0; r <= rings; r++) {
    const phi = (r / rings) * Math.PI;
    for (let s = 0; s <= sectors; s++) {
      const th = (s / sectors) * 2 * Math.PI;
      const p = [Math.sin(phi) * Math.cos(th), Math.cos(phi), Math.sin(phi) * Math.sin(th)];
      v.push(p[0], p[1], p[2], p[0], p[1], p[2]);
    }
  }
  const w = sectors + 1;
  for (let r = 0; r < rings; r++) {
    for (let s = 0; s < sectors; s++) {
      const a = r * w + s;
      idx.push(a, a + 1, a + w, a + 1, a + w + 1, a + w);
    }
  }
  return { vertices: new Float32Array(v), indices: new Uint16Array(idx) };
}

/**
 * Writes the joint positions of `clip` at `t` seconds into `out` (3 floats a joint): linear
 * between frame floor(t·fps) and the next, held at the first and last frames.
 */
export function poseAt(clip, t, out) {
  const n = 3 * clip.joints;
  const pos = clip.positions;
  if (clip.frames <= 0) {
    out.fill(0);
    return out;
  }
  const last = clip.frames - 1;
  const f = Number.isFinite(t) && clip.fps > 0 ? Math.max(0, t * clip.fps) : 0;
  let i = Math.floor(f);
  let w = f - i;
  if (i >= last) {
    i = Math.max(0, last);
    w = 0;
  }
  const a = n * i;
  if (w <= 0) {
    for (let k = 0; k < n; k++) out[k] = pos[a + k];
  } else {
    const b = a + n;
    for (let k = 0; k < n; k++) out[k] = pos[a + k] + (pos[b + k] - pos[a + k]) * w;
  }
  return out;
}

/** Point of the camera's path at `t` seconds (window: Track::at, Catmull-Rom, held at ends). */
export function trackAt(track, t) {
  const knots = track && Array.isArray(track.knots) ? track.knots : [];
  if (knots.length === 0) return [0, 0];
  const n = knots.length;
  const end = Number(track.end_s) || 0;
  if (n === 1 || end <= 0) return [knots[0][0], knots[0][1]];
  const tt = Number.isFinite(t) ? t : 0;
  const u = Math.min(1, Math.max(0, tt / end)) * (n - 1);
  const i = Math.min(Math.floor(u), n - 2);
  const f = u - i;
  const last = n - 1;
  const q = (j) => knots[Math.min(last, Math.max(0, j))];
  // Phantom knots past the ends continue the path straight on (reflection of the inner one).
  const k = (j) => {
    let e;
    let m;
    if (j < 0) {
      e = q(0);
      m = q(1);
    } else if (j > last) {
      e = q(last);
      m = q(last - 1);
    } else {
      return q(j);
    }
    return [2 * e[0] - m[0], 2 * e[1] - m[1]];
  };
  const p0 = k(i - 1);
  const p1 = k(i);
  const p2 = k(i + 1);
  const p3 = k(i + 2);
  const out = [0, 0];
  for (let c = 0; c < 2; c++) {
    out[c] =
      0.5 *
      (2 * p1[c] +
        (p2[c] - p0[c]) * f +
        (2 * p0[c] - 5 * p1[c] + 4 * p2[c] - p3[c]) * f * f +
        (3 * p1[c] - p0[c] - 3 * p2[c] + p3[c]) * f * f * f);
  }
  return out;
}

/**
 * The camera at `t` (window: View::at and View::view_proj) for a viewport of aspect `aspect`:
 * { viewProj (column-major Float32Array(16), WebGL depth −1..1), eye, target, ground: [cx, cz] }.
 */
export function cameraAt(camera, aspect, t) {
  const a = trackAt(camera.track, 0);
  const b = trackAt(camera.track, t);
  const sx = b[0] - a[0];
  const sz = b[1] - a[1];
  const target = [camera.target[0] + sx, camera.target[1], camera.target[2] + sz];
  let eye = [camera.eye[0] + sx, camera.eye[1], camera.eye[2] + sz];
  const asp = Number.isFinite(aspect) && aspect > 0 ? aspect : 1;
  const fovY = camera.fov_y;
  let near = camera.near;
  let far = camera.far;
  const halfFovX = Math.atan(asp * Math.tan(0.5 * fovY));
  const radius = Number(camera.radius) || 0;
  if (halfFovX < 0.5 * fovY) {
    // Narrower than tall: back off along eye − target so the sphere of every pose still fits.
    const off = sub(eye, target);
    const d = norm(off);
    const wanted = radius / Math.sin(halfFovX);
    if (d > 0 && wanted > d) {
      eye = add(target, scale(off, wanted / d));
      near = Math.max(wanted - 2.5 * radius, wanted * 0.02);
      far = wanted + 4 * radius;
    }
  }
  const viewProj = mul(perspective(fovY, asp, near, far), lookAt(eye, target, [0, 1, 0]));
  return { viewProj, eye, target, ground: [target[0], target[2]] };
}

/**
 * A figure of a pane: its clip, sizes and placement, with scratch for its pose; `shapes`
 * writes its instances at a time.
 */
export class Posed {
  constructor(clip, fig) {
    this.clip = clip;
    this.r = Number(fig.bone_radius) || 0;
    this.groundY = Number(fig.ground_y) || 0;
    this.height = Math.max(Number(fig.height) || 0, 1e-6);
    const p = fig.placed;
    this.placed = p
      ? {
          origin: p.origin,
          scale: Number.isFinite(p.scale) && p.scale > 0 ? p.scale : 1,
          turn: p.turn,
          at: p.at,
        }
      : null;
    this.points = new Float32Array(3 * clip.joints);
    this.bones = clip.parents.filter((q, j) => q >= 0 && q < clip.joints && q !== j).length;
  }

  /** A clip point moved into the pane (window: Placed::point). */
  place(p) {
    const s = this.placed;
    return add(rotateBy(s.turn, scale(sub(p, s.origin), s.scale)), s.at);
  }

  /**
   * Writes the instances at `t` (window: Figure::shapes_at then Placed::instance) at the
   * given instance offsets of `out` ({ bones, joints, shadows }: Float32Arrays); `shadow`
   * whether shadow discs are written. Returns the counts written.
   */
  shapes(t, shadow, out, at) {
    const c = this.clip;
    const p = poseAt(c, t, this.points);
    const r = this.r;
    let nb = 0;
    let nj = 0;
    let ns = 0;
    const put = (arr, k, pos, rot, scl, col) => {
      let o = k * INSTANCE_FLOATS;
      if (this.placed) {
        const s = this.placed;
        pos = this.place(pos);
        rot = quatMul(s.turn, rot);
        scl = scale(scl, s.scale);
      }
      arr[o++] = pos[0];
      arr[o++] = pos[1];
      arr[o++] = pos[2];
      arr[o++] = rot[0];
      arr[o++] = rot[1];
      arr[o++] = rot[2];
      arr[o++] = rot[3];
      arr[o++] = scl[0];
      arr[o++] = scl[1];
      arr[o++] = scl[2];
      arr[o++] = col[0];
      arr[o++] = col[1];
      arr[o++] = col[2];
      arr[o] = col[3];
    };
    const disc = (q) => {
      const u = Math.min(1, Math.max(0, (q[1] - this.groundY) / this.height));
      const radius = r * (2.2 + 4 * u);
      const alpha = 0.08 + 0.6 * (1 - u) * (1 - u);
      put(
        out.shadows,
        at.shadows + ns++,
        [q[0], this.groundY + 0.05 * r, q[2]],
        [0, 0, 0, 1],
        [radius, 0.01 * r, radius],
        [0, 0, 0, alpha],
      );
    };
    const joint = [r * 1.45, r * 1.45, r * 1.45];
    for (let j = 0; j < c.joints; j++) {
      const pj = [p[3 * j], p[3 * j + 1], p[3 * j + 2]];
      put(out.joints, at.joints + nj++, pj, [0, 0, 0, 1], joint, JOINT_COLOR);
      const q = c.parents[j];
      if (q < 0 || q >= c.joints || q === j) continue;
      const pp = [p[3 * q], p[3 * q + 1], p[3 * q + 2]];
      const d = sub(pj, pp);
      const len = norm(d);
      if (!(len > r * 0.05)) continue;
      put(out.bones, at.bones + nb++, pp, rotationFromY(scale(d, 1 / len)), [r, len, r], BONE_COLOR);
      if (shadow) disc(scale(add(pj, pp), 0.5));
    }
    if (shadow) {
      for (let j = 0; j < c.joints; j++) disc([p[3 * j], p[3 * j + 1], p[3 * j + 2]]);
    }
    return { bones: nb, joints: nj, shadows: ns };
  }
}

function sub(a, b) {
  return [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
}

function add(a, b) {
  return [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
}

function scale(a, s) {
  return [a[0] * s, a[1] * s, a[2] * s];
}

function dot(a, b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}

function norm(a) {
  return Math.sqrt(dot(a, a));
}

function normalize(a) {
  const n = norm(a);
  return n > 0 ? scale(a, 1 / n) : a;
}

/** `v` rotated by the unit quaternion `q` (x, y, z, w). */
function rotateBy(q, v) {
  const u = [q[0], q[1], q[2]];
  const t = scale(cross(u, v), 2);
  return add(add(v, scale(t, q[3])), cross(u, t));
}

/** The Hamilton product `a b` (rotate by `b`, then by `a`). */
function quatMul(a, b) {
  return [
    a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
    a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
    a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
    a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2],
  ];
}

/** The unit quaternion turning +y onto the unit vector `d`. */
function rotationFromY(d) {
  const c = d[1];
  if (c < -0.999999) return [1, 0, 0, 0];
  const w = 1 + c;
  const n = Math.sqrt(d[2] * d[2] + d[0] * d[0] + w * w);
  return [d[2] / n, 0, -d[0] / n, w / n];
}

/** Column-major product `a × b`. */
function mul(a, b) {
  const m = new Float32Array(16);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[4 * k + r] * b[4 * c + k];
      m[4 * c + r] = s;
    }
  }
  return m;
}

/** Right-handed perspective projection, WebGL depth −1..1 (the window's maps to 0..1). */
function perspective(fovY, aspect, near, far) {
  const f = 1 / Math.tan(0.5 * fovY);
  const nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}

/** Right-handed view matrix looking from `eye` at `target`. */
function lookAt(eye, target, up) {
  const f = normalize(sub(target, eye));
  const s = normalize(cross(f, up));
  const u = cross(s, f);
  return [
    s[0], u[0], -f[0], 0,
    s[1], u[1], -f[1], 0,
    s[2], u[2], -f[2], 0,
    -dot(s, eye), -dot(u, eye), dot(f, eye), 1,
  ];
}
