#!/usr/bin/env bash
# Every `penumbra` command the user docs show runs as shown (ctest Docs.ReadmeCommandsRunAsShown):
# the indented command lines that start with `build/penumbra` or `penumbra` are taken from
# README.md, docs/BAKING.md and docs/SERVICE.md, in that order, and run in a scratch folder that
# has the repository's `scenes/` and `build/`, against a penumbra-server started here (the
# first server line the docs show, on a free port: the address in the commands is replaced by
# the one it got; later server lines use it too). Placeholders are filled: SCENE.gltf with the
# Cornell box. Any command that fails fails the test, with its output. (`make` and `cmake`
# lines are the two commands themselves, the benchmarks and the install test's.)
#   $1  the build folder   $2  the source folder
set -uo pipefail
build=$(cd "$1" && pwd)
source_dir=$(cd "$2" && pwd)
work=$(mktemp -d)
server_pid=
cleanup() {
    [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
    rm -rf "$work"
}
trap cleanup EXIT
ln -s "$source_dir/scenes" "$work/scenes"
ln -s "$build" "$work/build"
cd "$work"

mapfile -t lines < <(for doc in README.md docs/BAKING.md docs/SERVICE.md; do
    sed -n 's/^    \(\(build\/\)\{0,1\}penumbra[ -].*\)$/\1/p' "$source_dir/$doc"
done)
[ ${#lines[@]} -gt 15 ] || { echo "found only ${#lines[@]} commands in the docs"; exit 1; }

url=
ran=0
for line in "${lines[@]}"; do
    command=${line%%  #*}  # the README's comments after two spaces and '#'
    command=${command/#penumbra /build/penumbra }
    command=${command% &}  # started in the background by the docs: this script does that
    if [[ $command == build/penumbra-server* ]]; then
        if [ -n "$url" ]; then echo "== $line  (the server on $url)"; continue; fi
        # The docs' server, on a free port and a private socket.
        command=${command//tcp:\/\/127.0.0.1:7450/tcp://127.0.0.1:0}
        command=${command//unix:\/\/\/tmp\/penumbra.sock/unix://$work/penumbra.sock}
        $command --ready-file "$work/ready" -q --device cpu &
        server_pid=$!
        for _ in $(seq 200); do [ -f "$work/ready" ] && break; sleep 0.05; done
        url=$(grep '^tcp://' "$work/ready")
        [ -n "$url" ] || { echo "the README's server did not start: $line"; exit 1; }
        echo "== $line  (on $url)"
        continue
    fi
    [ -n "$url" ] && command=${command//tcp:\/\/127.0.0.1:7450/$url}
    command=${command//SCENE.gltf/scenes/cornell-box.gltf}
    echo "== $line"
    if ! output=$(eval "timeout 300 $command" 2>&1); then
        echo "$output" | tail -20
        echo "FAILED: $line"
        exit 1
    fi
    ran=$((ran + 1))
done
echo "all $ran commands of the docs ran"
