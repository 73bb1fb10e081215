// Directions' tables on a Vulkan device, as LookupBin (shaders/directions.glsl) reads them:
// the bins' directions (a vec4 each), the coarse cube map (Directions::CubeTable) and every
// bin's neighbours padded to one width (Directions::PaddedAdjacency).
#pragma once

#include <glm/vec4.hpp>
#include <vector>

#include "gpu/buffer.h"
#include "hierarchy/directions.h"

namespace penumbra {

struct DeviceDirections {
    gpu::Buffer dirs, cube;
    std::unique_ptr<gpu::Buffer> adjacent;
    uint32_t adjacentWidth = 0;

    DeviceDirections(gpu::Context& ctx, const Directions& d)
        : dirs(ctx, size_t(d.Count()) * sizeof(glm::vec4)),
          cube(ctx, d.CubeTable().size() * sizeof(uint32_t)) {
        std::vector<glm::vec4> up;
        for (const glm::vec3& w : d.All()) up.emplace_back(w, 0.0f);
        dirs.Upload(up);
        cube.Upload(d.CubeTable());
        const std::vector<uint32_t> adj = d.PaddedAdjacency(adjacentWidth);
        adjacent = gpu::MakeBuffer(ctx, adj.size() * sizeof(uint32_t));
        adjacent->Upload(adj);
    }
};

}  // namespace penumbra
