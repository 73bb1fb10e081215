// The Penumbra C++ client library: connect, load, edit, subscribe, get. Depends on
// protocol/ only; what the CLI uses and what an external renderer links.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace penumbra::client {

// A failed request (the server's error code and message) or a lost connection (code 0).
class ClientError : public std::runtime_error {
  public:
    ClientError(uint16_t code, const std::string& message)
        : std::runtime_error(message), code_(code) {}
    uint16_t code() const { return code_; }  // protocol::fb::ErrorCode; 0 = connection

  private:
    uint16_t code_;
};

enum class Channel : uint8_t { kIndirect = 0, kDirect = 1, kTotal = 2 };
// How frames travel (protocol/SPEC.md, "Delta frames"): whole as f32 or f16 values, or as a
// delta stream (subscriptions only): the server sends a vertex again once it drifts past a
// tolerance of what this client holds, and the client applies it to its copy and hands on
// whole frames of fp16 values. Get with kDelta fetches one whole frame in f16.
enum class Format : uint8_t { kFloat32 = 0, kFloat16 = 1, kDelta = 2 };
// A delta stream's default tolerance: half a percent of a vertex's value (or of a twentieth
// of the frame's mean, where darker), below what a viewer sees in indirect light.
inline constexpr float kDefaultTolerance = 0.005f;

struct PrimitiveInfo {
    int mesh = -1, primitive = -1;
    uint32_t vertices = 0;
    std::string material;
};
struct NodeInfo {
    std::string name;
    bool dynamic = false, emissive = false;
    std::array<float, 16> matrix{};  // local transform, column-major
    // Motion bounds (world space): moves inside them update links in place; absent: none.
    std::optional<std::array<float, 3>> boundsMin, boundsMax;
    std::vector<PrimitiveInfo> primitives;
    uint32_t morphTargets = 0;        // its mesh's morph targets (SetMorphWeights)
    std::vector<float> morphWeights;  // the weights it is posed with now
};
struct MaterialInfo {
    std::string name;
    std::array<float, 3> albedo{}, emission{};  // albedo: glTF base colour
    float roughness = 1.0f, metallic = 0.0f;    // glTF factors
};
// A punctual light (KHR_lights_punctual), world space.
struct LightInfo {
    std::string name, node, type;  // type: point | spot | directional
    std::array<float, 3> color{}, position{}, direction{};
    float intensity = 0.0f;                    // cd (point, spot) or lux (directional)
    float range = 0.0f;                        // metres; 0 = infinite
    float innerCone = 0.0f, outerCone = 0.0f;  // radians (spot)
};
// A primitive the server subdivided (LoadOptions::refine): the vertices its frames' values
// are at, in its node's own space, and its triangles.
struct RefinedPrimitive {
    std::string node;
    int mesh = -1, primitive = -1;
    std::vector<float> positions, normals;  // x, y, z a vertex
    std::vector<uint32_t> indices;          // triangles
    std::vector<uint32_t> parentTriangles;  // the file's triangle each one lies in
};

struct SceneInfo {
    std::string scene, solver, device;
    std::vector<NodeInfo> nodes;
    std::vector<MaterialInfo> materials;
    std::vector<LightInfo> lights;
    uint32_t elements = 0;
    uint64_t links = 0;
    double buildSeconds = 0.0;
    bool reused = false;
    std::string environment;  // the sky's source; empty: none
    float environmentIntensity = 0.0f;
    std::string divergence;  // why the session stopped iterating; empty: it did not
    // What the answer leaves out: input the server ignored or approximated, no light.
    std::vector<std::string> warnings;
    std::vector<RefinedPrimitive> refined;  // with LoadOptions::refine
    const NodeInfo* Node(const std::string& name) const;
};

struct Frame {
    std::string scene;
    uint64_t frame = 0, lastEdit = 0, iterations = 0;
    double frameMs = 0.0, editLatencyMs = 0.0;
    bool converged = false;
    Channel channel = Channel::kIndirect;
    std::vector<std::pair<std::string, double>> passes;  // device ms per pass
    std::string note;
    struct Primitive {
        std::string node;
        int mesh = -1, primitive = -1;
        std::vector<float> rgb;  // 3 per vertex, in the primitive's vertex order (f16 widened)
    };
    std::vector<Primitive> primitives;
    size_t wireBytes = 0;   // size of the message as received
    bool keyframe = false;  // a delta stream's frame the server sent whole
};

// How a LoadScene's build goes: its stage, the fraction of it done, the seconds it has left
// (< 0: not known yet). Called on the client's reader thread.
using ProgressCallback =
    std::function<void(const std::string& stage, double fraction, double secondsLeft)>;

struct LoadOptions {
    std::string path;          // under the server's scene root
    std::vector<uint8_t> glb;  // or an uploaded binary glTF
    std::string name;          // session name for an upload
    std::string solver;        // empty: the server's default (lightfield)
    // The solver's own options by name, as text ({"bins", "64"}); `penumbra --help` lists
    // each solver's. Absent: the solver's defaults.
    using Options = std::map<std::string, std::string>;
    Options solverOptions;
    int iterationsPerFrame = 1;
    float elementSize = 0.0f;  // 0: automatic
    std::string device;        // "" = server default
    bool reload = false;
    float convergedChange = 1e-3f;  // 0: frames stream continuously, never idle
    int emitterRays = 256;          // shadow rays per surfel for the emitters' direct light; 0: off
    int gatherRays = 256;           // final gather rays per input vertex; 0: off
    // The sky: an equirectangular EXR under the server's scene root, or a constant colour.
    std::string environment;
    std::optional<std::array<float, 3>> environmentColor;
    float environmentIntensity = 1.0f;
    float environmentRotation = 0.0f;  // radians about +Y
    // A sun: azimuth (degrees from north, −Z, towards east, +X), elevation (degrees), lux; on a
    // node called "sun". With `clearSky`, Preetham's clear sky for it (instead of the above).
    std::optional<std::array<float, 3>> sun;
    bool clearSky = false;
    float turbidity = 3.0f;
    // Refined output for coarse meshes: triangles subdivided until no edge is longer (metres)
    // before lighting; SceneInfo::refined has the meshes the frames' values are on. 0: none.
    float refine = 0.0f;
    // Set: the server sends how the build goes (Progress messages) and this gets them.
    ProgressCallback progress;
};

class Client {
  public:
    // Connects to "tcp://HOST:PORT" or "unix:///PATH" and says Hello, with `token` when the
    // server asks for one (penumbra-server --token-file). Throws ClientError (code
    // Unauthorized, 8, for a missing or wrong token).
    explicit Client(const std::string& url, const std::string& clientName = "penumbra-client",
                    const std::string& token = "");
    ~Client();  // says Bye if still connected
    Client(const Client&) = delete;
    Client& operator=(const Client&) = delete;

    // Every call below blocks until its reply and throws ClientError on an Error reply.
    // `scene` "" means the scene this client loaded or joined last, else the server's newest.
    SceneInfo Load(const LoadOptions& options);
    SceneInfo Info(const std::string& scene = "");
    // Edits return their edit id; frames with lastEdit ≥ id include them.
    uint64_t SetTransform(const std::string& node, const std::array<float, 16>& matrix,
                          const std::string& scene = "");
    // A deformation of a dynamic node's mesh: its vertices in its own space (before its
    // matrix), its primitives' one after another in NodeInfo::primitives order, xyz each;
    // `normals` the same or empty (computed from the deformed triangles).
    uint64_t SetVertices(const std::string& node, const std::vector<float>& positions,
                         const std::vector<float>& normals = {}, const std::string& scene = "");
    // The same for a mesh with morph targets: one weight a target (NodeInfo::morphTargets).
    uint64_t SetMorphWeights(const std::string& node, const std::vector<float>& weights,
                             const std::string& scene = "");
    // A light edit: absent parts stay as they are. Position, direction, cone and range
    // apply to punctual lights only.
    struct LightChange {
        std::optional<std::array<float, 3>> color;
        std::optional<float> intensity;
        std::optional<std::array<float, 3>> position, direction;
        std::optional<float> innerCone, outerCone, range;
    };
    uint64_t SetLight(const std::string& light, const LightChange& change,
                      const std::string& scene = "");
    uint64_t SetLight(const std::string& light, std::optional<std::array<float, 3>> color,
                      std::optional<float> intensity, const std::string& scene = "");
    // Absent fields are unchanged. albedo is the base colour (docs/MATERIALS.md).
    struct MaterialChange {
        std::optional<std::array<float, 3>> albedo, emission;
        std::optional<float> roughness, metallic;
    };
    uint64_t SetMaterial(const std::string& material, const MaterialChange& change,
                         const std::string& scene = "");
    uint64_t SetMaterial(const std::string& material, std::optional<std::array<float, 3>> albedo,
                         std::optional<std::array<float, 3>> emission,
                         const std::string& scene = "");
    // The sky: a new one (`path`, an EXR under the server's scene root, or a constant
    // `color`) or `off`, then `intensity` and `rotation` (radians about +Y) when given.
    struct EnvironmentChange {
        std::string path;
        std::optional<std::array<float, 3>> color;
        bool off = false;
        std::optional<float> intensity, rotation;
        // The scene's sun moved (azimuth, elevation in degrees) and dimmed (lux); a clear sky
        // follows it. `clearSky`: a new clear sky for the sun, of `turbidity`.
        std::optional<std::array<float, 2>> sun;
        std::optional<float> sunIlluminance;
        bool clearSky = false;
        std::optional<float> turbidity;
    };
    uint64_t SetEnvironment(const EnvironmentChange& change, const std::string& scene = "");
    // Frames arrive on the client's reader thread; keep the callback short. The callback
    // stays registered until Close (which joins that thread) or the client's destruction:
    // whatever it uses must outlive that, or be owned by the callback (a shared_ptr).
    using FrameCallback = std::function<void(const Frame&)>;
    // `ended` (optional, on the reader thread too): the server ended the subscription
    // because its scene went (UnloadScene), with the server's reason; no frames follow.
    using EndCallback = std::function<void(const std::string& why)>;
    // By default a delta stream at kDefaultTolerance; a delta subscription's frames are
    // whole (the client's copy), `keyframe` set on those the server sent whole. Subscribing
    // again to the same scene asks for a keyframe.
    void Subscribe(FrameCallback callback, Channel channel = Channel::kIndirect,
                   Format format = Format::kDelta, const std::string& scene = "",
                   EndCallback ended = {}, float tolerance = kDefaultTolerance);
    void Unsubscribe(const std::string& scene = "");
    // Drops the scene from the server (its owner, the client that loaded it, while that one
    // is connected; else anyone): Error Forbidden for another client's scene. Its
    // subscribers get an Error NoScene and no more frames.
    void UnloadScene(const std::string& scene = "");
    Frame Get(Channel channel = Channel::kIndirect, Format format = Format::kFloat32,
              const std::string& scene = "");
    uint64_t Step(int iterations, const std::string& scene = "");  // returns the frame number
    std::string Stats(const std::string& scene = "");              // JSON text
    void Close();                                                  // Bye, then disconnect
    // Waits until the connection ends (the server closed it or Close() was called).
    void Wait();
    bool Connected() const;

    uint16_t ProtocolVersion() const;
    // What the server lets this connection do (Welcome's `role`; protocol/SPEC.md "Roles"):
    // "viewer", "user", "editor" or "admin".
    const std::string& Role() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra::client
