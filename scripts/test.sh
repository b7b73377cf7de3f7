#!/usr/bin/env bash
# Runs every test of bitrock, installing first what the tests need: Mesa's lavapipe, a software
# Vulkan driver, so the GPU tests run on machines without a GPU. The GPU tests fail loudly
# without an adapter; BITROCK_SKIP_GPU_TESTS=1 compiles them as ignored, so the summary counts
# them as such (CI never sets it).
set -euo pipefail
cd "$(dirname "$0")/.."

has_vulkan_driver() {
    # An ICD manifest in either standard place, and the Vulkan loader.
    { ls /usr/share/vulkan/icd.d/*.json || ls /etc/vulkan/icd.d/*.json; } >/dev/null 2>&1 \
        && ldconfig -p | grep libvulkan.so.1 >/dev/null
}
if ! has_vulkan_driver; then
    echo "installing Mesa lavapipe (mesa-vulkan-drivers, libvulkan1)..."
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
fi
# Silences a harmless warning of Mesa's device-select layer.
export NODEVICE_SELECT=1

# Slow tests (fits, simulations, ABC runs, GPU parity) run in release.
cargo test --release --all-targets
# --all-targets leaves out the doctests (the crate documentation's example of the library API).
cargo test --release --doc
