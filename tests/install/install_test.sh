#!/usr/bin/env bash
# What `cmake --install` puts in place, used as a renderer would: the programs, the client
# library with its header, CMake package and pkg-config file; the example renderer
# (examples/renderer) built against the installed package both ways and run against a live
# penumbra-server from the same prefix; and the client alone configured with
# -DPENUMBRA_CLIENT_ONLY=ON (FlatBuffers, Asio and GLM only).
# Usage: install_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src=$1
build=$2
work=$(mktemp -d /tmp/penumbra-install-XXXXXX)
server=
cleanup() {
    if [ -n "$server" ]; then kill "$server" 2>/dev/null || true; wait "$server" 2>/dev/null || true; fi
    rm -rf "$work"
}
trap cleanup EXIT
step() { echo "== $*"; }

step "cmake --install"
cmake --install "$build" --prefix "$work/prefix" > "$work/install.log"
prefix=$work/prefix
for f in bin/penumbra bin/penumbra-server include/penumbra/client.h; do
    test -e "$prefix/$f" || { echo "missing after install: $f"; exit 1; }
done
pc=$(find "$prefix" -name penumbra-client.pc | head -1)
config=$(find "$prefix" -name PenumbraClientConfig.cmake | head -1)
test -n "$pc" && test -n "$config" || { echo "no pkg-config file or CMake package installed"; exit 1; }
"$prefix/bin/penumbra" --version

step "example renderer: find_package(PenumbraClient)"
cmake -S "$src/examples/renderer" -B "$work/example" -DCMAKE_PREFIX_PATH="$prefix" \
    -DCMAKE_BUILD_TYPE=Release > "$work/example-configure.log"
cmake --build "$work/example" -j 2 > "$work/example-build.log"

step "example renderer: pkg-config penumbra-client"
# shellcheck disable=SC2046
c++ -std=c++20 -O1 "$src/examples/renderer/main.cpp" -o "$work/example-pc" \
    $(PKG_CONFIG_PATH=$(dirname "$pc") pkg-config --cflags --libs penumbra-client)

step "against a live server from the prefix"
"$prefix/bin/penumbra-server" --listen "unix://$work/socket" --scene-root "$src/scenes" \
    --ready-file "$work/ready" > "$work/server.log" 2>&1 &
server=$!
for _ in $(seq 1 100); do [ -s "$work/ready" ] && break; sleep 0.1; done
test -s "$work/ready" || { echo "the server did not start"; cat "$work/server.log"; exit 1; }
timeout 120 "$work/example/penumbra-renderer-example" "unix://$work/socket" blocker.gltf 2
timeout 60 "$work/example-pc" "unix://$work/socket" blocker.gltf 1
# Refined output: the example prints the refined meshes it would draw.
refined=$(timeout 120 "$work/example/penumbra-renderer-example" "unix://$work/socket" \
    cornell-box.gltf 1 0.05)
echo "$refined"
echo "$refined" | grep -q "^refined " || { echo "no refined meshes in SceneInfo"; exit 1; }

step "the client alone: -DPENUMBRA_CLIENT_ONLY=ON"
cmake -S "$src" -B "$work/client-only" -DPENUMBRA_CLIENT_ONLY=ON > "$work/client-only.log"
cmake --build "$work/client-only" -j 2 --target penumbra_client >> "$work/client-only.log"
test -f "$work/client-only/client/libpenumbra_client.a"
echo "install test: all steps passed"
