#!/usr/bin/python3
"""Writes a binary glTF holding COUNT copies of a binary glTF's scene, side by side along +X,
SPACING apart (in the file's own units): each copy a new root node over a copy of the scene's
node trees, the meshes, materials and buffer shared. Test content for scenes made of parts
that barely see each other (issue 61's two CAD engines 255 units apart).

usage: copies.py IN.glb OUT.glb COUNT SPACING
"""
import json
import struct
import sys


def read_glb(path):
    with open(path, "rb") as f:
        data = f.read()
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


def copy_tree(nodes, index):
    """Appends a copy of node INDEX and its descendants to NODES; returns the copy's index."""
    node = dict(nodes[index])
    if "children" in node:
        node["children"] = [copy_tree(nodes, c) for c in node["children"]]
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
        children = roots if i == 0 else [copy_tree(nodes, r) for r in roots]
        nodes.append({"name": "copy %d" % i, "translation": [i * spacing, 0.0, 0.0],
                      "children": children})
        copies.append(len(nodes) - 1)
    scene["nodes"] = copies
    write_glb(sys.argv[2], doc, binary)


if __name__ == "__main__":
    main()
