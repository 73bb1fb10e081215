#!/usr/bin/env bash
# Installs the Debian packages Penumbra builds, tests and runs with.
# Idempotent: installs only what is missing; uses sudo when not root.
set -euo pipefail

packages=(
    build-essential cmake pkg-config
    libvulkan-dev vulkan-validationlayers mesa-vulkan-drivers glslang-tools vulkan-tools
    libtinygltf-dev nlohmann-json3-dev libstb-dev libglm-dev
    libcli11-dev libtbb-dev libgtest-dev libembree-dev
    libflatbuffers-dev flatbuffers-compiler libasio-dev libopenexr-dev
    clang-format
)

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"
echo "install-deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
