#!/usr/bin/env bash
# penumbra against Cycles (issue 61): bakes a binary glTF with Blender's Cycles (an independent
# path tracer, Debian's `blender`) and with penumbra (`reference`, and `bake` with each solver
# asked for), all with the total channel and the same constant sky, and prints `penumbra
# compare` of each against Cycles, with the totals. First a plane under the sky checks the
# scale (E = π L at every vertex, both tracers).
#
# usage: scripts/cycles/check.sh SCENE.glb [BUILD] [OUT]   (BUILD default build; OUT: a
#        folder to keep the files in, default a temporary one)
# env:   SKY (r,g,b radiance in nits, default 1,1,1), SAMPLES (Cycles' samples a corner,
#        default 256), REFERENCE_SAMPLES (penumbra reference's paths, default 1024), SOLVERS
#        (default "lightfield"), DEVICE (default cpu), BACK_FACES (Cycles' back faces:
#        diffuse, its own default, or black, as penumbra's surfaces)
# Needs Debian's blender (installed when missing).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
scene=$(realpath "$1")
build=$(realpath "${2:-build}")
out=${3:-}
sky=${SKY:-1,1,1}
samples=${SAMPLES:-256}
reference_samples=${REFERENCE_SAMPLES:-1024}
solvers=${SOLVERS:-lightfield}
device=${DEVICE:-cpu}

if ! command -v blender >/dev/null; then
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get install -y -qq --no-install-recommends blender >/dev/null
fi
if [ -z "$out" ]; then
    out=$(mktemp -d)
    trap 'rm -rf "$out"' EXIT
fi
mkdir -p "$out"

cycles() {  # GLB NAME SKY -> OUT/NAME-cycles.json (a penumbra irradiance file)
    local glb=$1 name=$2 sky=$3
    blender -b --factory-startup --python "$here/bake_cycles.py" -- "$glb" \
        "$out/$name-corners.json" --samples "$samples" --environment-color "$sky" \
        --back-faces "${BACK_FACES:-diffuse}" \
        >"$out/$name-blender.log" 2>&1 || { tail -20 "$out/$name-blender.log"; exit 1; }
    /usr/bin/python3 "$here/gltf_corners.py" irradiance "$glb" "$out/$name-corners.json" \
        "$out/$name-cycles.json"
}
compare() {  # A B: relative RMSE (penumbra compare) and the ratio of the totals A / B
    local rmse
    rmse=$("$build/penumbra" compare --json "$1" "$2" |
        /usr/bin/python3 -c 'import json, sys; print(json.load(sys.stdin)["rel_rmse"])')
    /usr/bin/python3 - "$1" "$2" "$rmse" <<'EOF'
import json, sys
total = lambda path: sum(sum(v) for p in json.load(open(path))["primitives"] for v in p["irradiance"])
print("rel. RMSE %.1f%%, total light %.3f of Cycles'" % (100 * float(sys.argv[3]), total(sys.argv[1]) / total(sys.argv[2])))
EOF
}

# The scale: a 1 m plane facing up under a sky of 1 nit.
/usr/bin/python3 - "$out/plane.glb" <<'EOF'
import json, struct, sys
positions = [-0.5, 0, -0.5, 0.5, 0, -0.5, 0.5, 0, 0.5, -0.5, 0, 0.5]
indices = [0, 2, 1, 0, 3, 2]
binary = struct.pack("<12f", *positions) + struct.pack("<6I", *indices)
doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
       "nodes": [{"name": "n0", "mesh": 0}], "materials": [{"name": "m0"}],
       "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
       "buffers": [{"byteLength": len(binary)}],
       "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                       {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
       "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                      "min": [-0.5, 0, -0.5], "max": [0.5, 0, 0.5]},
                     {"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}]}
text = json.dumps(doc).encode()
text += b" " * (-len(text) % 4)
chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\x00") + binary
open(sys.argv[1], "wb").write(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
EOF
cycles "$out/plane.glb" plane 1,1,1
/usr/bin/python3 - "$out/plane-cycles.json" <<'EOF'
import json, math, sys
values = [v[0] for p in json.load(open(sys.argv[1]))["primitives"] for v in p["irradiance"]]
want = math.pi
print("scale: a plane under the sky, Cycles %.4f against pi L = %.4f" % (sum(values) / len(values), want))
if abs(sum(values) / len(values) / want - 1) > 0.02:
    sys.exit("Cycles' scale is off: the comparison below would be meaningless")
EOF

/usr/bin/python3 "$here/gltf_corners.py" name "$scene" "$out/scene.glb"
start=$(date +%s)
cycles "$out/scene.glb" scene "$sky"
echo "Cycles: $samples samples a corner in $(( $(date +%s) - start )) s"
"$build/penumbra" reference "$out/scene.glb" -o "$out/reference.json" --channel total \
    --samples "$reference_samples" --environment-color "$sky" -q
echo -n "penumbra reference ($reference_samples paths) against Cycles: "
compare "$out/reference.json" "$out/scene-cycles.json"
for solver in $solvers; do
    "$build/penumbra" bake "$out/scene.glb" -o "$out/$solver.json" --solver "$solver" \
        --device "$device" --channel total --environment-color "$sky" -q
    echo -n "penumbra bake --solver $solver against Cycles: "
    compare "$out/$solver.json" "$out/scene-cycles.json"
done
