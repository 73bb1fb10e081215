"""A Python client for penumbra-server: the framing and messages of protocol/SPEC.md.

One socket, one reader thread: replies are matched to requests by id, pushed frames (id 0)
go to a bounded queue that `frames()` and `wait()` read. Every request blocks until its reply
and raises PenumbraError on an Error reply.
"""
import collections
import json
import math
import os
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Dict, Iterator, List, Optional, Sequence

import flatbuffers
import numpy as np

from penumbra_client._fb import (Bye, Channel, EditAck, Error, ErrorCode, Format, Frame as FbFrame,
                                 GetIrradiance, GetSceneInfo, GetStats, Hello, LoadScene, Ok,
                                 Progress,
                                 SceneInfo as FbSceneInfo, SetEnvironment, SetLight, SetMaterial,
                                 SetTransform, SetVertices, SolverOption, Stats, Step, Subscribe, UnloadScene,
                                 Unsubscribe, Vec3, Welcome)

MAGIC = b"PNBR"
FRAMING_VERSION = 1
HEADER = struct.Struct("<4sBBHII")  # magic, framing version, flags, type, length, request id
PROTOCOL_VERSION = 1

# Message types (protocol/frame.h, SPEC.md "Messages").
HELLO, WELCOME, ERROR, BYE, OK = 1, 2, 3, 4, 5
LOAD_SCENE, GET_SCENE_INFO, SCENE_INFO, UNLOAD_SCENE = 10, 11, 12, 13
SET_TRANSFORM, SET_LIGHT, SET_MATERIAL, EDIT_ACK, SET_ENVIRONMENT, SET_VERTICES = (20, 21, 22, 23,
                                                                            24, 25)
SUBSCRIBE, UNSUBSCRIBE, GET_IRRADIANCE, FRAME, STEP, PROGRESS = 30, 31, 32, 33, 34, 35
GET_STATS, STATS = 40, 41

CHANNELS = {"indirect": Channel.Channel.Indirect, "direct": Channel.Channel.Direct,
            "total": Channel.Channel.Total}
FORMATS = {"f32": Format.Format.Float32, "f16": Format.Format.Float16}
# A delta stream's default tolerance (SPEC.md "Delta frames"): half a percent of a vertex's
# value, or of a twentieth of the frame's mean where darker.
DEFAULT_TOLERANCE = 0.005


def _varint(data: bytes, at: int):
    value, shift = 0, 0
    while True:
        if at >= len(data) or shift > 63:
            raise ValueError("delta payload: a run count ends early")
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, at


def apply_delta(data: bytes, raw_bytes: int, keyframe: bool, values: np.ndarray) -> np.ndarray:
    """A delta stream's payload (SPEC.md "Delta frames") applied to `values`, the (vertices, 3)
    uint16 fp16 bit patterns held; returns the new array. Raises ValueError if malformed."""
    import zstandard  # Debian: python3-zstandard
    vertices = len(values)
    if raw_bytes > 10 + 16 * vertices:
        raise ValueError(f"delta payload: {raw_bytes} raw bytes for {vertices} vertices")
    raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=raw_bytes)
    if len(raw) != raw_bytes:
        raise ValueError("delta payload: not the raw size it names")
    count, at = _varint(raw, 0)
    if count > vertices:
        raise ValueError("delta payload: more runs than vertices")
    index, position = [], 0
    for _ in range(count):
        gap, at = _varint(raw, at)
        length, at = _varint(raw, at)
        position += gap
        if position + length > vertices:
            raise ValueError("delta payload: a run goes past the scene's vertices")
        index.append(np.arange(position, position + length))
        position += length
    index = np.concatenate(index) if index else np.zeros(0, dtype=np.int64)
    n = len(index)
    if keyframe and (count != 1 or n != vertices):
        raise ValueError("delta payload: a keyframe is one run over every vertex")
    if len(raw) - at != 6 * n:
        raise ValueError("delta payload: value bytes do not match its runs")
    planes = np.frombuffer(raw, dtype=np.uint8, offset=at)
    z = planes[:3 * n].astype(np.uint16) | (planes[3 * n:].astype(np.uint16) << 8)
    residual = ((z >> 1) ^ (-(z & 1)).astype(np.uint16)).reshape(-1, 3)
    out = values.copy()
    if keyframe:  # each vertex predicted from the one before it, channel by channel
        out[:] = np.cumsum(residual, axis=0, dtype=np.uint64).astype(np.uint16)
    else:
        out[index] = out[index] + residual
    return out
ERROR_NAMES = {v: k for k, v in vars(ErrorCode.ErrorCode).items() if not k.startswith("_")}
# Pushed frames kept for a reader that falls behind; older ones are dropped (and counted).
FRAME_QUEUE = 16


class PenumbraError(Exception):
    """An Error reply: `code` (SPEC.md "Errors"), `name` ("NotFound", ...), the message."""

    def __init__(self, code: int, message: str):
        self.code = code
        self.name = ERROR_NAMES.get(code, "Unknown")
        super().__init__(f"{self.name} ({code}): {message}")


@dataclass
class Primitive:
    node: str
    mesh: int
    primitive: int
    rgb: np.ndarray  # (vertices, 3) float32, lux, in the primitive's vertex order


@dataclass
class Frame:
    scene: str
    frame: int
    last_edit: int
    iterations: int
    frame_ms: float
    edit_latency_ms: float
    converged: bool
    channel: str
    note: str
    passes: Dict[str, float]
    primitives: List[Primitive]
    keyframe: bool = False  # a delta stream's frame the server sent whole

    def primitive(self, node: str, mesh: int = 0, primitive: int = 0) -> np.ndarray:
        """The (vertices, 3) irradiance of one primitive of `node`."""
        for p in self.primitives:
            if p.node == node and p.mesh == mesh and p.primitive == primitive:
                return p.rgb
        raise KeyError(f"no primitive {mesh}/{primitive} of node '{node}' in the frame")


@dataclass
class Node:
    name: str
    dynamic: bool
    emissive: bool
    matrix: np.ndarray  # 4 × 4 local transform (matrix[:, 3] is the translation)
    primitives: List[dict]
    bounds: Optional[tuple] = None  # (min, max) motion bounds, world space; None: not given
    morph_targets: int = 0  # its mesh's morph targets (deform(weights=...))
    morph_weights: Optional[List[float]] = None  # the weights it is posed with now


@dataclass
class SceneInfo:
    scene: str
    solver: str
    device: str
    elements: int
    links: int
    build_seconds: float
    reused: bool
    environment: str
    environment_intensity: float
    divergence: str
    warnings: List[str] = field(default_factory=list)  # input ignored or approximated, no light
    nodes: Dict[str, Node] = field(default_factory=dict)
    materials: Dict[str, dict] = field(default_factory=dict)
    lights: Dict[str, dict] = field(default_factory=dict)
    # With load(refine=...): each primitive the server subdivided, as a dict of node, mesh,
    # primitive, positions and normals (n × 3, the node's own space), indices (triangles) and
    # parent_triangles (the file's triangle each one lies in); frames' values are on these.
    refined: List[dict] = field(default_factory=list)


def _text(b) -> str:
    return b.decode("utf-8") if b is not None else ""


def _vec(v) -> Optional[List[float]]:
    return [v.X(), v.Y(), v.Z()] if v is not None else None


def _finite(name: str, values: Sequence[float], count: int) -> List[float]:
    values = [float(x) for x in np.asarray(values, dtype=np.float64).ravel()]
    if len(values) != count or not all(math.isfinite(x) for x in values):
        raise ValueError(f"{name} needs {count} finite numbers, got {values}")
    return values


def _add_given(b, table, vectors: dict, scalars: dict):
    """Adds to the table being built (`table`'s generated module) each field given: vectors
    as Vec3, scalars as floats; a field left out stays unchanged on the server."""
    camel = lambda key: "".join(part.capitalize() for part in key.split("_"))
    for key, value in vectors.items():
        if value is not None:
            getattr(table, "Add" + camel(key))(b, Vec3.CreateVec3(b, *_finite(key, value, 3)))
    for key, value in scalars.items():
        if value is not None:
            getattr(table, "Add" + camel(key))(b, _finite(key, [value], 1)[0])


def _matrix_columns(matrix) -> List[float]:
    """A 4 × 4 matrix (math order: m[row][col]) as glTF's 16 column-major floats; 16 numbers
    are taken as column-major already."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape == (4, 4):
        return _finite("matrix", m.T.ravel(), 16)
    return _finite("matrix", m, 16)


class Client:
    """A connection to penumbra-server.

    `url`: "tcp://HOST:PORT" or "unix:///PATH" (default: $PENUMBRA_CONNECT, else
    tcp://127.0.0.1:7450); `token`: the server's --token-file token when it asks for one.
    `scene` arguments default to "": the scene this client loaded or joined last, else the
    server's newest (SPEC.md, Session).
    """

    def __init__(self, url: Optional[str] = None, name: str = "penumbra-python",
                 token: Optional[str] = None, timeout: float = 300.0):
        url = url or os.environ.get("PENUMBRA_CONNECT") or "tcp://127.0.0.1:7450"
        self.url, self.timeout = url, timeout
        if url.startswith("unix://"):
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            address = url[len("unix://"):]
        elif url.startswith("tcp://"):
            host, _, port = url[len("tcp://"):].rpartition(":")
            if not host or not port.isdigit():
                raise ValueError(f"'{url}': give tcp://HOST:PORT")
            self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET,
                                       socket.SOCK_STREAM)
            address = (host.strip("[]"), int(port))
        else:
            raise ValueError(f"'{url}': give tcp://HOST:PORT or unix:///PATH")
        try:
            self._sock.connect(address)
        except OSError as e:
            self._sock.close()
            raise ConnectionError(f"cannot connect to {url}: {e.strerror or e}") from None
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._next_id = 1
        self._replies: Dict[int, list] = {}
        self._progress: Dict[int, object] = {}  # request id → LoadScene's progress callback
        self._reply_ready = threading.Condition(self._lock)
        self._frames: collections.deque = collections.deque(maxlen=FRAME_QUEUE)
        self.frames_dropped = 0
        self._subscribed: Dict[str, int] = {}
        self._deltas: Dict[str, dict] = {}  # a delta stream's copy of each scene (reader)
        self._closed: Optional[str] = None
        # The server ended the subscription (its scene was unloaded): raised by frames().
        self._ended: Optional[PenumbraError] = None
        self._last_edit = 0
        self._reader = threading.Thread(target=self._read, name="penumbra-client", daemon=True)
        self._reader.start()
        b = flatbuffers.Builder(64)
        client = b.CreateString(name)
        tok = b.CreateString(token) if token else None
        Hello.Start(b)
        Hello.AddClient(b, client)
        Hello.AddMinVersion(b, PROTOCOL_VERSION)
        Hello.AddMaxVersion(b, PROTOCOL_VERSION)
        if tok is not None:
            Hello.AddToken(b, tok)
        b.Finish(Hello.End(b))
        try:
            _, payload = self._request(HELLO, b, expect=WELCOME)
        except BaseException:
            self._shutdown()
            raise
        w = Welcome.Welcome.GetRootAs(payload)
        self.server, self.protocol_version = _text(w.Server()), w.Version()
        self.max_frame_bytes = w.MaxFrameBytes()
        # What the server lets this connection do: viewer, user, editor or admin (SPEC.md,
        # "Roles").
        self.role = _text(w.Role()) or "user"

    # --- framing ------------------------------------------------------------------------
    def _read_exactly(self, n: int) -> bytes:
        data = bytearray()
        while len(data) < n:
            chunk = self._sock.recv(n - len(data))
            if not chunk:
                raise ConnectionError("the server closed the connection")
            data += chunk
        return bytes(data)

    def _read(self):
        reason = "the connection closed"
        try:
            while True:
                magic, version, _, kind, length, rid = HEADER.unpack(
                    self._read_exactly(HEADER.size))
                if magic != MAGIC or version != FRAMING_VERSION:
                    raise ConnectionError("not a Penumbra server (bad frame header)")
                payload = self._read_exactly(length) if length else b""
                if rid == 0 and kind == FRAME:
                    # A delta stream's frame is applied here, in order, so that none is lost
                    # to the queue's limit: the queue then holds whole frames.
                    frame = self._apply_delta_frame(payload)
                with self._lock:
                    if rid == 0 and kind == FRAME:
                        if len(self._frames) == self._frames.maxlen:
                            self.frames_dropped += 1
                        self._frames.append(frame)
                    elif kind == PROGRESS:
                        report = self._progress.get(rid)
                        if report is not None:
                            p = Progress.Progress.GetRootAs(payload)
                            report(_text(p.Stage()), p.Fraction(), p.SecondsLeft())
                    elif rid == 0 and kind == ERROR:
                        e = Error.Error.GetRootAs(payload)
                        error = PenumbraError(e.Code(), _text(e.Message()))
                        if e.Code() == ErrorCode.ErrorCode.NoScene:
                            # The subscription's scene was unloaded: frames() ends with it,
                            # the connection stays.
                            self._ended = error
                        else:  # the server is closing this connection
                            reason = str(error)
                    else:
                        self._replies[rid] = [kind, payload]
                    self._reply_ready.notify_all()
        except (OSError, ConnectionError) as e:
            if reason == "the connection closed":
                reason = str(e)
        with self._lock:
            self._closed = reason
            self._reply_ready.notify_all()

    def _send(self, kind: int, builder: Optional[flatbuffers.Builder], rid: int):
        payload = bytes(builder.Output()) if builder is not None else b""
        with self._send_lock:
            self._sock.sendall(HEADER.pack(MAGIC, FRAMING_VERSION, 0, kind, len(payload), rid) +
                               payload)

    def _request(self, kind: int, builder, expect: int, progress=None):
        with self._lock:
            if self._closed:
                raise ConnectionError(self._closed)
            rid = self._next_id
            self._next_id = self._next_id % 0xFFFFFFFF + 1  # 0 is the id of pushed frames
            if progress is not None:
                self._progress[rid] = progress
        try:
            return self._await(kind, builder, expect, rid)
        finally:
            with self._lock:
                self._progress.pop(rid, None)

    def _await(self, kind: int, builder, expect: int, rid: int):
        self._send(kind, builder, rid)
        deadline = time.monotonic() + self.timeout
        with self._lock:
            while rid not in self._replies:
                if self._closed:
                    raise ConnectionError(self._closed)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no reply within {self.timeout} s")
                self._reply_ready.wait(left)
            got, payload = self._replies.pop(rid)
        if got == ERROR:
            e = Error.Error.GetRootAs(payload)
            raise PenumbraError(e.Code(), _text(e.Message()))
        if got != expect:
            raise ConnectionError(f"unexpected reply type {got} (wanted {expect})")
        return got, payload

    @staticmethod
    def _scene_only(module, scene: str) -> flatbuffers.Builder:
        b = flatbuffers.Builder(64)
        s = b.CreateString(scene)
        module.Start(b)
        module.AddScene(b, s)
        b.Finish(module.End(b))
        return b

    def _edit(self, kind: int, builder) -> int:
        _, payload = self._request(kind, builder, EDIT_ACK)
        edit = EditAck.EditAck.GetRootAs(payload).EditId()
        self._last_edit = max(self._last_edit, edit)
        return edit

    # --- scenes -------------------------------------------------------------------------
    def load(self, path: Optional[str] = None, *, glb: Optional[bytes] = None,
             name: str = "", solver: str = "", iterations_per_frame: int = 1,
             element_size: float = 0.0, device: str = "", reload: bool = False,
             converged_change: float = 1e-3, environment: str = "",
             environment_color: Optional[Sequence[float]] = None,
             environment_intensity: float = 1.0, environment_rotation: float = 0.0,
             emitter_rays: int = 256, gather_rays: int = 256, progress=None,
             sun: Optional[Sequence[float]] = None, sky: str = "", turbidity: float = 3.0,
             refine: float = 0.0, **solver_options) -> SceneInfo:
        """Loads a scene (a path under the server's --scene-root, or `glb` bytes), or joins
        the session that has it. `solver` "" is the server's default (lightfield). Other
        keywords are the solver's own options (`penumbra --help`), `_` for `-`:
        `load("office.gltf", solver="antiradiance", bins=64, link_oracle="paper")`.
        `progress(stage, fraction, seconds_left)` is called (on the reader thread) as the
        server builds; `seconds_left` < 0 while not known. `sun` (azimuth, elevation in
        degrees, lux) adds a sun on a node "sun" (north −Z, east +X); `sky="clear"` Preetham's
        clear sky for it, of `turbidity`. `refine` (metres): triangles subdivided until no
        edge is longer before lighting; SceneInfo.refined has the meshes frames are on.
        """
        if (path is None) == (glb is None):
            raise ValueError("give a path or glb bytes")
        b = flatbuffers.Builder(1024 + (len(glb) if glb else 0))
        options = []
        for key, value in solver_options.items():
            k, v = b.CreateString(key.replace("_", "-")), b.CreateString(str(value))
            SolverOption.Start(b)
            SolverOption.AddName(b, k)
            SolverOption.AddValue(b, v)
            options.append(SolverOption.End(b))
        LoadScene.StartOptionsVector(b, len(options))
        for o in reversed(options):
            b.PrependUOffsetTRelative(o)
        opts = b.EndVector()
        p = b.CreateString(path) if path is not None else None
        g = b.CreateByteVector(glb) if glb is not None else None
        n, s, d, env, k = (b.CreateString(x) for x in (name, solver, device, environment, sky))
        LoadScene.Start(b)
        if p is not None:
            LoadScene.AddPath(b, p)
        if g is not None:
            LoadScene.AddGlb(b, g)
        LoadScene.AddName(b, n)
        LoadScene.AddSolver(b, s)
        LoadScene.AddIterationsPerFrame(b, int(iterations_per_frame))
        LoadScene.AddElementSize(b, float(element_size))
        LoadScene.AddDevice(b, d)
        LoadScene.AddReload(b, bool(reload))
        LoadScene.AddConvergedChange(b, float(converged_change))
        LoadScene.AddEnvironment(b, env)
        if environment_color is not None:
            c = _finite("environment_color", environment_color, 3)
            LoadScene.AddEnvironmentColor(b, Vec3.CreateVec3(b, *c))
        LoadScene.AddEnvironmentIntensity(b, float(environment_intensity))
        LoadScene.AddEnvironmentRotation(b, float(environment_rotation))
        LoadScene.AddEmitterRays(b, int(emitter_rays))
        LoadScene.AddGatherRays(b, int(gather_rays))
        LoadScene.AddOptions(b, opts)
        LoadScene.AddProgress(b, progress is not None)
        if sun is not None:
            LoadScene.AddSun(b, Vec3.CreateVec3(b, *_finite("sun", sun, 3)))
        LoadScene.AddSky(b, k)
        LoadScene.AddTurbidity(b, float(turbidity))
        LoadScene.AddRefine(b, _finite("refine", [refine], 1)[0])
        b.Finish(LoadScene.End(b))
        _, payload = self._request(LOAD_SCENE, b, SCENE_INFO, progress)
        return self._scene_info(payload)

    def info(self, scene: str = "") -> SceneInfo:
        _, payload = self._request(GET_SCENE_INFO, self._scene_only(GetSceneInfo, scene),
                                   SCENE_INFO)
        return self._scene_info(payload)

    @staticmethod
    def _scene_info(payload: bytes) -> SceneInfo:
        s = FbSceneInfo.SceneInfo.GetRootAs(payload)
        info = SceneInfo(scene=_text(s.Scene()), solver=_text(s.Solver()),
                         device=_text(s.Device()), elements=s.Elements(), links=s.Links(),
                         build_seconds=s.BuildSeconds(), reused=s.Reused(),
                         environment=_text(s.Environment()),
                         environment_intensity=s.EnvironmentIntensity(),
                         divergence=_text(s.Divergence()),
                         warnings=[_text(s.Warnings(i)) for i in range(s.WarningsLength())])
        for i in range(s.RefinedLength()):
            r = s.Refined(i)
            vectors = {}
            for key, length, numpy in (("positions", r.PositionsLength, r.PositionsAsNumpy),
                                       ("normals", r.NormalsLength, r.NormalsAsNumpy),
                                       ("indices", r.IndicesLength, r.IndicesAsNumpy),
                                       ("parent_triangles", r.ParentTrianglesLength,
                                        r.ParentTrianglesAsNumpy)):
                vectors[key] = np.array(numpy()) if length() else np.zeros(0)
            info.refined.append({"node": _text(r.Node()), "mesh": r.Mesh(),
                                 "primitive": r.Primitive(),
                                 "positions": vectors["positions"].reshape(-1, 3),
                                 "normals": vectors["normals"].reshape(-1, 3),
                                 "indices": vectors["indices"],
                                 "parent_triangles": vectors["parent_triangles"]})
        for i in range(s.NodesLength()):
            n = s.Nodes(i)
            columns = n.MatrixAsNumpy() if n.MatrixLength() == 16 else np.eye(4).ravel()
            prims = []
            for j in range(n.PrimitivesLength()):
                p = n.Primitives(j)
                prims.append({"mesh": p.Mesh(), "primitive": p.Primitive(),
                              "vertices": p.Vertices(), "material": _text(p.Material())})
            info.nodes[_text(n.Name())] = Node(
                name=_text(n.Name()), dynamic=n.Dynamic(), emissive=n.Emissive(),
                matrix=np.asarray(columns, dtype=np.float64).reshape(4, 4).T, primitives=prims,
                bounds=(_vec(n.BoundsMin()), _vec(n.BoundsMax())) if n.BoundsMin() else None,
                morph_targets=n.MorphTargets(),
                morph_weights=[n.MorphWeights(j) for j in range(n.MorphWeightsLength())])
        for i in range(s.MaterialsLength()):
            m = s.Materials(i)
            info.materials[_text(m.Name())] = {
                "albedo": _vec(m.Albedo()), "emission": _vec(m.Emission()),
                "roughness": m.Roughness(), "metallic": m.Metallic()}
        for i in range(s.LightsLength()):
            li = s.Lights(i)
            info.lights[_text(li.Name())] = {
                "node": _text(li.Node()), "type": _text(li.Type()), "color": _vec(li.Color()),
                "intensity": li.Intensity(), "range": li.Range(), "inner_cone": li.InnerCone(),
                "outer_cone": li.OuterCone(), "position": _vec(li.Position()),
                "direction": _vec(li.Direction())}
        return info

    # --- edits (each returns its edit id; frames with last_edit ≥ it include it) ---------
    def move(self, node: str, translate: Optional[Sequence[float]] = None,
             rotate_y: Optional[float] = None, matrix=None, scene: str = "") -> int:
        """Moves a dynamic node: new local = translate × current × rotate-y (`rotate_y` in
        degrees, about the node's own y axis), or `matrix` (4 × 4, or 16 column-major floats)."""
        if matrix is not None:
            if translate is not None or rotate_y is not None:
                raise ValueError("give matrix, or translate and/or rotate_y")
            columns = _matrix_columns(matrix)
        else:
            if translate is None and rotate_y is None:
                raise ValueError("give translate, rotate_y or matrix")
            nodes = self.info(scene).nodes
            if node not in nodes:
                movable = ", ".join(sorted(n for n, v in nodes.items() if v.dynamic)) or "none"
                raise PenumbraError(ErrorCode.ErrorCode.NotFound,
                                    f"no node '{node}' (movable: {movable})")
            m = nodes[node].matrix.copy()
            if rotate_y is not None:
                a = math.radians(_finite("rotate_y", [rotate_y], 1)[0])
                r = np.eye(4)
                r[0, 0], r[0, 2], r[2, 0], r[2, 2] = math.cos(a), math.sin(a), -math.sin(a), \
                    math.cos(a)
                m = m @ r
            if translate is not None:
                t = np.eye(4)
                t[:3, 3] = _finite("translate", translate, 3)
                m = t @ m
            columns = _matrix_columns(m)
        b = flatbuffers.Builder(256)
        s, n = b.CreateString(scene), b.CreateString(node)
        SetTransform.StartMatrixVector(b, 16)
        for x in reversed(columns):
            b.PrependFloat32(x)
        mv = b.EndVector()
        SetTransform.Start(b)
        SetTransform.AddScene(b, s)
        SetTransform.AddNode(b, n)
        SetTransform.AddMatrix(b, mv)
        b.Finish(SetTransform.End(b))
        return self._edit(SET_TRANSFORM, b)

    def deform(self, node: str, positions: Optional[Sequence[float]] = None,
               normals: Optional[Sequence[float]] = None,
               weights: Optional[Sequence[float]] = None, scene: str = "") -> int:
        """Deforms a dynamic node's mesh (SPEC.md SetVertices): `positions` (every vertex of
        its primitives in its own space, n × 3 or flat) and optionally `normals` (the same;
        None: computed by the server), or `weights` for its morph targets. Returns the edit id."""
        if (positions is None) == (weights is None):
            raise ValueError("deform takes either positions or weights")
        def flat(name, values):
            v = np.asarray(values, dtype=np.float32).ravel()
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite numbers")
            return v
        b = flatbuffers.Builder(1024)
        s, n = b.CreateString(scene), b.CreateString(node)
        vectors = {}
        for key, values in (("positions", positions), ("normals", normals), ("weights", weights)):
            if values is None:
                continue
            v = flat(key, values)
            getattr(SetVertices, "Start" + key.capitalize() + "Vector")(b, len(v))
            for x in reversed(v):
                b.PrependFloat32(float(x))
            vectors[key] = b.EndVector()
        SetVertices.Start(b)
        SetVertices.AddScene(b, s)
        SetVertices.AddNode(b, n)
        for key, offset in vectors.items():
            getattr(SetVertices, "Add" + key.capitalize())(b, offset)
        b.Finish(SetVertices.End(b))
        return self._edit(SET_VERTICES, b)

    def light(self, name: str, color: Optional[Sequence[float]] = None,
              intensity: Optional[float] = None, position: Optional[Sequence[float]] = None,
              direction: Optional[Sequence[float]] = None, inner_cone: Optional[float] = None,
              outer_cone: Optional[float] = None, range: Optional[float] = None,
              scene: str = "") -> int:
        """Changes a punctual light or an emissive node (SPEC.md SetLight); what is not given
        stays. Negative numbers are refused here: on the wire they mean "unchanged"."""
        scalars = {"intensity": intensity, "inner_cone": inner_cone, "outer_cone": outer_cone,
                   "range": range}
        for key, value in scalars.items():
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{key} must be a finite number ≥ 0, got {value}")
        if all(v is None for v in (color, position, direction, *scalars.values())):
            raise ValueError("give at least one of color, intensity, position, direction, "
                             "inner_cone, outer_cone, range")
        b = flatbuffers.Builder(128)
        s, n = b.CreateString(scene), b.CreateString(name)
        SetLight.Start(b)
        SetLight.AddScene(b, s)
        SetLight.AddLight(b, n)
        _add_given(b, SetLight, {"color": color, "position": position, "direction": direction},
                   scalars)
        b.Finish(SetLight.End(b))
        return self._edit(SET_LIGHT, b)

    def material(self, name: str, albedo: Optional[Sequence[float]] = None,
                 emission: Optional[Sequence[float]] = None, roughness: Optional[float] = None,
                 metallic: Optional[float] = None, scene: str = "") -> int:
        """Changes a material: albedo (base colour), emission (nits), roughness and metallic
        in [0, 1]; what is not given stays."""
        for key, value in (("roughness", roughness), ("metallic", metallic)):
            if value is not None and not (0.0 <= value <= 1.0):
                raise ValueError(f"{key} must be in [0, 1], got {value}")
        if albedo is None and emission is None and roughness is None and metallic is None:
            raise ValueError("give at least one of albedo, emission, roughness, metallic")
        b = flatbuffers.Builder(128)
        s, n = b.CreateString(scene), b.CreateString(name)
        SetMaterial.Start(b)
        SetMaterial.AddScene(b, s)
        SetMaterial.AddMaterial(b, n)
        _add_given(b, SetMaterial, {"albedo": albedo, "emission": emission},
                   {"roughness": roughness, "metallic": metallic})
        b.Finish(SetMaterial.End(b))
        return self._edit(SET_MATERIAL, b)

    def sky(self, path: Optional[str] = None, color: Optional[Sequence[float]] = None,
            off: bool = False, intensity: Optional[float] = None,
            rotation: Optional[float] = None, scene: str = "",
            sun: Optional[Sequence[float]] = None, clear: bool = False,
            turbidity: Optional[float] = None) -> int:
        """A new sky (`path`, an EXR under the server's scene root, or a constant `color` in
        nits, or `clear`: a clear sky for the sun, of `turbidity`) or `off`; then `intensity`
        (≥ 0) and `rotation` (radians about +Y) if given. `sun` (azimuth, elevation in
        degrees[, lux]) moves the scene's sun; a clear sky follows it."""
        if sum(x is not None and x is not False for x in (path, color, off or None)) > 1:
            raise ValueError("give one of path, color, off")
        if intensity is not None and not (math.isfinite(intensity) and intensity >= 0):
            raise ValueError(f"intensity must be a finite number ≥ 0, got {intensity}")
        b = flatbuffers.Builder(128)
        s, e = b.CreateString(scene), b.CreateString(path or "")
        k = b.CreateString("clear" if clear else "")
        SetEnvironment.Start(b)
        SetEnvironment.AddScene(b, s)
        SetEnvironment.AddEnvironment(b, e)
        if color is not None:
            SetEnvironment.AddEnvironmentColor(b, Vec3.CreateVec3(b, *_finite("color", color, 3)))
        SetEnvironment.AddOff(b, bool(off))
        if intensity is not None:
            SetEnvironment.AddIntensity(b, float(intensity))
        if rotation is not None:
            SetEnvironment.AddRotation(b, _finite("rotation", [rotation], 1)[0])
            SetEnvironment.AddSetRotation(b, True)
        if sun is not None:
            if len(sun) not in (2, 3):
                raise ValueError("sun: azimuth, elevation[, lux]")
            a, el = _finite("sun", sun[:2], 2)
            lux = _finite("sun", sun[2:], 1)[0] if len(sun) == 3 else -1.0
            SetEnvironment.AddSun(b, Vec3.CreateVec3(b, a, el, lux))
        SetEnvironment.AddSky(b, k)
        if turbidity is not None:
            SetEnvironment.AddTurbidity(b, _finite("turbidity", [turbidity], 1)[0])
        b.Finish(SetEnvironment.End(b))
        return self._edit(SET_ENVIRONMENT, b)

    # --- results ------------------------------------------------------------------------
    def get(self, channel: str = "indirect", format: str = "f32", scene: str = "") -> Frame:
        """The newest frame: irradiance per primitive as (vertices, 3) float32 arrays."""
        b = self._channel_request(GetIrradiance, scene, channel, format)
        _, payload = self._request(GET_IRRADIANCE, b, FRAME)
        return self._frame(payload)

    def frames(self, channel: str = "indirect", format: str = "delta", scene: str = "",
               timeout: Optional[float] = None,
               tolerance: float = DEFAULT_TOLERANCE) -> Iterator[Frame]:
        """Subscribes and yields each frame the server pushes (first the newest so far); ends
        the subscription when the loop stops. `format` "delta" (the default) is a delta
        stream at `tolerance` (SPEC.md "Delta frames": only the vertices that drifted past
        it travel; this client applies them to its copy and yields whole frames of fp16
        values; 0 sends every change of a vertex's fp16 value); "f32" and "f16" send every
        frame whole. A reader that falls more than 16 frames behind loses the oldest
        (`frames_dropped`); the server drops frames for a slow connection too: a gap in
        `frame` numbers is how many were skipped. `timeout`: seconds to wait for a frame
        before TimeoutError (None: wait as long as it takes). When the scene is unloaded the
        loop ends with PenumbraError NoScene (the connection stays)."""
        self._subscribe(scene, channel, format, tolerance)
        try:
            while True:
                yield self._next_frame(timeout)
        finally:
            self._unsubscribe(scene)

    def wait(self, edit: Optional[int] = None, timeout: float = 60.0, scene: str = "") -> Frame:
        """Waits until the scene has applied `edit` (default: this client's last edit), has
        no edit pending or rebuilding, and has converged; returns the newest frame then."""
        edit = self._last_edit if edit is None else edit
        deadline = time.monotonic() + timeout
        while True:
            stats = self.stats(scene)
            s = stats["scenes"][-1] if "scenes" in stats else stats
            if (s["last_applied_edit"] >= edit and s["pending_edits"] == 0 and
                    not s["rebuilding"] and s["converged"]):
                return self.get(scene=scene)
            if time.monotonic() > deadline:
                raise TimeoutError(f"edit {edit} not applied and converged within {timeout} s")
            time.sleep(0.02)

    def step(self, iterations: int = 1, scene: str = "") -> int:
        """Runs `iterations` solver iterations now (even when converged); the frame number."""
        b = flatbuffers.Builder(64)
        s = b.CreateString(scene)
        Step.Start(b)
        Step.AddScene(b, s)
        Step.AddIterations(b, int(iterations))
        b.Finish(Step.End(b))
        _, payload = self._request(STEP, b, OK)
        return Ok.Ok.GetRootAs(payload).Frame()

    def unload(self, scene: str = "") -> None:
        """Drops the scene from the server ("": this client's last, else the newest). Only the
        client that loaded it may while it is connected (PenumbraError Forbidden otherwise);
        once it has gone, anyone may. Its subscribers' frames() raise PenumbraError NoScene."""
        self._request(UNLOAD_SCENE, self._scene_only(UnloadScene, scene), OK)

    def stats(self, scene: str = "") -> dict:
        _, payload = self._request(GET_STATS, self._scene_only(GetStats, scene), STATS)
        return json.loads(_text(Stats.Stats.GetRootAs(payload).Json()))

    def close(self):
        """Says Bye and disconnects."""
        if self._closed is None:
            try:
                b = flatbuffers.Builder(16)
                Bye.Start(b)
                b.Finish(Bye.End(b))
                self._request(BYE, b, BYE)
            except (ConnectionError, OSError, TimeoutError, PenumbraError):
                pass
        self._shutdown()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- helpers ------------------------------------------------------------------------
    def _shutdown(self):
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        self._reader.join(timeout=5)

    @staticmethod
    def _channel(channel: str) -> int:
        if channel not in CHANNELS:
            raise ValueError(f"channel '{channel}': give one of {', '.join(CHANNELS)}")
        return CHANNELS[channel]

    @staticmethod
    def _format(format: str) -> int:
        if format not in FORMATS:
            raise ValueError(f"format '{format}': give one of {', '.join(FORMATS)}")
        return FORMATS[format]

    @classmethod
    def _channel_request(cls, table, scene: str, channel: str, format: str):
        """GetIrradiance or Subscribe (`table`'s generated module): scene, channel, format."""
        b = flatbuffers.Builder(64)
        s = b.CreateString(scene)
        table.Start(b)
        table.AddScene(b, s)
        table.AddChannel(b, cls._channel(channel))
        table.AddFormat(b, cls._format(format))
        b.Finish(table.End(b))
        return b

    def _subscribe(self, scene: str, channel: str, format: str, tolerance: float):
        delta = format == "delta"
        if delta:
            if not 0.0 <= tolerance <= 1.0:
                raise ValueError(f"tolerance {tolerance}: give a relative tolerance in [0, 1]")
            import zstandard  # noqa: F401  (a clear ImportError here, not in the reader)
        b = flatbuffers.Builder(64)
        s = b.CreateString(scene)
        Subscribe.Start(b)
        Subscribe.AddScene(b, s)
        Subscribe.AddChannel(b, self._channel(channel))
        Subscribe.AddFormat(b, self._format("f16" if delta else format))
        Subscribe.AddTolerance(b, float(tolerance) if delta else -1.0)
        b.Finish(Subscribe.End(b))
        with self._lock:
            self._frames.clear()
            self._deltas.clear()
        self._request(SUBSCRIBE, b, OK)

    def _unsubscribe(self, scene: str):
        if self._closed is None:
            try:
                self._request(UNSUBSCRIBE, self._scene_only(Unsubscribe, scene), OK)
            except (ConnectionError, OSError, PenumbraError):
                pass

    def _next_frame(self, timeout: Optional[float]) -> Frame:
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._lock:
            while not self._frames:
                if self._ended is not None:
                    ended, self._ended = self._ended, None
                    raise ended
                if self._closed:
                    raise ConnectionError(self._closed)
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise TimeoutError(f"no frame within {timeout} s")
                self._reply_ready.wait(left)
            payload = self._frames.popleft()
        return payload if isinstance(payload, Frame) else self._frame(payload)

    def _apply_delta_frame(self, payload: bytes):
        """A delta stream's frame applied to this client's copy of its scene (reader thread):
        the whole Frame; other frames are returned as they came, decoded when read."""
        f = FbFrame.Frame.GetRootAs(payload)
        d = f.Delta()
        if d is None:
            return payload
        frame = self._frame(payload)
        copy = self._deltas.get(frame.scene)
        if d.Keyframe():
            counts = d.CountsAsNumpy() if d.CountsLength() else np.zeros(0, dtype=np.uint32)
            if len(counts) != len(frame.primitives) or int(counts.sum()) != d.Vertices():
                raise ConnectionError("bad frame from the server: keyframe counts")
            values = np.zeros((d.Vertices(), 3), dtype=np.uint16)
            layout = [(p.node, p.mesh, p.primitive) for p in frame.primitives]
            copy = {"layout": layout, "counts": [int(c) for c in counts]}
        elif copy is None or d.BaseFrame() != copy["frame"]:
            raise ConnectionError(
                f"bad frame from the server: delta frame {f.Frame()} changes frame "
                f"{d.BaseFrame()}, this client holds {copy['frame'] if copy else 'none'}")
        else:
            values = copy["values"]
        try:
            values = apply_delta(d.DataAsNumpy().tobytes(), d.RawBytes(), d.Keyframe(), values)
        except ValueError as e:
            raise ConnectionError(f"bad frame from the server: {e}") from None
        copy["values"], copy["frame"] = values, f.Frame()
        self._deltas[frame.scene] = copy
        rgb = values.view(np.float16).astype(np.float32)
        prims, at = [], 0
        for (node, mesh, primitive), n in zip(copy["layout"], copy["counts"]):
            prims.append(Primitive(node=node, mesh=mesh, primitive=primitive, rgb=rgb[at:at + n]))
            at += n
        frame.primitives = prims
        frame.keyframe = bool(d.Keyframe())
        return frame

    @staticmethod
    def _frame(payload: bytes) -> Frame:
        f = FbFrame.Frame.GetRootAs(payload)
        names = {v: k for k, v in CHANNELS.items()}
        prims = []
        for i in range(f.PrimitivesLength()):
            p = f.Primitives(i)
            if p.F32Length():
                rgb = np.array(p.F32AsNumpy(), dtype=np.float32)
            elif p.F16Length():
                rgb = np.array(p.F16AsNumpy(), dtype=np.uint16).view(np.float16).astype(
                    np.float32)
            else:
                rgb = np.zeros(0, dtype=np.float32)
            prims.append(Primitive(node=_text(p.Node()), mesh=p.Mesh(), primitive=p.Primitive(),
                                   rgb=rgb.reshape(-1, 3)))
        passes = {}
        for i in range(f.PassesLength()):
            passes[_text(f.Passes(i).Name())] = f.Passes(i).Ms()
        return Frame(scene=_text(f.Scene()), frame=f.Frame(), last_edit=f.LastEdit(),
                     iterations=f.Iterations(), frame_ms=f.FrameMs(),
                     edit_latency_ms=f.EditLatencyMs(), converged=f.Converged(),
                     channel=names.get(f.Channel(), str(f.Channel())), note=_text(f.Note()),
                     passes=passes, primitives=prims)
