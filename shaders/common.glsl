// Structs and constants shared by the antiradiance compute shaders. The C++ side of
// each struct is named beside it and locked there with static_assert.

// Bins per element (Directions::Count), and the workgroup size.
layout(constant_id = 0) const uint WORKGROUP = 64;
layout(constant_id = 1) const uint BINS = 128;

// links/links.h: struct Link (12 bytes). binLevel = bin | level << 16.
struct Link {
    uint sender;
    uint binLevel;
    float formFactor;
};

// hierarchy/directions.h: struct BinWeight (8 bytes).
struct BinWeight {
    uint bin;
    float weight;
};

// solvers/antiradiance/model.h: struct LeafAttributes (64 bytes).
struct Leaf {
    vec3 normal;
    float area;
    vec3 albedo;
    float cosNormIn;
    vec3 emission;
    float cosNormOut;
    uint node;
    uint parent;
    uint surfel;
    uint flags;  // kLeafTwoSided | kLeafGlossy | glossy index << kGlossyShift
};
const uint kLeafTwoSided = 1u;
const uint kLeafGlossy = 2u;
const uint kGlossyShift = 8u;

// solvers/antiradiance/model.h: struct GlossyLeaf (16 bytes).
struct GlossyLeaf {
    vec3 specular;  // F0
    uint lobe;
};
// solvers/antiradiance/model.h: struct GlossyLobe (16 bytes).
struct Lobe {
    uint start;
    uint width;
    float exponent;
    float norm;
};

const uint kReflect = 1u;
const uint kAntiradiance = 2u;
