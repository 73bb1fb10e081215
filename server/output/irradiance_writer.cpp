// JSON via nlohmann::json; glTF via tinygltf (load the input, add accessors, write).
#include "output/irradiance_writer.h"

#include <tiny_gltf.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "base/check.h"
#include "base/image.h"
#include "scene/gltf_loader.h"

namespace penumbra {

IrradianceResult CollectIrradiance(const Scene& scene, Solver& solver, Channel channel) {
    IrradianceResult r;
    r.channel = ChannelName(channel);
    std::vector<glm::vec3> surfel = solver.SurfelIrradiance(channel);
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        r.primitives.push_back(PrimitiveIrradiance(solver.GetSurfels(), surfel, scene, p));
    r.solver = solver.Stats().solver;
    r.stats = StatsToJson(solver.Stats());
    return r;
}

nlohmann::json StatsToJson(const SolverStats& s) {
    nlohmann::json j;
    j["solver"] = s.solver;
    j["device"] = s.device;
    j["elements"] = s.elements;
    j["nodes"] = s.nodes;
    j["links"] = s.links;
    j["bins"] = s.bins;
    j["iterations"] = s.iterations;
    j["element_size"] = s.elementSize;
    j["link_build_seconds"] = s.linkBuildSeconds;
    j["setup_seconds"] = s.setupSeconds;
    j["ms_per_iteration"] = s.MsPerIteration();
    j["passes_run"] = s.gathers;
    j["ms_per_pass"] = s.gathers ? s.msTotal / s.gathers : 0.0;
    if (s.lights > 0) {
        j["punctual_lights"] = s.lights;
        j["shadow_views"] = s.lighting.shadowViews;
        j["shadow_map_size"] = s.lighting.shadowMapSize;
        j["shadow_ms"] = s.lighting.msShadow;
        j["direct_ms"] = s.lighting.msDirect;
    }
    if (!s.lighting.environment.empty())
        j["environment"] = {
            {"source", s.lighting.environment},
            {"intensity", s.lighting.environmentIntensity},
            {"rotation_degrees", s.lighting.environmentRotation * 57.29577951308232}};
    j["two_sided_elements"] = s.twoSidedElements;
    j["glossy_elements"] = s.glossyElements;
    if (s.motion.groups > 0)
        j["motion"] = {{"groups", s.motion.groups},
                       {"links", s.motion.links},
                       {"moves", s.motion.moves},
                       {"links_updated", s.motion.linksUpdated},
                       {"last_move_ms", s.motion.msLastMove}};
    if (!s.motion.declined.empty()) j["motion_declined"] = s.motion.declined;
    j["bounces"] = s.bounces;
    if (std::isfinite(s.irradianceBound)) j["irradiance_bound"] = s.irradianceBound;
    if (!s.divergence.empty()) j["divergence"] = s.divergence;
    if (s.gather.emitterRays > 0)
        j["emitter_direct"] = {{"rays", s.gather.emitterRays},
                               {"sun_rays", s.gather.sunRays},
                               {"ms", s.gather.msFirstShot},
                               {"device", s.gather.device}};
    if (s.gather.rays > 0)
        j["final_gather"] = {{"rays", s.gather.rays},
                             {"targets", s.gather.targets},
                             {"ms_trace", s.gather.msTrace},
                             {"ms_evaluate", s.gather.msEvaluate},
                             {"rays_retraced_by_last_move", s.gather.raysRetraced},
                             {"device", s.gather.device}};
    nlohmann::json passes = nlohmann::json::object();
    for (const auto& p : s.passes)
        passes[p.name + "_ms_per_iteration"] = s.iterations ? p.msTotal / s.iterations : 0.0;
    j["passes"] = passes;
    j["table_bytes"] = s.tableBytes;
    j["link_bytes"] = s.linkBytes;
    // The solver's own figures, beside the common ones.
    for (const auto& [name, value] : s.details) {
        if (const double* number = std::get_if<double>(&value))
            j[name] = *number;
        else
            j[name] = std::get<std::string>(value);
    }
    return j;
}

void WriteIrradianceJson(const std::string& path, const Scene& scene,
                         const IrradianceResult& result) {
    nlohmann::json j;
    j["units"] = kIrradianceUnits;
    j["solver"] = result.solver;
    j["channel"] = result.channel;
    nlohmann::json prims = nlohmann::json::array();
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const auto& prim = scene.primitives[p];
        nlohmann::json e;
        e["node"] = prim.node;
        e["mesh"] = prim.mesh;
        e["primitive"] = prim.primitive;
        nlohmann::json values = nlohmann::json::array();
        for (const auto& v : result.primitives[p]) values.push_back({v.x, v.y, v.z});
        e["irradiance"] = std::move(values);
        if (prim.refined) {  // RefineForOutput: the vertices the values are at
            nlohmann::json positions = nlohmann::json::array(), normals = positions;
            for (const auto& v : prim.objectPositions) positions.push_back({v.x, v.y, v.z});
            for (const auto& n : prim.objectNormals) normals.push_back({n.x, n.y, n.z});
            e["refined"] = {{"positions", std::move(positions)},
                            {"normals", std::move(normals)},
                            {"indices", prim.indices},
                            {"parent_triangles", prim.parentTriangles}};
        }
        if (!result.standardError.empty()) {
            nlohmann::json errors = nlohmann::json::array();
            for (const auto& v : result.standardError[p]) errors.push_back({v.x, v.y, v.z});
            e["stderr"] = std::move(errors);
        }
        prims.push_back(std::move(e));
    }
    j["primitives"] = std::move(prims);
    j["stats"] = result.stats;
    j["warnings"] = SceneWarnings(scene);
    if (path == "-") {  // standard output
        std::cout << j.dump(1) << "\n" << std::flush;
        if (!std::cout) throw Error("standard output: write failed");
        return;
    }
    std::ofstream out(path);
    if (!out) throw Error(path + ": cannot open for writing (" + std::strerror(errno) + ")");
    out << j.dump(1) << "\n";
    // Closed here, so that an error of the last buffered write (a full disk) is seen.
    out.close();
    if (!out) throw Error(path + ": write failed (" + std::strerror(errno) + ")");
}

IrradianceFile ToIrradianceFile(const Scene& scene, const IrradianceResult& result) {
    IrradianceFile file{result.solver, result.channel, {}};
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const auto& prim = scene.primitives[p];
        file.primitives.push_back({prim.node, prim.mesh, prim.primitive, result.primitives[p]});
    }
    return file;
}

namespace {

// The JSON library's message without its "[json.exception.parse_error.101] " tag.
std::string JsonWhy(const nlohmann::json::exception& e) {
    std::string why = e.what();
    const size_t tag = why.find("] ");
    if (why.rfind("[json.", 0) == 0 && tag != std::string::npos) why = why.substr(tag + 2);
    return why;
}

}  // namespace

IrradianceFile ReadIrradianceJson(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw Error(path + ": cannot open");
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        throw Error(path + ": not JSON: " + JsonWhy(e));
    }
    IrradianceFile file;
    try {
        file.solver = j.value("solver", "");
        file.channel = j.value("channel", "");
        const auto& prims = j.at("primitives");
        if (!prims.is_array()) throw Error(path + ": \"primitives\" is not an array");
        for (size_t p = 0; p < prims.size(); ++p) {
            const auto& e = prims[p];
            IrradianceRecord r;
            r.node = e.at("node").get<std::string>();
            r.mesh = e.at("mesh").get<int>();
            r.primitive = e.at("primitive").get<int>();
            for (const auto& v : e.at("irradiance")) {
                if (!v.is_array() || v.size() != 3)
                    throw Error(path + ": primitive " + std::to_string(p) + " (node '" + r.node +
                                "'): irradiance values must be [r, g, b]");
                r.irradiance.emplace_back(v[0].get<float>(), v[1].get<float>(), v[2].get<float>());
            }
            file.primitives.push_back(std::move(r));
        }
    } catch (const nlohmann::json::exception& e) {
        throw Error(path + ": not an irradiance file: " + JsonWhy(e));
    }
    return file;
}

IrradianceFile ReadIrradianceGltf(const std::string& path) {
    tinygltf::Model model;
    ReadGltfModel(path, &model);
    IrradianceFile file;
    const tinygltf::Value& about = model.asset.extras.Get("penumbra");
    file.solver = about.Get("solver").IsString() ? about.Get("solver").Get<std::string>()
                                                 : model.asset.generator;
    if (about.Get("channel").IsString()) file.channel = about.Get("channel").Get<std::string>();
    for (size_t n = 0; n < model.nodes.size(); ++n) {
        const tinygltf::Node& node = model.nodes[n];
        if (node.mesh < 0 || node.mesh >= static_cast<int>(model.meshes.size())) continue;
        const auto& primitives = model.meshes[node.mesh].primitives;
        for (size_t k = 0; k < primitives.size(); ++k) {
            auto it = primitives[k].attributes.find(kIrradianceAttribute);
            if (it == primitives[k].attributes.end()) continue;
            IrradianceRecord r;
            r.node = node.name.empty() ? "node" + std::to_string(n) : node.name;
            r.mesh = node.mesh;
            r.primitive = static_cast<int>(k);
            const std::string where = path + ": mesh " + std::to_string(node.mesh) + " primitive " +
                                      std::to_string(k) + "'s " + kIrradianceAttribute;
            if (it->second < 0 || it->second >= static_cast<int>(model.accessors.size()))
                throw Error(where + " names no accessor");
            const tinygltf::Accessor& a = model.accessors[it->second];
            if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || a.type != TINYGLTF_TYPE_VEC3 ||
                a.sparse.isSparse || a.bufferView < 0 ||
                a.bufferView >= static_cast<int>(model.bufferViews.size()))
                throw Error(where + " is not a plain float VEC3 accessor");
            const tinygltf::BufferView& v = model.bufferViews[a.bufferView];
            const size_t stride = v.byteStride ? v.byteStride : sizeof(glm::vec3);
            if (v.buffer < 0 || v.buffer >= static_cast<int>(model.buffers.size()) ||
                stride < sizeof(glm::vec3) ||
                (a.count > 0 &&
                 a.byteOffset + (a.count - 1) * stride + sizeof(glm::vec3) > v.byteLength) ||
                v.byteOffset + v.byteLength > model.buffers[v.buffer].data.size())
                throw Error(where + " reaches past its buffer");
            const unsigned char* base =
                model.buffers[v.buffer].data.data() + v.byteOffset + a.byteOffset;
            r.irradiance.resize(a.count);
            for (size_t i = 0; i < a.count; ++i)
                std::memcpy(&r.irradiance[i], base + i * stride, sizeof(glm::vec3));
            file.primitives.push_back(std::move(r));
        }
    }
    if (file.primitives.empty())
        throw Error(path + ": no primitive has " + kIrradianceAttribute +
                    " (not written by bake or reference)");
    return file;
}

DisplayColor ParseDisplayColor(const std::string& name) {
    if (name == "none") return DisplayColor::kNone;
    if (name == "tonemapped") return DisplayColor::kToneMapped;
    throw Error("--color0 must be none or tonemapped, not '" + name + "'");
}

void WriteIrradianceGltf(const std::string& input, const std::string& output, const Scene& scene,
                         const IrradianceResult& result, DisplayColor color) {
    tinygltf::Model model;
    ReadGltfModel(input, &model);

    // Give every (node, mesh) pair its own mesh so the values cannot collide.
    std::map<int, int> seen;
    std::map<int, int> meshOfNode;
    for (const auto& prim : scene.primitives) {
        if (prim.primitive != 0) continue;
        int uses = seen[prim.mesh]++;
        if (uses == 0) {
            meshOfNode[prim.nodeIndex] = prim.mesh;
        } else {
            model.meshes.push_back(model.meshes[prim.mesh]);
            int copy = static_cast<int>(model.meshes.size()) - 1;
            model.nodes[prim.nodeIndex].mesh = copy;
            meshOfNode[prim.nodeIndex] = copy;
        }
    }

    // The display colours' exposure: the scene's 99th-percentile irradiance maps to 1.
    float key = 0.0f;
    if (color == DisplayColor::kToneMapped) {
        std::vector<glm::vec3> all;
        for (const auto& values : result.primitives)
            all.insert(all.end(), values.begin(), values.end());
        key = Luminance99(all);
    }
    // One new buffer holding every _IRRADIANCE (and COLOR_0) array (WriteGltfModel merges it
    // with the input's).
    tinygltf::Buffer buffer;
    const int bufferIndex = static_cast<int>(model.buffers.size());
    // An accessor over `count` elements of `type` (floats, or unsigned ints for indices), with
    // their bounds for float vectors (POSITION must have them).
    auto addRaw = [&](const void* data, size_t count, int type, int components, bool indices) {
        const size_t bytes = count * components * 4;
        tinygltf::BufferView view;
        view.buffer = bufferIndex;
        view.byteOffset = buffer.data.size();
        view.byteLength = bytes;
        view.target = indices ? TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER : TINYGLTF_TARGET_ARRAY_BUFFER;
        buffer.data.resize(buffer.data.size() + bytes);
        if (bytes) std::memcpy(buffer.data.data() + view.byteOffset, data, bytes);
        model.bufferViews.push_back(view);
        tinygltf::Accessor acc;
        acc.bufferView = static_cast<int>(model.bufferViews.size()) - 1;
        acc.componentType =
            indices ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT : TINYGLTF_COMPONENT_TYPE_FLOAT;
        acc.type = type;
        acc.count = count;
        if (!indices && count > 0) {
            const float* f = static_cast<const float*>(data);
            acc.minValues.assign(components, std::numeric_limits<double>::max());
            acc.maxValues.assign(components, std::numeric_limits<double>::lowest());
            for (size_t i = 0; i < count; ++i)
                for (int c = 0; c < components; ++c) {
                    acc.minValues[c] = std::min(acc.minValues[c], double(f[i * components + c]));
                    acc.maxValues[c] = std::max(acc.maxValues[c], double(f[i * components + c]));
                }
        }
        model.accessors.push_back(acc);
        return static_cast<int>(model.accessors.size()) - 1;
    };
    auto add = [&](const std::vector<glm::vec3>& values) {
        return addRaw(values.data(), values.size(), TINYGLTF_TYPE_VEC3, 3, false);
    };
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const auto& prim = scene.primitives[p];
        const auto& values = result.primitives[p];
        tinygltf::Primitive& out =
            model.meshes[meshOfNode.at(prim.nodeIndex)].primitives[prim.primitive];
        auto& attributes = out.attributes;
        if (prim.refined) {
            // Refined output (RefineForOutput): the refined geometry replaces the file's, in
            // the node's own space, with the vertex lists the scene carries (others dropped).
            attributes.clear();
            attributes["POSITION"] = add(prim.objectPositions);
            attributes["NORMAL"] = add(prim.objectNormals);
            for (size_t set = 0; set < prim.texcoords.size(); ++set)
                if (prim.texcoords[set].size() == prim.positions.size())
                    attributes["TEXCOORD_" + std::to_string(set)] =
                        addRaw(prim.texcoords[set].data(), prim.positions.size(),
                               TINYGLTF_TYPE_VEC2, 2, false);
            out.indices =
                addRaw(prim.indices.data(), prim.indices.size(), TINYGLTF_TYPE_SCALAR, 1, true);
            out.mode = TINYGLTF_MODE_TRIANGLES;
            for (size_t t = 0; t < out.targets.size(); ++t) {
                std::map<std::string, int> target;
                if (t < prim.morphPositions.size() &&
                    prim.morphPositions[t].size() == prim.positions.size())
                    target["POSITION"] = add(prim.morphPositions[t]);
                if (t < prim.morphNormals.size() &&
                    prim.morphNormals[t].size() == prim.positions.size())
                    target["NORMAL"] = add(prim.morphNormals[t]);
                out.targets[t] = std::move(target);
            }
        }
        attributes[kIrradianceAttribute] = add(values);
        if (color == DisplayColor::kToneMapped) {
            std::vector<glm::vec3> display(values.size());
            for (size_t i = 0; i < values.size(); ++i)
                display[i] = glm::clamp(key > 0.0f ? values[i] / key : glm::vec3(0.0f),
                                        glm::vec3(0.0f), glm::vec3(1.0f));
            attributes["COLOR_0"] = add(display);
        }
    }
    model.buffers.push_back(std::move(buffer));
    model.asset.generator = "penumbra bake";
    // What the values are, for a reader of this file (ReadIrradianceGltf).
    tinygltf::Value::Object about;
    about["solver"] = tinygltf::Value(result.solver);
    about["channel"] = tinygltf::Value(result.channel);
    about["units"] = tinygltf::Value(std::string(kIrradianceUnits));
    tinygltf::Value::Object extras;
    extras["penumbra"] = tinygltf::Value(std::move(about));
    model.asset.extras = tinygltf::Value(std::move(extras));
    const size_t slash = input.find_last_of('/');
    WriteGltfModel(std::move(model), output,
                   slash == std::string::npos ? "." : input.substr(0, slash));
}

}  // namespace penumbra
