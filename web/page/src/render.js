// The trial's panes drawn with WebGL (three.js) as the study window draws them
// (window/src/render.rs, skeleton.wgsl, scene.rs): shaded instanced cylinders for the bones,
// orange spheres for the joints, soft shadow discs on a grid floor that fades into the
// background, seen through the scene's camera at the presentation time. The clips are the
// server's joint positions in cm (format MCJP, web/src/clipdata.rs); the scene (camera,
// ground, light, panes and their figures) comes with the trial. shapes.js holds the math.
import * as THREE from 'three';
import { INSTANCE_FLOATS, Posed, cameraAt, cylinderMesh, sphereMesh } from './shapes.js';

// Colours are written to the canvas as they are, like the window's non-sRGB (Unorm) target:
// no colour management anywhere (output colour space linear = no encoding, raw shaders).
/** The pane's background: the window fills a pane with egui's Color32 of BACKGROUND
 * [0.20, 0.21, 0.24], bytes truncated (51, 53, 61). */
const BACKGROUND = [51 / 255, 53 / 255, 61 / 255];
/** The grey between stimuli and around the panes (egui gray 96). */
const GREY = [96 / 255, 96 / 255, 96 / 255];

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

const MESH_VERTEX = /* glsl */ `
precision highp float;
uniform mat4 viewProj;
in vec3 position;
in vec3 normal;
in vec3 iPosition;
in vec4 iRotation;
in vec3 iScale;
in vec4 iColor;
out vec3 vNormal;
out vec4 vColor;
out vec3 vLocal;
vec3 rotate(vec4 q, vec3 v) {
  vec3 t = 2.0 * cross(q.xyz, v);
  return v + q.w * t + cross(q.xyz, t);
}
void main() {
  vec3 world = iPosition + rotate(iRotation, position * iScale);
  gl_Position = viewProj * vec4(world, 1.0);
  vNormal = rotate(iRotation, normal / iScale);
  vColor = iColor;
  vLocal = position;
}`;

const MESH_FRAGMENT = /* glsl */ `
precision highp float;
uniform vec4 light;
in vec3 vNormal;
in vec4 vColor;
in vec3 vLocal;
out vec4 outColor;
void main() {
  vec3 n = normalize(vNormal);
  float diffuse = max(dot(n, light.xyz), 0.0);
  float fill = 0.5 + 0.5 * n.y;
  float shade = light.w * fill + (1.0 - light.w) * diffuse;
  outColor = vec4(vColor.rgb * shade, 1.0);
}`;

const SHADOW_FRAGMENT = /* glsl */ `
precision highp float;
in vec3 vNormal;
in vec4 vColor;
in vec3 vLocal;
out vec4 outColor;
void main() {
  float r = length(vLocal.xz);
  float soft = 1.0 - smoothstep(0.35, 1.0, r);
  outColor = vec4(vColor.rgb, vColor.a * soft);
}`;

const GROUND_VERTEX = /* glsl */ `
precision highp float;
uniform mat4 viewProj;
// x, z: ground centre; y: half side; w: ground height.
uniform vec4 ground;
in vec3 position;
out vec3 vWorld;
void main() {
  vec3 world = vec3(ground.x + position.x * ground.y, ground.w, ground.z + position.z * ground.y);
  gl_Position = viewProj * vec4(world, 1.0);
  vWorld = world;
}`;

const GROUND_FRAGMENT = /* glsl */ `
precision highp float;
uniform vec4 ground;
uniform float grid;
in vec3 vWorld;
out vec4 outColor;
void main() {
  vec2 cell = vWorld.xz / grid;
  vec2 width = max(fwidth(cell), vec2(1e-4, 1e-4));
  vec2 d = abs(fract(cell - 0.5) - 0.5) / width;
  float line = 1.0 - min(min(d.x, d.y), 1.0);
  float r = length(vWorld.xz - vec2(ground.x, ground.z)) / ground.y;
  float fade = clamp(1.3 - r, 0.0, 1.0);
  vec3 base = vec3(0.46, 0.47, 0.50);
  vec3 gridColor = vec3(0.30, 0.31, 0.34);
  vec3 sky = vec3(0.20, 0.21, 0.24);
  vec3 col = mix(base, gridColor, line);
  outColor = vec4(mix(sky, col, fade), 1.0);
}`;

/** The unit meshes (window: cylinder_mesh(10), sphere_mesh(6, 10)), made once. */
const CYLINDER = cylinderMesh(10);
const SPHERE = sphereMesh(6, 10);

/** An instanced geometry of `mesh` with room for `capacity` instances. */
function instanced(mesh, capacity) {
  const g = new THREE.InstancedBufferGeometry();
  const base = new THREE.InterleavedBuffer(mesh.vertices, 6);
  g.setAttribute('position', new THREE.InterleavedBufferAttribute(base, 3, 0));
  g.setAttribute('normal', new THREE.InterleavedBufferAttribute(base, 3, 3));
  g.setIndex(new THREE.BufferAttribute(mesh.indices, 1));
  const data = new Float32Array(Math.max(1, capacity) * INSTANCE_FLOATS);
  const buf = new THREE.InstancedInterleavedBuffer(data, INSTANCE_FLOATS, 1);
  buf.setUsage(THREE.DynamicDrawUsage);
  g.setAttribute('iPosition', new THREE.InterleavedBufferAttribute(buf, 3, 0));
  g.setAttribute('iRotation', new THREE.InterleavedBufferAttribute(buf, 4, 3));
  g.setAttribute('iScale', new THREE.InterleavedBufferAttribute(buf, 3, 7));
  g.setAttribute('iColor', new THREE.InterleavedBufferAttribute(buf, 4, 10));
  g.instanceCount = 0;
  return { geometry: g, data, buf, capacity: Math.max(1, capacity) };
}

/** A pane's instance buffers (bones, joints, shadows), reused across trials while big enough. */
class Slot {
  constructor() {
    this.parts = { bones: null, joints: null, shadows: null };
  }

  /** Makes room for `need` ({ bones, joints, shadows }) instances. */
  ensure(need) {
    for (const [name, mesh] of [['bones', CYLINDER], ['joints', SPHERE], ['shadows', SPHERE]]) {
      const have = this.parts[name];
      if (have && have.capacity >= need[name]) continue;
      if (have) have.geometry.dispose();
      // Some headroom so that a slightly larger next trial does not reallocate.
      this.parts[name] = instanced(mesh, Math.ceil(Math.max(need[name], 16) * 1.25));
    }
  }

  /** The instance arrays and the offsets to write at. */
  arrays() {
    return { bones: this.parts.bones.data, joints: this.parts.joints.data, shadows: this.parts.shadows.data };
  }

  /** Uploads the first `counts` instances of each part. */
  commit(counts) {
    for (const name of ['bones', 'joints', 'shadows']) {
      const p = this.parts[name];
      p.geometry.instanceCount = counts[name];
      if (counts[name] > 0) {
        p.buf.clearUpdateRanges();
        p.buf.addUpdateRange(0, counts[name] * INSTANCE_FLOATS);
        p.buf.needsUpdate = true;
      }
    }
  }

  dispose() {
    for (const name of ['bones', 'joints', 'shadows']) {
      if (this.parts[name]) this.parts[name].geometry.dispose();
      this.parts[name] = null;
    }
  }
}

/** The stage: one canvas over the stimulus area, the trial's panes drawn in rectangles of it. */
export class Stage {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({
      canvas,
      antialias: true,
      alpha: false,
      depth: true,
      stencil: false,
      preserveDrawingBuffer: false,
    });
    // The canvas is sized in device pixels here (pixel ratio 1 to three), so that viewports
    // and scissors are exact integers.
    this.renderer.setPixelRatio(1);
    this.renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    this.renderer.autoClear = false;
    this.renderer.sortObjects = true;
    this.renderer.setScissorTest(true);
    this.clearColor = new THREE.Color();

    this.uniforms = {
      viewProj: { value: new THREE.Matrix4() },
      light: { value: new THREE.Vector4(0, 1, 0, 0.35) },
      ground: { value: new THREE.Vector4(0, 1, 0, 0) },
      grid: { value: 100 },
    };
    const raw = (vertexShader, fragmentShader, extra) =>
      new THREE.RawShaderMaterial({
        glslVersion: THREE.GLSL3,
        vertexShader,
        fragmentShader,
        uniforms: this.uniforms,
        depthTest: true,
        depthWrite: true,
        depthFunc: THREE.LessDepth,
        transparent: false,
        blending: THREE.NoBlending,
        side: THREE.FrontSide,
        ...extra,
      });
    this.materials = {
      mesh: raw(MESH_VERTEX, MESH_FRAGMENT, {}),
      // Blended over the ground, tested against it, writing no depth (window: shadow_pipeline).
      shadow: raw(MESH_VERTEX, SHADOW_FRAGMENT, {
        depthWrite: false,
        blending: THREE.CustomBlending,
        blendEquation: THREE.AddEquation,
        blendSrc: THREE.SrcAlphaFactor,
        blendDst: THREE.OneMinusSrcAlphaFactor,
        blendEquationAlpha: THREE.AddEquation,
        blendSrcAlpha: THREE.OneFactor,
        blendDstAlpha: THREE.OneMinusSrcAlphaFactor,
      }),
      ground: raw(GROUND_VERTEX, GROUND_FRAGMENT, { side: THREE.DoubleSide }),
    };
    // The ground: a square of corners ±1 in x and z, placed by the shader.
    const quad = new THREE.BufferGeometry();
    quad.setAttribute(
      'position',
      new THREE.BufferAttribute(new Float32Array([-1, 0, -1, 1, 0, -1, 1, 0, 1, -1, 0, -1, 1, 0, 1, -1, 0, 1]), 3),
    );
    this.quad = quad;
    // One scene whose meshes take each pane's geometries in turn; drawn in the window's
    // order: ground, shadows, bones, joints.
    this.scene3 = new THREE.Scene();
    this.scene3.matrixWorldAutoUpdate = false;
    const mesh = (geometry, material, order) => {
      const m = new THREE.Mesh(geometry, material);
      m.frustumCulled = false;
      m.renderOrder = order;
      m.matrixAutoUpdate = false;
      this.scene3.add(m);
      return m;
    };
    this.placeholder = new THREE.BufferGeometry();
    this.meshes = {
      ground: mesh(quad, this.materials.ground, 0),
      shadows: mesh(this.placeholder, this.materials.shadow, 1),
      bones: mesh(this.placeholder, this.materials.mesh, 2),
      joints: mesh(this.placeholder, this.materials.mesh, 3),
    };
    for (const m of [this.meshes.shadows, this.meshes.bones, this.meshes.joints]) m.visible = false;
    // three wants a camera; the shaders use the scene's own matrix (uniform viewProj).
    this.camera = new THREE.PerspectiveCamera();
    this.slots = [];
    this.scene = null;
    this.panes = [];
  }

  /**
   * Shows `scene` (the trial's camera, ground, light and panes) with `clips` (parsed MCJP
   * clips indexed by the figures' `clip`) from now on.
   */
  load(scene, clips) {
    if (!scene || !scene.camera || !Array.isArray(scene.panes)) throw new Error('a scene without camera or panes');
    const panes = scene.panes.map((pane, k) =>
      (pane.figures || []).map((fig, i) => {
        const clip = clips[fig.clip];
        if (!clip) throw new Error(`pane ${k} figure ${i}: no clip ${fig.clip}`);
        return new Posed(clip, fig);
      }),
    );
    const shadow = scene.shadow !== false;
    this.scene = scene;
    this.panes = panes;
    this.shadow = shadow;
    // A pane's slot is kept while big enough; slots of panes no longer shown are freed.
    while (this.slots.length > panes.length) this.slots.pop().dispose();
    panes.forEach((figs, k) => {
      if (!this.slots[k]) this.slots[k] = new Slot();
      let bones = 0;
      let joints = 0;
      for (const f of figs) {
        bones += f.bones;
        joints += f.clip.joints;
      }
      this.slots[k].ensure({ bones, joints, shadows: shadow ? bones + joints : 0 });
    });
    const l = scene.light || [0.34912827, 0.8478829, 0.39900373, 0.35];
    const n = Math.max(Math.hypot(l[0], l[1], l[2]), 1e-6);
    this.uniforms.light.value.set(l[0] / n, l[1] / n, l[2] / n, l[3]);
    const grid = Number(scene.ground && scene.ground.grid);
    this.uniforms.grid.value = grid > 0 ? grid : 100;
  }

  /** The canvas' size in CSS pixels, its backing store resized to device pixels if needed. */
  resize() {
    const w = this.canvas.clientWidth;
    const h = this.canvas.clientHeight;
    const dpr = window.devicePixelRatio || 1;
    const dw = Math.max(1, Math.round(w * dpr));
    const dh = Math.max(1, Math.round(h * dpr));
    if (this.canvas.width !== dw || this.canvas.height !== dh) this.renderer.setSize(dw, dh, false);
    return { w, h, dpr, dw, dh };
  }

  /**
   * Draws one frame: each rectangle of `layout` ({ pane, x, y, w, h }, CSS pixels from the
   * canvas' top-left) shows its pane at `t` seconds; the rest of the canvas is grey 96
   * (all of it when `layout` is empty: the grey between stimuli).
   */
  draw(layout, t) {
    const { dpr, dw, dh } = this.resize();
    const r = this.renderer;
    r.setViewport(0, 0, dw, dh);
    r.setScissor(0, 0, dw, dh);
    this.clear(GREY);
    for (const rect of layout || []) {
      const x0 = Math.round(rect.x * dpr);
      const x1 = Math.round((rect.x + rect.w) * dpr);
      const y0 = Math.round(rect.y * dpr);
      const y1 = Math.round((rect.y + rect.h) * dpr);
      if (x1 <= x0 || y1 <= y0) continue;
      // WebGL counts rows from the bottom.
      r.setViewport(x0, dh - y1, x1 - x0, y1 - y0);
      r.setScissor(x0, dh - y1, x1 - x0, y1 - y0);
      this.clear(BACKGROUND);
      if (this.scene && this.panes[rect.pane]) this.drawPane(rect.pane, t, rect.w / Math.max(rect.h, 1e-6));
    }
  }

  clear(rgb) {
    this.renderer.setClearColor(this.clearColor.setRGB(rgb[0], rgb[1], rgb[2], THREE.LinearSRGBColorSpace), 1);
    this.renderer.clear(true, true, false);
  }

  /** Pane `k` at `t` into the current viewport, of aspect `aspect`. */
  drawPane(k, t, aspect) {
    const scene = this.scene;
    const cam = cameraAt(scene.camera, aspect, t);
    const u = this.uniforms;
    u.viewProj.value.fromArray(cam.viewProj);
    const g = scene.ground || {};
    u.ground.value.set(cam.ground[0], Number(g.half) || 0, cam.ground[1], Number(g.y) || 0);
    const slot = this.slots[k];
    const out = slot.arrays();
    const at = { bones: 0, joints: 0, shadows: 0 };
    for (const f of this.panes[k]) {
      if (f.clip.frames <= 0) continue;
      const n = f.shapes(t, this.shadow, out, at);
      at.bones += n.bones;
      at.joints += n.joints;
      at.shadows += n.shadows;
    }
    slot.commit(at);
    const m = this.meshes;
    m.bones.geometry = slot.parts.bones.geometry;
    m.joints.geometry = slot.parts.joints.geometry;
    m.shadows.geometry = slot.parts.shadows.geometry;
    m.bones.visible = at.bones > 0;
    m.joints.visible = at.joints > 0;
    m.shadows.visible = at.shadows > 0;
    m.ground.visible = (Number(g.half) || 0) > 0;
    for (const mat of Object.values(this.materials)) mat.uniformsNeedUpdate = true;
    this.renderer.render(this.scene3, this.camera);
  }

  /** Frees the stage's WebGL resources. */
  dispose() {
    for (const s of this.slots) s.dispose();
    this.slots = [];
    this.quad.dispose();
    this.placeholder.dispose();
    for (const m of Object.values(this.materials)) m.dispose();
    this.renderer.dispose();
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
