#!/usr/bin/env bash
# Installs the Debian packages Penumbra builds, tests and runs with.
# Idempotent: installs only what is missing; uses sudo when not root.
set -euo pipefail

packages=(
    build-essential cmake pkg-config
    libvulkan-dev vulkan-validationlayers mesa-vulkan-drivers glslang-tools vulkan-tools
    libtinygltf-dev libdraco-dev libmeshoptimizer-dev gltfpack nlohmann-json3-dev libstb-dev libglm-dev
    libcli11-dev libtbb-dev libgtest-dev libembree-dev
    libflatbuffers-dev flatbuffers-compiler libasio-dev libopenexr-dev libzstd-dev
    clang-format
    clang libclang-rt-14-dev
    python3 python3-venv python3-setuptools python3-flatbuffers python3-numpy python3-jsonschema python3-zstandard
    assimp-testmodels assimp-utils
)

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done
# Node and npm for the test tools below, unless some install of them is already there.
command -v node >/dev/null && command -v npm >/dev/null || missing+=(nodejs npm)
if [ ${#missing[@]} -gt 0 ]; then
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    echo "install-deps: installing ${missing[*]}"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Test tools from npm (tests/tools/package.json, pinned by its lock file): the Khronos glTF
# validator.
tools="$(dirname "$0")/../tests/tools"
if [ ! -d "$tools/node_modules/gltf-validator" ]; then
    echo "install-deps: npm ci in tests/tools (gltf-validator)"
    npm ci --prefix "$tools" --no-audit --no-fund --loglevel=error >/dev/null
fi
