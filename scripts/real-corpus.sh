#!/usr/bin/env bash
# The real-world corpus (issue 61): models nobody on the project wrote, and generated scenes
# of the kinds exporters write (boxes as face nodes, a sunlit maze), each baked at the
# defaults with every solver asked for and checked against `penumbra reference` at the same
# lighting. Writes OUT/real-corpus.json and OUT/real-corpus.md: per scene and solver the
# relative RMSE, the time from load to answer, the peak memory, the device, and whether the
# solver fell back (`stats.fallback`).
#
# usage: scripts/real-corpus.sh [BUILD] [OUT]   (BUILD default build, OUT default bench/results)
# env:   SOLVERS (default "antiradiance lightfield"), SAMPLES (reference paths a vertex,
#        default 1024), SCENES (names below; default all but
#        the engines, minutes and gigabytes each), DEVICE (default cpu)
# Needs Debian's assimp-testmodels and assimp-utils (installed when missing, as install-deps).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
out=${2:-bench/results}
solvers=${SOLVERS:-antiradiance lightfield}
samples=${SAMPLES:-1024}
device=${DEVICE:-cpu}
scenes=${SCENES:-house bookshelf-faces office-faces sunlit-maze box-textured clearcoat}
models=/usr/share/assimp/models

need=()
command -v assimp >/dev/null || need+=(assimp-utils)
[ -d "$models/IFC" ] || need+=(assimp-testmodels)
if [ ${#need[@]} -gt 0 ]; then
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$build/tools/make_scenes" "$work" --clutter >/dev/null

# scene name -> file and the sky it is lit by (constant radiance, nits)
file_of() {
    case $1 in
    house) # AC14-FZK-Haus (KIT/IAI), converted from IFC as a user would
        assimp export "$models/IFC/AC14-FZK-Haus.ifc" "$work/house.glb" >/dev/null
        echo "$work/house.glb" ;;
    engine) echo "$models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb" ;;
    engines) # two copies 255 units apart: parts that barely see each other
        /usr/bin/python3 scripts/copies.py "$models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb" \
            "$work/engines.glb" 2 255
        echo "$work/engines.glb" ;;
    clearcoat) echo "$models/glTF2/ClearCoat-glTF/ClearCoatTest.gltf" ;; # Khronos' sample model
    box-textured) echo "$models/glTF2/BoxTextured-glTF-Binary/BoxTextured.glb" ;;
    bookshelf-faces) echo "$work/bookshelf-5mm-faces.gltf" ;;
    office-faces)
        /usr/bin/python3 scripts/split-faces.py scenes/office.gltf "$work/office-faces.gltf"
        echo "$work/office-faces.gltf" ;;
    sunlit-maze) echo "$work/sunlit-maze.gltf" ;;
    *) echo "unknown scene $1" >&2; exit 2 ;;
    esac
}
sky_of() {
    case $1 in
    house | engine | engines | box-textured | office-faces | clearcoat) echo "--environment-color 1,1,1" ;;
    *) echo "" ;;
    esac
}

results="$work/rows.jsonl"
: >"$results"
for scene in $scenes; do
    f=$(file_of "$scene")
    sky=$(sky_of "$scene")
    echo "$scene: reference at $samples paths..." >&2
    ref_start=$(date +%s.%N)
    # shellcheck disable=SC2086
    "$build/penumbra" reference "$f" -o "$work/$scene-ref.json" --samples "$samples" \
        --channel total $sky -q 2>/dev/null
    ref_seconds=$(echo "$(date +%s.%N) - $ref_start" | bc)
    for solver in $solvers; do
        echo "$scene: $solver..." >&2
        start=$(date +%s.%N)
        status=0
        # shellcheck disable=SC2086
        /usr/bin/time -f "%M" -o "$work/rss" "$build/penumbra" bake "$f" -o "$work/$scene-$solver.json" \
            --solver "$solver" --device "$device" --channel total $sky -q \
            2>"$work/$scene-$solver.err" || status=$?
        seconds=$(echo "$(date +%s.%N) - $start" | bc)
        rss=$(tail -1 "$work/rss")
        rmse=null
        if [ "$status" -eq 0 ]; then
            rmse=$("$build/penumbra" compare "$work/$scene-$solver.json" "$work/$scene-ref.json" \
                --json | /usr/bin/python3 -c 'import json,sys; print(json.load(sys.stdin)["rel_rmse"])')
        fi
        /usr/bin/python3 - "$scene" "$solver" "$status" "$seconds" "$rss" "$rmse" "$samples" \
            "$ref_seconds" "$work/$scene-$solver.json" "$work/$scene-$solver.err" >>"$results" <<'EOF'
import json, os, sys
scene, solver, status, seconds, rss, rmse, samples, ref_seconds, path, err = sys.argv[1:]
row = {"scene": scene, "solver": solver, "exit": int(status), "seconds": float(seconds),
       "peak_rss_mb": int(rss) / 1024, "rel_rmse": None if rmse == "null" else float(rmse),
       "reference_samples": int(samples), "reference_seconds": float(ref_seconds)}
if os.path.exists(path) and int(status) == 0:
    stats = json.load(open(path))["stats"]
    row["device"] = stats.get("device")
    row["elements"] = stats.get("elements")
    row["fallback"] = stats.get("fallback", {}).get("why")
else:
    row["error"] = open(err).read().strip().splitlines()[-1:] or None
print(json.dumps(row))
EOF
    done
done

mkdir -p "$out"
/usr/bin/python3 - "$results" "$out" <<'EOF'
import json, platform, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
out = sys.argv[2]
json.dump({"host": platform.node(), "rows": rows}, open(out + "/real-corpus.json", "w"), indent=1)
with open(out + "/real-corpus.md", "w") as md:
    md.write("# The real-world corpus (scripts/real-corpus.sh)\n\n"
             "`bake --channel total` at the defaults against `reference --channel total`, "
             "relative RMSE over every vertex.\n\n"
             "| scene | solver | device | elements | rel. RMSE | load to answer | peak RSS | note |\n"
             "|---|---|---|---|---|---|---|---|\n")
    for r in rows:
        err = "%.1f%%" % (100 * r["rel_rmse"]) if r["rel_rmse"] is not None else "exit %d" % r["exit"]
        note = r.get("fallback") or (" ".join(r.get("error") or []) if r["exit"] else "")
        md.write("| %s | %s | %s | %s | %s | %.1f s | %.0f MB | %s |\n" % (
            r["scene"], r["solver"], r.get("device", "-"), r.get("elements", "-"), err,
            r["seconds"], r["peak_rss_mb"], note))
print(open(out + "/real-corpus.md").read())
EOF
