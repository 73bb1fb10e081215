// Shadow pass, fragment stage: the fragment's depth into a float colour target. With the
// depth test LESS the colour that remains is the nearest surface's depth (gpu::RenderTarget).
#version 450

layout(location = 0) out float depth;

void main() { depth = gl_FragCoord.z; }
