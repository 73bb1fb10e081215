"""The Python client (clients/python, installed by run_tests.sh) against a live penumbra-server
process on a Unix socket and loopback TCP: loads, edits, frames as numpy arrays, errors."""
import json
import os
import pathlib
import shutil
import subprocess
import tempfile
import time
import unittest

import jsonschema
import numpy as np

import penumbra_client
from penumbra_client import Client, PenumbraError

BUILD = pathlib.Path(os.environ["PENUMBRA_BUILD"])
SCENES = pathlib.Path(os.environ["PENUMBRA_SCENES"])
CORNELL = dict(device="cpu", element_size=0.06)  # the default solver (lightfield)
SCHEMA = json.loads((SCENES.parent / "protocol" / "stats.schema.json").read_text())


class Server:
    """penumbra-server as a process on a Unix socket and an ephemeral TCP port."""

    def __init__(self):
        self.dir = tempfile.mkdtemp(prefix="penumbra-python-")
        ready = os.path.join(self.dir, "ready")
        self.unix = "unix://" + os.path.join(self.dir, "s.sock")
        self.log = open(os.path.join(self.dir, "server.log"), "w")
        self.process = subprocess.Popen(
            [str(BUILD / "penumbra-server"), "--listen", self.unix, "--listen",
             "tcp://127.0.0.1:0", "--scene-root", str(SCENES), "--device", "cpu",
             "--ready-file", ready], stderr=self.log)
        for _ in range(500):
            if os.path.exists(ready):
                break
            time.sleep(0.02)
        with open(ready) as f:
            self.tcp = [line.strip() for line in f if line.startswith("tcp://")][0]

    def stop(self):
        self.process.terminate()
        code = self.process.wait(timeout=30)
        self.log.close()
        shutil.rmtree(self.dir, ignore_errors=True)
        return code


def mean(frame, node):
    return float(np.mean(np.concatenate([p.rgb for p in frame.primitives if p.node == node])))


class ClientAgainstALiveServer(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = Server()

    @classmethod
    def tearDownClass(cls):
        # A clean exit on SIGTERM with the clients gone.
        assert cls.server.stop() == 0

    def test_installed_from_the_package(self):
        self.assertNotIn(str(pathlib.Path(__file__).resolve().parents[2] / "clients"),
                         penumbra_client.__file__)
        self.assertTrue(hasattr(penumbra_client.client, "SetTransform"))  # generated code

    def test_load_get_and_edits(self):
        with Client(self.server.unix, name="python-test") as c:
            self.assertEqual(c.protocol_version, 1)
            reports = []
            info = c.load("cornell-box.gltf", progress=lambda *r: reports.append(r), reload=True,
                          **CORNELL)
            self.assertTrue(reports)  # (stage, fraction, seconds left) as the server builds
            self.assertTrue(all(0.0 <= f <= 1.0 for _, f, _ in reports))
            self.assertEqual(info.solver, "lightfield")  # the default
            self.assertEqual(info.warnings, [])  # nothing in the Cornell box is ignored
            self.assertIn("tall_block", info.nodes)
            self.assertTrue(info.nodes["tall_block"].dynamic)
            lo, hi = info.nodes["tall_block"].bounds  # extras.penumbra.bounds of the file
            self.assertLess(lo[0], hi[0])
            self.assertIsNone(info.nodes["floor"].bounds)
            self.assertGreater(info.elements, 0)
            first = c.wait(0)
            self.assertTrue(first.converged)
            self.assertGreater(len(first.primitives), 0)
            for p in first.primitives:
                self.assertEqual(p.rgb.ndim, 2)
                self.assertEqual(p.rgb.shape[1], 3)
                self.assertEqual(p.rgb.dtype, np.float32)
                self.assertTrue(np.all(np.isfinite(p.rgb)) and np.all(p.rgb >= 0))
            floor = first.primitive("floor")
            self.assertGreater(float(floor.mean()), 0.0)
            # f16 is the same answer at half precision.
            half = c.get(format="f16")
            self.assertEqual(half.frame, first.frame)
            np.testing.assert_allclose(half.primitive("floor"), floor, rtol=2e-3, atol=1e-3)
            # The same vertices, arrays of the counts SceneInfo gives.
            counts = {(n, p["mesh"], p["primitive"]): p["vertices"]
                      for n, node in info.nodes.items() for p in node.primitives}
            for p in first.primitives:
                self.assertEqual(p.rgb.shape[0], counts[(p.node, p.mesh, p.primitive)])

            # Light is linear in the emission: the ceiling light at half its radiance halves
            # every floor vertex (to the convergence bound).
            e = info.materials[info.nodes["ceiling_light"].primitives[0]["material"]]["emission"]
            edit = c.light("ceiling_light", intensity=max(e) / 2, color=[x / max(e) for x in e])
            dim = c.wait(edit)
            self.assertGreaterEqual(dim.last_edit, edit)
            np.testing.assert_allclose(dim.primitive("floor"), 0.5 * floor, rtol=2e-2,
                                       atol=1e-3 * float(floor.max()))

            # A move: the node's matrix follows, and frames include the edit.
            before = info.nodes["tall_block"].matrix
            moved = c.move("tall_block", translate=[0.05, 0.0, -0.03], rotate_y=10)
            after = c.wait(moved)
            self.assertGreaterEqual(after.last_edit, moved)
            m = c.info().nodes["tall_block"].matrix
            np.testing.assert_allclose(m[:3, 3], before[:3, 3] + [0.05, 0.0, -0.03], atol=1e-5)
            # A full matrix puts it back.
            c.wait(c.move("tall_block", matrix=before))
            np.testing.assert_allclose(c.info().nodes["tall_block"].matrix, before, atol=1e-6)

            edit = c.material("white", albedo=[0.5, 0.5, 0.5])
            self.assertGreater(edit, moved)
            self.assertGreaterEqual(c.wait(edit).last_edit, edit)
            stats = c.stats()
            self.assertIn("server", stats)
            cornell = [x for x in stats["scenes"] if x["scene"] == "cornell-box.gltf"]
            self.assertGreaterEqual(cornell[0]["last_applied_edit"], edit)
            # Both forms of the Stats JSON follow protocol/stats.schema.json.
            jsonschema.validate(stats, SCHEMA)
            jsonschema.validate(c.stats(info.scene), SCHEMA)
            broken = c.stats(info.scene)
            del broken["solver"]["elements"]
            with self.assertRaises(jsonschema.ValidationError):
                jsonschema.validate(broken, SCHEMA)

    def test_sun_and_clear_sky(self):
        with Client(self.server.unix, name="python-sun") as c:
            info = c.load("blocker.gltf", sun=(135, 30, 80000), sky="clear", reload=True,
                          **CORNELL)
            self.assertIn("sun", info.lights)
            self.assertIn("Preetham", info.environment)
            before = c.wait(0)
            edit = c.sky(sun=(225, 60, 90000))
            after = c.wait(edit)
            self.assertGreaterEqual(after.last_edit, edit)
            info = c.info()
            self.assertAlmostEqual(info.lights["sun"]["intensity"], 90000.0)
            self.assertIn("azimuth 225", info.environment)
            self.assertNotEqual(mean(before, "floor"), mean(after, "floor"))
            with self.assertRaises(ValueError):
                c.sky(sun=(0,))
            c.unload("blocker.gltf")  # test_unload loads it afresh

    def test_refined_output(self):
        # Issue 62: load(refine=...) subdivides before lighting; SceneInfo.refined has the
        # meshes, and each frame's values are on their vertices.
        with Client(self.server.unix, name="python-refine") as c:
            info = c.load("blocker.gltf", refine=0.1, reload=True, **CORNELL)
            self.assertTrue(info.refined)
            frame = c.get()
            for r in info.refined:
                self.assertEqual(r["positions"].shape[1], 3)
                self.assertEqual(len(r["indices"]), 3 * len(r["parent_triangles"]))
                edges = r["positions"][r["indices"].reshape(-1, 3)]
                lengths = np.linalg.norm(edges - np.roll(edges, 1, axis=1), axis=2)
                self.assertLessEqual(lengths.max(), 0.1 + 1e-5)
                values = [p for p in frame.primitives
                          if (p.node, p.mesh, p.primitive) == (r["node"], r["mesh"], r["primitive"])]
                self.assertEqual(len(values), 1)
                self.assertEqual(len(values[0].rgb), len(r["positions"]))
            with self.assertRaises(ValueError):
                c.load("blocker.gltf", refine=float("nan"), reload=True)
            c.unload("blocker.gltf")  # test_unload loads it afresh

    def test_delta_stream_matches_the_full_one(self):
        # Issue 64: frames() defaults to a delta stream; at tolerance 0 what the client holds
        # is the full stream's values in fp16, exactly, frame by frame; at the default within
        # half a percent (SPEC.md "Delta frames"). The first frame is a keyframe.
        import threading as th
        with Client(self.server.unix) as c, Client(self.server.unix) as full_client, \
                Client(self.server.unix) as exact_client:
            c.load("cornell-box.gltf", **CORNELL)
            full, exact, deltas = {}, {}, {}

            def collect(client, into, **kw):
                for f in client.frames(timeout=60, **kw):
                    into[f.frame] = f
                    if f.converged and f.last_edit >= edits[-1]:
                        break
            edits = [1 << 62]
            threads = [th.Thread(target=collect, args=(full_client, full), kwargs={"format": "f32"}),
                       th.Thread(target=collect, args=(exact_client, exact),
                                 kwargs={"tolerance": 0.0})]
            for t in threads:
                t.start()
            time.sleep(0.5)
            for i in range(1, 6):
                edits.append(c.light("ceiling_light", intensity=17.0 * (1 - 0.01 * i)))
                time.sleep(0.05)
            edits[0] = edits[-1]
            for f in c.frames(timeout=60):  # the default: a delta stream at 0.005
                deltas[f.frame] = f
                if f.converged and f.last_edit >= edits[-1]:
                    break
            for t in threads:
                t.join(60)
            self.assertTrue(exact[min(exact)].keyframe)
            common = 0
            for number, f in full.items():
                if number in exact:
                    common += 1
                    for p, q in zip(f.primitives, exact[number].primitives):
                        np.testing.assert_array_equal(
                            q.rgb, p.rgb.astype(np.float16).astype(np.float32))
                if number in deltas:
                    values = np.concatenate([p.rgb.ravel() for p in f.primitives])
                    floor = np.abs(values).mean() / 20
                    for p, q in zip(f.primitives, deltas[number].primitives):
                        bound = 0.005 * np.maximum(np.abs(p.rgb), floor) * 1.001 + \
                            np.abs(p.rgb) * 1e-3 + 1e-6
                        self.assertTrue(np.all(np.abs(q.rgb - p.rgb) <= bound), p.node)
            self.assertGreater(common, 2)

    def test_frames_stream_over_tcp(self):
        with Client(self.server.tcp) as c:
            c.load("cornell-box.gltf", **CORNELL)
            editor = Client(self.server.unix)
            seen = []
            for f in c.frames(channel="total", timeout=60):
                seen.append(f)
                if len(seen) == 1:
                    edit = editor.light("ceiling_light", intensity=20.0)
                if len(seen) > 1 and f.last_edit >= edit and f.converged:
                    break
            editor.close()
            self.assertEqual(seen[0].channel, "total")
            numbers = [f.frame for f in seen]
            self.assertEqual(numbers, sorted(numbers))
            self.assertGreater(mean(seen[-1], "floor"), mean(seen[0], "floor"))
            # The subscription ended with the loop: no more frames queue up.
            time.sleep(0.3)
            c.light("ceiling_light", intensity=10.0)
            time.sleep(0.5)
            self.assertEqual(len(c._frames), 0)

    def test_deform(self):
        with Client(self.server.unix) as c:
            info = c.load("morph-room.gltf", device="cpu", solver="implicit", bins=64,
                          element_size=0.2, gather_rays=0, emitter_rays=0)
            blob = info.nodes["blob"]
            self.assertEqual(blob.morph_targets, 2)
            self.assertEqual(blob.morph_weights, [0.0, 0.0])
            c.wait(c.deform("blob", weights=[0.5, 0.25]))
            self.assertEqual(c.info().nodes["blob"].morph_weights, [0.5, 0.25])
            vertices = sum(p["vertices"] for p in blob.primitives)
            with self.assertRaises(PenumbraError) as e:  # one vertex short
                c.deform("blob", positions=np.zeros((vertices - 1, 3)))
            self.assertEqual(e.exception.name, "InvalidArgument")
            with self.assertRaises(ValueError):
                c.deform("blob", weights=[float("nan"), 0.0])
            with self.assertRaises(PenumbraError) as e:
                c.deform("floor", weights=[1.0])
            self.assertEqual(e.exception.name, "StaticNode")

    def test_errors(self):
        with Client(self.server.unix) as c:
            c.load("cornell-box.gltf", **CORNELL)
            with self.assertRaises(PenumbraError) as e:
                c.load("no-such.gltf", device="cpu")
            self.assertEqual(e.exception.name, "NotFound")
            with self.assertRaises(PenumbraError) as e:
                c.load("../CMakeLists.txt")
            self.assertEqual(e.exception.name, "OutsideRoot")
            with self.assertRaises(PenumbraError) as e:
                c.load("cornell-box.gltf", device="cpu", no_such_option=3)
            self.assertEqual(e.exception.name, "InvalidArgument")
            with self.assertRaises(PenumbraError) as e:
                c.move("tall_blok", translate=[0, 1, 0])
            self.assertIn("tall_block", str(e.exception))  # the movable ones are listed
            with self.assertRaises(PenumbraError) as e:
                c.move("floor", matrix=np.eye(4))
            self.assertEqual(e.exception.name, "StaticNode")
            with self.assertRaises(ValueError):  # on the wire it would mean "unchanged"
                c.light("ceiling_light", intensity=-3)
            with self.assertRaises(ValueError):
                c.move("tall_block", matrix=[float("nan")] * 16)
            with self.assertRaises(ValueError):
                c.get(channel="bounce")
            self.assertEqual(c.info().solver, "lightfield")  # the connection stays
        with self.assertRaises(ConnectionError):
            Client("unix:///nonexistent/penumbra.sock")
        with self.assertRaises(ValueError):
            Client("http://localhost:7450")

    def test_unload(self):
        # Issue 63: the client that loaded a scene unloads it; a subscriber's frames() ends
        # with NoScene and its connection stays; another client may not while the owner is on.
        with Client(self.server.unix) as owner, Client(self.server.unix) as viewer, \
                Client(self.server.unix) as other:
            owner.load("blocker.gltf", device="cpu", element_size=0.2)
            frames = viewer.frames(scene="blocker.gltf", timeout=30)
            next(frames)
            with self.assertRaises(PenumbraError) as e:
                other.unload("blocker.gltf")
            self.assertEqual(e.exception.name, "Forbidden")
            # Nor edit it: without --token-file every client is a "user", who edits its own.
            self.assertEqual(other.role, "user")
            with self.assertRaises(PenumbraError) as e:
                other.light("emitter", intensity=0.0, scene="blocker.gltf")
            self.assertEqual(e.exception.name, "Forbidden")
            self.assertIn("editor role", str(e.exception))
            owner.light("emitter", intensity=2.0, scene="blocker.gltf")
            owner.unload("blocker.gltf")
            with self.assertRaises(PenumbraError) as e:
                while True:
                    next(frames)
            self.assertEqual(e.exception.name, "NoScene")
            self.assertIn("was unloaded", str(e.exception))
            self.assertNotIn("blocker.gltf", [s["scene"] for s in viewer.stats()["scenes"]])


if __name__ == "__main__":
    unittest.main(verbosity=2)
