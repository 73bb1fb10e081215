// Structs shared between C++ and a shader are written twice, once in each language; this
// locks the C++ side to the shader's layout field by field (std430 buffers and push
// constants), beside each struct: a field moved or retyped on one side fails the build.
#pragma once

#include <cstddef>

// Field `field` of `Type` sits at byte `offset`, as the shader named beside `Type` reads it.
#define PENUMBRA_GPU_FIELD(Type, field, offset)      \
    static_assert(offsetof(Type, field) == (offset), \
                  #Type "::" #field " must sit at byte " #offset ", where the shader reads it")
