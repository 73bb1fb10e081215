// Light-field lines by depth peeling, fragment stage: a layer keeps, per line (pixel), the
// nearest surface behind the one layer k − 1 kept there (Everitt 2001's depth peeling: the
// fixed-function depth test LESS picks the nearest fragment this shader does not discard).
// Writes (depth, triangle + 1, u, v); a line with nothing left keeps the clear value
// (1, 0, 0, 0), and a layer after it then discards everything.
#version 450

layout(std430, binding = 1) readonly buffer Layers { vec4 layers[]; };

layout(push_constant) uniform Push {
    mat4 view;
    uint layer;
    uint size;
    uint previousOffset;
} pc;

layout(location = 0) flat in uint triangle;
layout(location = 1) noperspective in vec2 bary;
layout(location = 0) out vec4 hit;

void main() {
    if (pc.layer > 0u) {
        const uvec2 cell = uvec2(gl_FragCoord.xy);
        if (gl_FragCoord.z <= layers[pc.previousOffset + cell.y * pc.size + cell.x].x) discard;
    }
    hit = vec4(gl_FragCoord.z, float(triangle + 1u), bary);
}
