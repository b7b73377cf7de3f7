#!/usr/bin/env bash
# Runs every test of bitrock, installing first what the tests need.
# (Mesa's lavapipe software Vulkan driver joins this list when the GPU evaluator lands.)
set -euo pipefail
cd "$(dirname "$0")/.."
# Slow tests (fits, simulations) run in release.
cargo test --release --all-targets
