#!/usr/bin/env bash
# `make demo`: the lighting service end to end. penumbra-server keeps the bundled Cornell
# box resident; a scripted client moves a block and dims the light while a second client
# watches the frames stream; the final irradiance is written as .glb; SIGTERM stops the
# server.
set -euo pipefail
build=${1:-build}
out="$build/demo"
mkdir -p "$out"
tmp=$(mktemp -d /tmp/penumbra-demo-XXXXXX)
sock="unix://$tmp/penumbra.sock"
server_pid=""
cleanup() {
    [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null || true
    rm -rf "$tmp"
}
trap cleanup EXIT

echo "== penumbra-server --listen $sock --listen tcp://127.0.0.1:0 --scene-root scenes/"
"$build/penumbra-server" --listen "$sock" --listen tcp://127.0.0.1:0 --scene-root scenes \
    --ready-file "$tmp/ready" &
server_pid=$!
for _ in $(seq 200); do [ -f "$tmp/ready" ] && break; sleep 0.05; done
[ -f "$tmp/ready" ] || { echo "demo: the server did not start" >&2; exit 1; }

echo "== client 1: load cornell-box.gltf"
"$build/penumbra" --connect "$sock" load cornell-box.gltf

echo "== client 2: watch (prints every frame until the second edit has converged)"
"$build/penumbra" --connect "$sock" watch --until-converged --min-edit 2 --timeout 300 &
watch_pid=$!
sleep 0.5

echo "== client 1: script scenes/demo-edits.txt"
"$build/penumbra" --connect "$sock" script scenes/demo-edits.txt -q
wait "$watch_pid"

echo "== client 1: get -o $out/cornell-box-lit.glb"
"$build/penumbra" --connect "$sock" get -o "$out/cornell-box-lit.glb" --gltf scenes/cornell-box.gltf
"$build/penumbra" --connect "$sock" get -o "$out/cornell-box.json" -q

echo "== stopping the server (SIGTERM)"
kill -TERM "$server_pid"
wait "$server_pid"
server_pid=""
echo
echo "wrote $out/cornell-box-lit.glb (COLOR_0 = irradiance; open in any glTF viewer)"
echo "wrote $out/cornell-box.json"
