// Direct-light initialisation (antiradiance paper, Sec. 3.3): the shadowed irradiance E_d
// of every punctual light at every receiver (hierarchy leaf), E_d = Φ · att · cosθ / d² · V
// (point, spot) or E⊥ · cosθ · V (directional), V averaged over 16 taps on the receiver's
// footprint, each a bilinear 2×2 shadow-map comparison. Writes the local pass's E_d table;
// makes no antiradiance. direct/direct_light.cpp (DirectIrradiance) is the CPU twin: keep
// the arithmetic in step.
#version 450

layout(local_size_x = 64) in;

// direct/direct_light.h: GpuLight, GpuShadowView, GpuReceiver.
struct Light {
    vec4 position;   // w: 0 point, 1 spot, 2 directional
    vec4 direction;  // w: range (0 none)
    vec4 radiant;
    vec4 cone;       // cos outer, 1/(cos inner − cos outer), first view, view count
    vec4 cube;       // cube lights: f/(f−n), n·f/(f−n), 1/tan(half fov), texel per metre
};
struct View {
    mat4 viewProj;
    vec4 eye;      // w = 1: orthographic
    vec4 forward;  // w: texel world size (per metre of depth when perspective)
};
struct Receiver {
    vec4 position;  // w: footprint radius
    vec4 normal;
    vec4 middle;  // the footprint centre (C++: centroid; `centroid` is a GLSL keyword)
};

layout(std430, binding = 0) readonly buffer Receivers { Receiver receivers[]; };
layout(std430, binding = 1) readonly buffer Lights { Light lights[]; };
// Views (24 floats each: viewProj, eye, forward) and depth maps through texel buffers: the
// taps read them at per-lane places, which lavapipe gathers in vector registers where it
// loads storage buffers lane by lane (gpu/pipeline.h, Slot).
layout(binding = 2) uniform samplerBuffer views;
layout(binding = 3) uniform samplerBuffer maps;
layout(std430, binding = 4) writeonly buffer Out { vec4 direct[]; };
// Each light's share, light-major: perLight[light · receiverCount + receiver].
layout(std430, binding = 5) writeonly buffer PerLight { vec4 perLight[]; };

layout(push_constant) uniform Push {
    uint receiverCount;
    uint lightCount;
    uint size;
} pc;

const int kTaps = 16;

vec4 ViewRow(int vi, int k) {
    int at = 24 * vi + 4 * k;
    return vec4(texelFetch(views, at).x, texelFetch(views, at + 1).x, texelFetch(views, at + 2).x,
                texelFetch(views, at + 3).x);
}

View LoadView(int vi) {
    return View(mat4(ViewRow(vi, 0), ViewRow(vi, 1), ViewRow(vi, 2), ViewRow(vi, 3)),
                ViewRow(vi, 4), ViewRow(vi, 5));
}

float Depth(uint at) { return texelFetch(maps, int(at)).x; }

// Which face of a cube light sees the point at v from the light (+x, −x, +y, −y, +z, −z).
int CubeFace(vec3 v) {
    vec3 a = abs(v);
    if (a.x >= a.y && a.x >= a.z) return v.x >= 0.0 ? 0 : 1;
    if (a.y >= a.z) return v.y >= 0.0 ? 2 : 3;
    return v.z >= 0.0 ? 4 : 5;
}

// The lit fraction of a bilinear 2×2 footprint of view vi's map around ndc.
float MapVisibility(int vi, vec3 ndc) {
    if (abs(ndc.x) > 1.0 || abs(ndc.y) > 1.0 || ndc.z < 0.0 || ndc.z > 1.0) return 1.0;
    int size = int(pc.size);
    float u = (ndc.x * 0.5 + 0.5) * float(size) - 0.5;
    float v = (ndc.y * 0.5 + 0.5) * float(size) - 0.5;
    float fu = floor(u), fv = floor(v);
    float wu = u - fu, wv = v - fv;
    int x0 = int(fu), y0 = int(fv);
    uint base = uint(vi) * uint(size) * uint(size);
    int xa = clamp(x0, 0, size - 1), xb = clamp(x0 + 1, 0, size - 1);
    int ya = clamp(y0, 0, size - 1), yb = clamp(y0 + 1, 0, size - 1);
    float l00 = ndc.z <= Depth(base + uint(ya * size + xa)) ? 1.0 : 0.0;
    float l10 = ndc.z <= Depth(base + uint(ya * size + xb)) ? 1.0 : 0.0;
    float l01 = ndc.z <= Depth(base + uint(yb * size + xa)) ? 1.0 : 0.0;
    float l11 = ndc.z <= Depth(base + uint(yb * size + xb)) ? 1.0 : 0.0;
    return (1.0 - wv) * ((1.0 - wu) * l00 + wu * l10) + wv * ((1.0 - wu) * l01 + wu * l11);
}

// Where a tap at q falls in its light's shadow maps: the view and NDC (w = 0 when q is
// behind the view: lit). A single-view light's view is loaded once a receiver (`view`); a
// cube light's tap takes its face and the face's projection from light.cube, the frame as
// glm::lookAtRH builds it, so no view is loaded per tap (24 texel fetches on lavapipe).
// Both projections are plain arithmetic and selected without a branch: lavapipe would run
// both sides of one anyway.
vec4 TapNdc(Light light, View view, vec3 q, vec3 n, vec3 toLight, out int vi) {
    vec3 eye = light.position.xyz;
    int face = CubeFace(q - eye);
    vec3 forward = vec3(0.0);
    forward[face / 2] = (face & 1) != 0 ? -1.0 : 1.0;
    bool cube = light.cone.w >= 6.0;
    vi = int(light.cone.z) + (cube ? face : 0);
    float texel;
    if (cube)
        texel = light.cube.w * max(dot(q - eye, forward), 0.0);
    else
        texel = view.eye.w > 0.5 ? view.forward.w
                                 : view.forward.w * max(dot(q - view.eye.xyz, view.forward.xyz), 0.0);
    q += n * (2.0 * texel) + toLight * texel;
    // The cube face's projection (CubeNdc in C++).
    vec3 up = abs(forward.y) > 0.9 ? vec3(0.0, 0.0, 1.0) : vec3(0.0, 1.0, 0.0);
    vec3 right = cross(forward, up), top = cross(right, forward);
    vec3 v = q - eye;
    float depth = dot(forward, v);
    vec4 faceClip = vec4(dot(right, v) * light.cube.z, dot(top, v) * light.cube.z,
                         light.cube.x * depth - light.cube.y, depth);
    vec4 clip = cube ? faceClip : view.viewProj * vec4(q, 1.0);
    if (!(clip.w > 0.0)) return vec4(0.0);
    return vec4(clip.xyz / clip.w, 1.0);
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.receiverCount) return;
    Receiver r = receivers[i];
    vec3 p = r.position.xyz, n = r.normal.xyz, c = r.middle.xyz;
    // Branchless orthonormal basis (Duff et al. 2017), as TangentBasis in C++.
    float sgn = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sgn + n.z);
    float bb = n.x * n.y * a;
    vec3 t = vec3(1.0 + sgn * n.x * n.x * a, sgn * bb, -sgn * n.x);
    vec3 b = vec3(bb, sgn + n.y * n.y * a, -n.y);
    vec3 e = vec3(0.0);
    for (uint li = 0u; li < pc.lightCount; ++li) {
        Light light = lights[li];
        perLight[li * pc.receiverCount + i] = vec4(0.0);
        vec3 toLight;
        float scale;
        if (light.position.w == 2.0) {
            toLight = -light.direction.xyz;
            scale = 1.0;
        } else {
            vec3 v = light.position.xyz - p;
            float d2 = dot(v, v);
            if (!(d2 > 1e-12)) continue;
            float d = sqrt(d2);
            toLight = v / d;
            scale = 1.0 / d2;
            if (light.direction.w > 0.0) {
                float x = d / light.direction.w;
                float w = clamp(1.0 - x * x * x * x, 0.0, 1.0);
                scale *= w * w;
            }
            if (light.position.w == 1.0) {
                float s = clamp((dot(light.direction.xyz, -toLight) - light.cone.x) * light.cone.y,
                                0.0, 1.0);
                scale *= s * s;
            }
        }
        float cosine = dot(n, toLight);
        if (cosine <= 0.0 || scale <= 0.0) continue;
        float visible = 0.0;
        View view = LoadView(int(light.cone.z));  // single-view lights: once, not per tap
        for (int k = 0; k < kTaps; ++k) {
            float rr = r.position.w * sqrt((float(k) + 0.5) / float(kTaps));
            float phi = 2.3999632 * float(k);
            vec3 q = c + rr * (cos(phi) * t + sin(phi) * b);
            vec3 qToLight = light.position.w == 2.0 ? toLight : normalize(light.position.xyz - q);
            int vi;
            vec4 ndc = TapNdc(light, view, q, n, qToLight, vi);
            visible += ndc.w > 0.0 ? MapVisibility(vi, ndc.xyz) : 1.0;
        }
        vec3 ek = light.radiant.xyz * (scale * cosine * visible / float(kTaps));
        e += ek;
        perLight[li * pc.receiverCount + i] = vec4(ek, 0.0);
    }
    direct[i] = vec4(e, 0.0);
}
