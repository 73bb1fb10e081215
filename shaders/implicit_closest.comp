// One round of the implicit solver's link creation with the paper's closest rule (bin-cover
// closest): implicit_pairs.glsl with CLOSEST, each link kept in its (node, bin) slot when it is
// the closest there, by 64-bit atomicMin (shaderInt64 and shaderBufferInt64Atomics: the
// device must have them, gpu::Context::Int64Atomics).
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

#define CLOSEST
#include "implicit_pairs.glsl"
