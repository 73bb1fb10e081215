#!/usr/bin/python3
"""Writes a glTF whose every mesh node is split into one child node a plane: the triangles
of each primitive grouped by the plane they lie in (normal and offset), as exporters that
write a box as six faces do. Test content for solids made of several nodes (issue 61).

usage: split-faces.py IN.gltf OUT.gltf   (buffers embedded as data URIs or beside IN)
"""
import base64
import json
import os
import sys

import numpy as np

COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
             5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def load_buffers(gltf, folder):
    out = []
    for b in gltf["buffers"]:
        uri = b["uri"]
        if uri.startswith("data:"):
            out.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            with open(os.path.join(folder, uri), "rb") as f:
                out.append(f.read())
    return out


def read(gltf, buffers, index):
    a = gltf["accessors"][index]
    view = gltf["bufferViews"][a["bufferView"]]
    dtype = np.dtype(COMPONENT[a["componentType"]])
    width = WIDTH[a["type"]]
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = view.get("byteStride", dtype.itemsize * width)
    raw = buffers[view["buffer"]]
    rows = [np.frombuffer(raw, dtype, width, start + i * stride) for i in range(a["count"])]
    return np.array(rows).reshape(a["count"], width) if width > 1 else np.array(rows).ravel()


def main(src, dst):
    with open(src) as f:
        gltf = json.load(f)
    buffers = load_buffers(gltf, os.path.dirname(src))
    blob = bytearray()
    accessors, views, meshes = [], [], []

    def add(array, kind, target):
        array = np.ascontiguousarray(array)
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes,
                      "target": target})
        blob.extend(array.tobytes())
        acc = {"bufferView": len(views) - 1, "count": int(array.shape[0]), "type": kind,
               "componentType": 5126 if array.dtype == np.float32 else 5125}
        if kind == "VEC3" and array.dtype == np.float32:
            acc["min"] = array.min(axis=0).tolist()
            acc["max"] = array.max(axis=0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    nodes = gltf["nodes"]
    for ni in range(len(nodes)):
        node = nodes[ni]
        if "mesh" not in node:
            continue
        groups = {}  # plane key -> list of (material, positions, normals)
        for prim in gltf["meshes"][node.pop("mesh")]["primitives"]:
            p = read(gltf, buffers, prim["attributes"]["POSITION"]).astype(np.float32)
            n = (read(gltf, buffers, prim["attributes"]["NORMAL"]).astype(np.float32)
                 if "NORMAL" in prim["attributes"] else None)
            idx = (read(gltf, buffers, prim["indices"]).astype(np.int64) if "indices" in prim
                   else np.arange(len(p))).reshape(-1, 3)
            a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
            fn = np.cross(b - a, c - a)
            length = np.linalg.norm(fn, axis=1)
            fn = fn / np.maximum(length, 1e-30)[:, None]
            offset = np.einsum("ij,ij->i", fn, a)
            scale = max(float(np.abs(p).max()), 1e-6)
            for t in range(len(idx)):
                if length[t] == 0:
                    continue
                key = (prim.get("material", -1),) + tuple(np.round(fn[t], 3)) + (
                    round(float(offset[t]) / scale, 4),)
                groups.setdefault(key, []).append((idx[t], p, n))
        children = node.setdefault("children", [])
        for k, (key, tris) in enumerate(groups.items()):
            verts, norms = [], []
            for tri, p, n in tris:
                verts.extend(p[tri])
                if n is not None:
                    norms.extend(n[tri])
            attributes = {"POSITION": add(np.array(verts, np.float32), "VEC3", 34962)}
            if norms:
                attributes["NORMAL"] = add(np.array(norms, np.float32), "VEC3", 34962)
            indices = add(np.arange(len(verts), dtype=np.uint32), "SCALAR", 34963)
            prim = {"attributes": attributes, "indices": indices}
            if key[0] >= 0:
                prim["material"] = key[0]
            meshes.append({"primitives": [prim]})
            nodes.append({"name": "%s.face%d" % (node.get("name", "node%d" % ni), k),
                          "mesh": len(meshes) - 1})
            children.append(len(nodes) - 1)
    gltf["meshes"], gltf["accessors"], gltf["bufferViews"] = meshes, accessors, views
    gltf["buffers"] = [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(bytes(blob)).decode()}]
    with open(dst, "w") as f:
        json.dump(gltf, f)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
