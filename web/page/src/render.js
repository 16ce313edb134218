// Two skeletons drawn with WebGL (three.js): the clips the server decoded, as joint
// positions in cm (format MCJP, web/src/clipdata.rs), posed by clip time.
import * as THREE from 'three';

const BACKGROUND = 0x1e1e1e;
const GREY = 0x606060;

/** Parses an MCJP buffer: { joints, frames, fps, parents, positions (Float32Array) }. */
export function parseClip(buf) {
  const v = new DataView(buf);
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== 'MCJP' || v.getUint16(4, true) !== 1) throw new Error('not an MCJP clip');
  const joints = v.getUint16(6, true);
  const frames = v.getUint32(8, true);
  const fps = v.getFloat32(12, true);
  const parents = [];
  for (let j = 0; j < joints; j++) parents.push(v.getInt16(16 + 2 * j, true));
  const start = Math.ceil((16 + 2 * joints) / 4) * 4;
  if (buf.byteLength !== start + 12 * joints * frames) throw new Error('MCJP clip of the wrong size');
  return { joints, frames, fps, parents, positions: new Float32Array(buf, start, 3 * joints * frames) };
}

/** The frame of `clip` at `t` seconds (held at the last frame). */
function frameAt(clip, t) {
  return Math.max(0, Math.min(clip.frames - 1, Math.floor(t * clip.fps + 1e-6)));
}

class Figure {
  constructor(clip, color) {
    this.clip = clip;
    const bones = clip.parents.filter((p) => p >= 0).length;
    this.lines = new THREE.BufferGeometry();
    this.lines.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * bones), 3));
    this.points = new THREE.BufferGeometry();
    this.points.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * clip.joints), 3));
    this.group = new THREE.Group();
    this.group.add(new THREE.LineSegments(this.lines, new THREE.LineBasicMaterial({ color })));
    this.group.add(new THREE.Points(this.points, new THREE.PointsMaterial({ color, size: 5, sizeAttenuation: false })));
  }

  pose(t) {
    const c = this.clip;
    const f = frameAt(c, t);
    const base = 3 * c.joints * f;
    const lp = this.lines.attributes.position.array;
    const pp = this.points.attributes.position.array;
    let k = 0;
    for (let j = 0; j < c.joints; j++) {
      for (let a = 0; a < 3; a++) pp[3 * j + a] = c.positions[base + 3 * j + a];
      const p = c.parents[j];
      if (p < 0) continue;
      for (let a = 0; a < 3; a++) {
        lp[k + a] = c.positions[base + 3 * p + a];
        lp[k + 3 + a] = c.positions[base + 3 * j + a];
      }
      k += 6;
    }
    this.lines.attributes.position.needsUpdate = true;
    this.points.attributes.position.needsUpdate = true;
    this.lines.computeBoundingSphere();
    this.points.computeBoundingSphere();
    return [c.positions[base], c.positions[base + 1], c.positions[base + 2]];
  }
}

/** The stage: one canvas, one or two viewports. */
export class Stage {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setScissorTest(true);
    this.scenes = [new THREE.Scene(), new THREE.Scene()];
    this.figures = [null, null];
    this.camera = new THREE.PerspectiveCamera(35, 1, 1, 10000);
    for (const s of this.scenes) {
      const grid = new THREE.GridHelper(1000, 20, 0x444444, 0x333333);
      s.add(grid);
    }
  }

  /** Shows `clips` (the first and second position's) from now on. */
  load(clips) {
    for (let i = 0; i < 2; i++) {
      if (this.figures[i]) this.scenes[i].remove(this.figures[i].group);
      this.figures[i] = new Figure(clips[i], 0xe8e8e8);
      this.scenes[i].add(this.figures[i].group);
    }
    // The figure's height frames the view (the window frames the reference likewise).
    const c = clips[0];
    let lo = Infinity;
    let hi = -Infinity;
    for (let i = 1; i < c.positions.length; i += 3) {
      lo = Math.min(lo, c.positions[i]);
      hi = Math.max(hi, c.positions[i]);
    }
    this.height = Math.max(50, hi - lo);
    this.floor = lo;
  }

  resize() {
    const w = this.canvas.clientWidth;
    const h = this.canvas.clientHeight;
    if (this.canvas.width !== Math.floor(w * this.renderer.getPixelRatio()) ||
        this.canvas.height !== Math.floor(h * this.renderer.getPixelRatio())) {
      this.renderer.setSize(w, h, false);
    }
    return [w, h];
  }

  /**
   * Draws one frame: `show` is 'both', 'grey', or the slot (0, 1) shown alone; `t` the clip
   * time in seconds.
   */
  draw(show, t) {
    const [w, h] = this.resize();
    const r = this.renderer;
    if (show === 'grey' || !this.figures[0]) {
      r.setViewport(0, 0, w, h);
      r.setScissor(0, 0, w, h);
      r.setClearColor(GREY);
      r.clear();
      return;
    }
    r.setClearColor(BACKGROUND);
    const views = show === 'both' ? [[0, 0, w / 2, h], [1, w / 2, w / 2, h]] : [[show, 0, w, h]];
    for (const [slot, x, vw, vh] of views) {
      const root = this.figures[slot].pose(t);
      r.setViewport(x, 0, vw, vh);
      r.setScissor(x, 0, vw, vh);
      this.camera.aspect = vw / Math.max(1, vh);
      const d = this.height * 2.6;
      const target = new THREE.Vector3(root[0], this.floor + this.height * 0.5, root[2]);
      // Seen from the front-right and a little above, following the root.
      this.camera.position.set(target.x + d * 0.5, target.y + this.height * 0.25, target.z + d * 0.85);
      this.camera.lookAt(target);
      this.camera.updateProjectionMatrix();
      r.render(this.scenes[slot], this.camera);
    }
  }
}

/** The WebGL renderer string, or '' without WebGL2. */
export function webglInfo() {
  const c = document.createElement('canvas');
  const gl = c.getContext('webgl2');
  if (!gl) return { webgl2: false, renderer: '' };
  const ext = gl.getExtension('WEBGL_debug_renderer_info');
  const renderer = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER) || '');
  const lose = gl.getExtension('WEBGL_lose_context');
  if (lose) lose.loseContext();
  return { webgl2: true, renderer };
}
