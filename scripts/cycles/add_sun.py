#!/usr/bin/python3
# A binary glTF with a sun added (scripts/cycles/check.sh's sunlit cases): a root node
# carrying a KHR_lights_punctual directional light, pointed down at ELEVATION degrees above
# the horizon from AZIMUTH degrees (clockwise from -Z, glTF's +Y up), of LUX lux.
#
#   add_sun.py IN.glb OUT.glb [--elevation 30] [--azimuth 220] [--lux 80000]
import argparse
import math

import numpy as np

from gltf_corners import read_glb, write_glb

parser = argparse.ArgumentParser()
parser.add_argument("source")
parser.add_argument("out")
parser.add_argument("--elevation", type=float, default=30.0)
parser.add_argument("--azimuth", type=float, default=220.0)
parser.add_argument("--lux", type=float, default=80000.0)
a = parser.parse_args()

doc, binary = read_glb(a.source)
el, az = math.radians(a.elevation), math.radians(a.azimuth)
# The direction the light travels; a glTF light shines along its node's -Z.
d = -np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
z = np.array([0.0, 0.0, -1.0])
axis, c = np.cross(z, d), float(np.dot(z, d))
q = np.array([*axis, 1.0 + c])  # (x, y, z, w): the rotation taking -Z to d
q /= np.linalg.norm(q)
if "KHR_lights_punctual" not in doc.setdefault("extensionsUsed", []):
    doc["extensionsUsed"].append("KHR_lights_punctual")
lights = doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {}).setdefault(
    "lights", [])
lights.append({"type": "directional", "intensity": a.lux, "color": [1.0, 1.0, 1.0],
               "name": "sun"})
doc["nodes"].append({"name": "sun", "rotation": [float(x) for x in q],
                     "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
doc["scenes"][doc.get("scene", 0)]["nodes"].append(len(doc["nodes"]) - 1)
write_glb(a.out, doc, binary)
