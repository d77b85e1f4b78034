// Scene shaders for leman's renderer: shaded triangles (skin, muscles, bones, joints, wand) and
// coloured lines (floor grid, skeleton, springs, fat, cursor, screen border).
// One uniform block per eye pass (bound with a dynamic offset): the eye's clip_from_world made by
// the stereo module, the eye position for the headlight, the key light direction, and a row filter
// for row-interleaved stereo (fragments on the other eye's rows are discarded).

struct PassUniforms {
    clip_from_world: mat4x4<f32>,
    // xyz: eye position in the world (metres).
    eye_position_world: vec4<f32>,
    // xyz: unit direction towards the key light (world).
    key_light_direction: vec4<f32>,
    // x: 0 = every row, 1 = keep even rows only, 2 = keep odd rows only (rows counted from the
    // top of the target); y: added to the row number before the parity test.
    row_filter: vec4<u32>,
};

@group(0) @binding(0) var<uniform> pass_u: PassUniforms;

fn row_visible(frag_y: f32) -> bool {
    let mode = pass_u.row_filter.x;
    if mode == 0u {
        return true;
    }
    let row = u32(floor(frag_y)) + pass_u.row_filter.y;
    return (row & 1u) == (mode - 1u);
}

struct LitIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
};

struct LitOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
};

@vertex
fn vs_lit(v: LitIn) -> LitOut {
    var out: LitOut;
    out.clip = pass_u.clip_from_world * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.color = v.color;
    return out;
}

fn shade(in: LitOut) -> vec4<f32> {
    var n = normalize(in.normal);
    let to_eye = normalize(pass_u.eye_position_world.xyz - in.world);
    // Two-sided lighting: a surface seen from behind is lit as its visible side.
    if dot(n, to_eye) < 0.0 {
        n = -n;
    }
    let key = normalize(pass_u.key_light_direction.xyz);
    let headlight = max(dot(n, to_eye), 0.0);
    let key_diffuse = max(dot(n, key), 0.0);
    let half_vector = normalize(key + to_eye);
    let specular = pow(max(dot(n, half_vector), 0.0), 40.0) * 0.25;
    let light = 0.12 + 0.45 * headlight + 0.55 * key_diffuse;
    return vec4<f32>(in.color.rgb * light + vec3<f32>(specular), in.color.a);
}

// Without a discard (every row): lets the GPU test depth before shading.
@fragment
fn fs_lit(in: LitOut) -> @location(0) vec4<f32> {
    return shade(in);
}

// Row-interleaved passes: fragments on the other eye's rows are discarded.
@fragment
fn fs_lit_rows(in: LitOut) -> @location(0) vec4<f32> {
    if !row_visible(in.clip.y) {
        discard;
    }
    return shade(in);
}

struct LineIn {
    @location(0) position: vec3<f32>,
    @location(1) color: vec4<f32>,
};

struct LineOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
};

@vertex
fn vs_line(v: LineIn) -> LineOut {
    var out: LineOut;
    out.clip = pass_u.clip_from_world * vec4<f32>(v.position, 1.0);
    out.color = v.color;
    return out;
}

@fragment
fn fs_line(in: LineOut) -> @location(0) vec4<f32> {
    return in.color;
}

@fragment
fn fs_line_rows(in: LineOut) -> @location(0) vec4<f32> {
    if !row_visible(in.clip.y) {
        discard;
    }
    return in.color;
}
