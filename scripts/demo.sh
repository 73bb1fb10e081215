#!/usr/bin/env bash
# `make demo`: bakes the bundled Cornell box with the antiradiance solver and prints a
# summary. The service (issue 4) will turn this into a live, streamed session.
set -euo pipefail
build=${1:-build}
out="$build/demo"
mkdir -p "$out"
echo "== penumbra bake scenes/cornell-box.gltf (antiradiance, 128 bins, 8 iterations)"
"$build/penumbra" bake scenes/cornell-box.gltf -o "$out/cornell-box-lit.glb"
"$build/penumbra" bake scenes/cornell-box.gltf -o "$out/cornell-box.json" -q
python3 - "$out/cornell-box.json" <<'PY' 2>/dev/null || true
import json, sys
j = json.load(open(sys.argv[1]))
print("\nper-node mean irradiance (%s):" % j["units"])
for p in j["primitives"]:
    v = p["irradiance"]
    m = [sum(c[i] for c in v) / len(v) for i in range(3)]
    print("  %-14s %3d vertices  r %.3f  g %.3f  b %.3f" % (p["node"], len(v), *m))
PY
echo
echo "wrote $out/cornell-box-lit.glb (COLOR_0 = irradiance; open in any glTF viewer)"
echo "wrote $out/cornell-box.json"
