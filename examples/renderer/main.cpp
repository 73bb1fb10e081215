// What a renderer does with Penumbra: load a scene on the server, subscribe to its frames of
// per-vertex irradiance, and hand each primitive's colours to its own vertex buffers (here:
// print what would be uploaded). With REFINE (metres) the server subdivides the scene's
// triangles first, and the renderer draws the refined meshes SceneInfo gives instead of the
// file's. Usage: penumbra-renderer-example URL SCENE [FRAMES] [REFINE]
#include <penumbra/client.h>

#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s URL SCENE [FRAMES] [REFINE]\n", argv[0]);
        return 2;
    }
    const int wanted = argc > 3 ? std::atoi(argv[3]) : 3;
    try {
        penumbra::client::Client client(argv[1], "renderer-example");
        penumbra::client::LoadOptions load;
        load.path = argv[2];
        if (argc > 4) load.refine = std::strtof(argv[4], nullptr);
        const penumbra::client::SceneInfo info = client.Load(load);
        std::printf("scene %s: %zu nodes, solver %s on %s\n", info.scene.c_str(), info.nodes.size(),
                    info.solver.c_str(), info.device.c_str());
        // A refined primitive's frames are on its refined vertices: a renderer replaces that
        // primitive's vertex and index buffers with these (positions in its node's own space).
        for (const auto& r : info.refined)
            std::printf("refined %s mesh %d primitive %d: %zu vertices, %zu triangles\n",
                        r.node.c_str(), r.mesh, r.primitive, r.positions.size() / 3,
                        r.indices.size() / 3);
        std::mutex m;
        std::condition_variable cv;
        int seen = 0;
        client.Subscribe([&](const penumbra::client::Frame& f) {
            // A renderer would copy f.primitives[i].rgb into primitive i's colour buffer.
            size_t vertices = 0;
            double sum = 0.0;
            for (const auto& p : f.primitives) {
                vertices += p.rgb.size() / 3;
                for (float v : p.rgb) sum += v;
            }
            std::printf("frame %llu: %zu primitives, %zu vertices, mean %.4g lux%s\n",
                        static_cast<unsigned long long>(f.frame), f.primitives.size(), vertices,
                        vertices ? sum / (3.0 * vertices) : 0.0, f.converged ? ", converged" : "");
            std::lock_guard lock(m);
            ++seen;
            cv.notify_all();
        });
        bool enough = false;
        {
            std::unique_lock lock(m);
            cv.wait(lock, [&] { return seen >= wanted || !client.Connected(); });
            enough = seen >= wanted;
        }
        // No frame reaches the callback after Close (it joins the reader thread): the locals
        // the callback uses, declared after `client`, would otherwise be gone before it.
        client.Close();
        return enough ? 0 : 1;
    } catch (const penumbra::client::ClientError& e) {
        std::fprintf(stderr, "penumbra: %s\n", e.what());
        return 1;
    }
}
