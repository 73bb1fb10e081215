#!/usr/bin/python3
"""Writes a binary glTF holding COUNT copies of a binary glTF's scene, side by side along +X,
SPACING apart (in the file's own units): each copy a new root node over a copy of the scene's
node trees, the meshes, materials and buffer shared. Test content for scenes made of parts
that barely see each other (issue 61's two CAD engines 255 units apart).

IN may also be a text .gltf whose one buffer is a data URI (the bundled scenes). The copies'
nodes are named as the originals with " #I" after (copy 0 keeps the names), so that each
is found by name.

usage: copies.py IN.glb|IN.gltf OUT.glb COUNT SPACING
"""
import base64
import json
import struct
import sys


def read_glb(path):
    with open(path, "rb") as f:
        data = f.read()
    if path.endswith(".gltf"):
        doc = json.loads(data)
        buffers = doc.get("buffers", [])
        if len(buffers) != 1 or not buffers[0].get("uri", "").startswith("data:"):
            sys.exit("%s: a .gltf needs its one buffer as a data URI" % path)
        binary = base64.b64decode(buffers[0].pop("uri").split(",", 1)[1])
        return doc, binary
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2:
        sys.exit("%s: not a binary glTF 2.0 file" % path)
    chunks, at = {}, 12
    while at < len(data):
        length, kind = struct.unpack_from("<I4s", data, at)
        chunks[kind] = data[at + 8:at + 8 + length]
        at += 8 + length
    return json.loads(chunks[b"JSON"]), chunks.get(b"BIN\x00")


def write_glb(path, doc, binary):
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    parts = [struct.pack("<I4s", len(text), b"JSON"), text]
    if binary is not None:
        binary += b"\0" * (-len(binary) % 4)
        parts += [struct.pack("<I4s", len(binary), b"BIN\x00"), binary]
    body = b"".join(parts)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


def copy_tree(nodes, index, suffix):
    """Appends a copy of node INDEX and its descendants to NODES, their names ending in
    SUFFIX; returns the copy's index."""
    node = dict(nodes[index])
    if "name" in node:
        node["name"] += suffix
    if "children" in node:
        node["children"] = [copy_tree(nodes, c, suffix) for c in node["children"]]
    nodes.append(node)
    return len(nodes) - 1


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__.strip())
    doc, binary = read_glb(sys.argv[1])
    count, spacing = int(sys.argv[3]), float(sys.argv[4])
    if count < 1:
        sys.exit("COUNT must be at least 1")
    scene = doc["scenes"][doc.get("scene", 0)]
    roots = list(scene.get("nodes", []))
    nodes = doc.setdefault("nodes", [])
    copies = []
    for i in range(count):
        children = roots if i == 0 else [copy_tree(nodes, r, " #%d" % i) for r in roots]
        nodes.append({"name": "copy %d" % i, "translation": [i * spacing, 0.0, 0.0],
                      "children": children})
        copies.append(len(nodes) - 1)
    scene["nodes"] = copies
    write_glb(sys.argv[2], doc, binary)


if __name__ == "__main__":
    main()
