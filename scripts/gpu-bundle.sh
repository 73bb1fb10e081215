#!/bin/bash
# Packs the built binaries for a run on a machine that has a GPU and its driver but no build
# tools (bench/results/gpu-h200-implicit.md): the CLI, the benches and the Vulkan tests, the
# libraries they load (not glibc's: the machine's own run them), Debian's Vulkan loader and
# validation layer, and env.sh, which sets the loader up from the bundle.
#
#   scripts/gpu-bundle.sh [BUILD] [OUT.tar.xz]     (default build/, gpu-bundle.tar.xz)
#
# There: unpack it to a folder B, `source B/env.sh`, then run B/bin/NAME from the repository
# root (the tests read scenes from the path they were built in: link it there). The driver's
# Vulkan ICD needs GLVND's libGLX.so.0 and libEGL.so.1; where the machine lacks them, unpack
# Debian's libglx0, libegl1, libglvnd0, libgl1, libopengl0 and libgles2 there first.
set -euo pipefail
build=${1:-build}
out=$(realpath -m "${2:-gpu-bundle.tar.xz}")
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/bin" "$stage/lib" "$stage/layers"
cp "$build/penumbra" "$build"/bench/penumbra-bench-* "$stage/bin/"
for t in implicit_test vulkan_passes_test ray_tracer_test direct_gpu_test lightfield_test; do
    cp "$build/tests/$t" "$stage/bin/"
done
multiarch=$(dirname "$(ldconfig -p | awk '/libvulkan.so.1 / {print $NF; exit}')")
cp -L "$multiarch/libvulkan.so.1" "$stage/lib/"
cp "$multiarch/libVkLayer_khronos_validation.so" "$stage/layers/"
sed 's#"library_path": *"[^"]*"#"library_path": "./libVkLayer_khronos_validation.so"#' \
    /usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json \
    > "$stage/layers/VkLayer_khronos_validation.json"
for f in "$stage"/bin/* "$stage/layers/libVkLayer_khronos_validation.so"; do
    ldd "$f" | awk '/=>/ {print $3}'
done | sort -u | while read -r lib; do
    case $(basename "$lib") in
        libc.so* | libm.so* | libpthread* | libdl.so* | librt.so* | ld-linux*) ;;
        *) cp -L "$lib" "$stage/lib/" ;;
    esac
done
cat > "$stage/env.sh" <<'ENV'
# Sourced: the bundle's libraries first, then the NVIDIA driver's, and its validation layer.
here=$(dirname "$(realpath "${BASH_SOURCE[0]}")")
icd=$(ls /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json \
    /etc/vulkan/icd.d/nvidia_icd.json 2>/dev/null | head -1 || true)
[ -n "$icd" ] && export VK_DRIVER_FILES=$icd VK_ICD_FILENAMES=$icd
glx=$(ls /usr/local/nvidia/lib64/libGLX_nvidia.so.0 /usr/lib/x86_64-linux-gnu/libGLX_nvidia.so.0 \
    2>/dev/null | head -1 || true)
driver=${glx:+$(dirname "$glx")}
export LD_LIBRARY_PATH=$here/lib${driver:+:$driver}
export VK_LAYER_PATH=$here/layers
ENV
tar -C "$stage" -cf - . | xz -T0 -3 > "$out"
echo "wrote $out ($(du -h "$out" | cut -f1))"
