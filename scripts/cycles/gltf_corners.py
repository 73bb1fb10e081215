#!/usr/bin/python3
# The glTF side of scripts/cycles/check.sh (Debian's python3 and numpy).
#
#   gltf_corners.py name IN.glb OUT.glb
#       a copy of IN.glb with node i named n<i> and material j named m<j>, so that Blender's
#       objects and materials carry the glTF indices (bake_cycles.py) and penumbra's output
#       names the same nodes.
#   gltf_corners.py irradiance NAMED.glb CORNERS.json OUT.json
#       Cycles' face-corner irradiance (bake_cycles.py) as a penumbra irradiance file: for
#       every primitive, each input vertex gets the area-weighted mean of the corners at its
#       position on the same node and material (a flat-shaded vertex: the mean over its faces,
#       as penumbra reports it). `penumbra compare` then reads it like any other.
import json
import struct
import sys
from collections import defaultdict

import numpy as np


def read_glb(path):
    data = open(path, "rb").read()
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2:
        sys.exit(path + ": not a binary glTF 2.0 file")
    offset, doc, binary = 12, None, b""
    while offset < len(data):
        length, kind = struct.unpack_from("<I4s", data, offset)
        chunk = data[offset + 8:offset + 8 + length]
        if kind == b"JSON":
            doc = json.loads(chunk)
        elif kind == b"BIN\x00":
            binary = chunk
        offset += 8 + length
    return doc, binary


def write_glb(path, doc, binary):
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\x00" * (-len(binary) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    if binary:
        chunks += struct.pack("<I4s", len(binary), b"BIN\x00") + binary
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)


COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
              5125: np.uint32, 5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def accessor(doc, binary, index):
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    dtype = np.dtype(COMPONENTS[a["componentType"]])
    width = WIDTH[a["type"]]
    stride = view.get("byteStride", dtype.itemsize * width)
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    rows = [np.frombuffer(binary, dtype, width, start + i * stride) for i in range(a["count"])]
    return np.array(rows)


def name(source, out):
    doc, binary = read_glb(source)
    for i, node in enumerate(doc.get("nodes", [])):
        node["name"] = "n%d" % i
    for j, material in enumerate(doc.get("materials", [])):
        material["name"] = "m%d" % j
    write_glb(out, doc, binary)


def irradiance(named, corners_path, out):
    doc, binary = read_glb(named)
    sums = defaultdict(lambda: np.zeros(4))
    for node, material, x, y, z, w, r, g, b in json.load(open(corners_path))["corners"]:
        sums[(node, material, x, y, z)] += (w * r, w * g, w * b, w)
    primitives, missing = [], 0
    for n, node in enumerate(doc["nodes"]):
        if "mesh" not in node:
            continue
        for p, prim in enumerate(doc["meshes"][node["mesh"]]["primitives"]):
            positions = accessor(doc, binary, prim["attributes"]["POSITION"])
            values = []
            for x, y, z in positions.astype(np.float64):
                s = sums.get((n, prim.get("material", -1), x, y, z))
                if s is None or s[3] <= 0:
                    missing += 1
                    values.append([0.0, 0.0, 0.0])
                else:
                    values.append(list(s[:3] / s[3]))
            primitives.append({"node": node["name"], "mesh": node["mesh"], "primitive": p,
                               "irradiance": values})
    json.dump({"units": "lux (lm/m^2) for emission given in nits (cd/m^2)", "solver": "cycles",
               "channel": "total", "primitives": primitives, "stats": {},
               "warnings": ["%d vertices no face uses" % missing] if missing else []},
              open(out, "w"))
    if missing:
        print("gltf_corners: %d vertices without a baked corner (unused, or lost by Blender's "
              "import): 0 there" % missing, file=sys.stderr)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "name":
        name(sys.argv[2], sys.argv[3])
    elif len(sys.argv) == 5 and sys.argv[1] == "irradiance":
        irradiance(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        sys.exit(__doc__ if __doc__ else "usage: gltf_corners.py name|irradiance ...")
