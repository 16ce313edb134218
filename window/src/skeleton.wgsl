// Shaded skeletons (instanced unit cylinders and spheres), a ground plane with a grid, and a
// ground shadow (flattened spheres blended over the ground, soft at their rims).

struct Globals {
    view_proj: mat4x4<f32>,
    // xyz: direction towards the light (unit), w: ambient share.
    light: vec4<f32>,
    // x, z: ground centre; y: half side; w: ground height.
    ground: vec4<f32>,
    // x: grid spacing (one metre in clip units).
    grid: vec4<f32>,
};

@group(0) @binding(0) var<uniform> g: Globals;

struct MeshIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) i_position: vec3<f32>,
    @location(3) i_rotation: vec4<f32>,
    @location(4) i_scale: vec3<f32>,
    @location(5) i_color: vec4<f32>,
};

struct MeshOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
    // The mesh vertex before placement (the shadow's radial falloff).
    @location(2) local: vec3<f32>,
};

fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

@vertex
fn vs_mesh(in: MeshIn) -> MeshOut {
    var out: MeshOut;
    let world = in.i_position + rotate(in.i_rotation, in.position * in.i_scale);
    out.clip = g.view_proj * vec4<f32>(world, 1.0);
    // Inverse-transpose of rotation × scale applied to the normal.
    out.normal = rotate(in.i_rotation, in.normal / in.i_scale);
    out.color = in.i_color;
    out.local = in.position;
    return out;
}

@fragment
fn fs_shadow(in: MeshOut) -> @location(0) vec4<f32> {
    let r = length(in.local.xz);
    let soft = 1.0 - smoothstep(0.35, 1.0, r);
    return vec4<f32>(in.color.rgb, in.color.a * soft);
}

@fragment
fn fs_mesh(in: MeshOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let diffuse = max(dot(n, g.light.xyz), 0.0);
    let fill = 0.5 + 0.5 * n.y;
    let shade = g.light.w * fill + (1.0 - g.light.w) * diffuse;
    return vec4<f32>(in.color.rgb * shade, 1.0);
}

struct GroundOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
};

@vertex
fn vs_ground(@builtin(vertex_index) i: u32) -> GroundOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[i];
    let world = vec3<f32>(g.ground.x + c.x * g.ground.y, g.ground.w, g.ground.z + c.y * g.ground.y);
    var out: GroundOut;
    out.clip = g.view_proj * vec4<f32>(world, 1.0);
    out.world = world;
    return out;
}

@fragment
fn fs_ground(in: GroundOut) -> @location(0) vec4<f32> {
    let cell = in.world.xz / g.grid.x;
    let width = max(fwidth(cell), vec2<f32>(1e-4, 1e-4));
    let d = abs(fract(cell - 0.5) - 0.5) / width;
    let line = 1.0 - min(min(d.x, d.y), 1.0);
    let r = length(in.world.xz - vec2<f32>(g.ground.x, g.ground.z)) / g.ground.y;
    let fade = clamp(1.3 - r, 0.0, 1.0);
    let base = vec3<f32>(0.46, 0.47, 0.50);
    let grid = vec3<f32>(0.30, 0.31, 0.34);
    let sky = vec3<f32>(0.20, 0.21, 0.24);
    let col = mix(base, grid, line);
    return vec4<f32>(mix(sky, col, fade), 1.0);
}
