// Structs shared between C++ and a shader are written twice, once in each language; this
// locks the C++ side to the shader's layout (std430 buffers and push constants), beside each
// struct: a field moved, retyped or added on one side fails the build.
#pragma once

#include <cstddef>
#include <type_traits>

// Field `field` of `Type` sits at byte `offset`, as the shader named beside `Type` reads it.
#define PENUMBRA_GPU_FIELD(Type, field, offset)      \
    static_assert(offsetof(Type, field) == (offset), \
                  #Type "::" #field " must sit at byte " #offset ", where the shader reads it")

// `Type` is `count` 4-byte scalars (uint, int, float) one after another, as the shader's block
// declares them in the same order: with no padding their declaration order is their offsets
// (field i at byte 4·i), so its size is all there is to check.
#define PENUMBRA_GPU_WORDS(Type, count)                                                       \
    static_assert(                                                                            \
        std::is_standard_layout_v<Type> && alignof(Type) == 4 && sizeof(Type) == 4 * (count), \
        #Type " must be " #count " 4-byte scalars in the order the shader reads them")
