#!/usr/bin/env bash
# Runs every test of bitrock, installing what the tests need beside the build: Mesa's lavapipe,
# a software Vulkan driver, so the GPU tests run on machines without a GPU, and Chromium with
# its WebDriver, in which the live page is tested. The GPU tests fail loudly
# without an adapter; BITROCK_SKIP_GPU_TESTS=1 compiles them as ignored, so the summary counts
# them as such (CI never sets it).
set -euo pipefail
cd "$(dirname "$0")/.."

# The background jobs and temporary files of the run, for the way out.
SYSTEM_JOB="" SYSTEM_LOG="" DEPENDENCIES="" ARVIZ1="" WHEEL_JOB="" ARVIZ1_TESTS="" UNIT_TESTS=""
BITROCK_CACHE_DIR="" WHEELS=""
# Stops pip's and the tests' jobs still running, then the shell that started each: a job that
# has ended is never signalled, as its number may have been given to another process since.
stop_background() {
    local job running
    running=" $(jobs -pr | tr '\n' ' ') "
    for job in "$@"; do
        case "$running" in
            *" $job "*) { pkill -P "$job"; kill "$job"; } 2>/dev/null || true ;;
        esac
    done
}
# On the way out, whatever the reason: apt's install is waited for, never stopped (dpkg cut part
# way leaves the system's packages half configured), and its log shown where it failed.
cleanup() {
    stop_background $DEPENDENCIES $ARVIZ1 $WHEEL_JOB $ARVIZ1_TESTS $UNIT_TESTS
    if [ -n "$SYSTEM_JOB" ]; then
        echo "waiting for the system packages' install (apt) to end..." >&2
        if ! wait "$SYSTEM_JOB"; then
            cat "$SYSTEM_LOG" >&2
            echo "installing ${SYSTEM_PACKAGES[*]} failed (above)" >&2
        fi
    fi
    rm -rf "$BITROCK_CACHE_DIR" "$SYSTEM_LOG" "$WHEELS"
}
trap cleanup EXIT

# A command as root: through sudo for a user. apt always runs as `env DEBIAN_FRONTEND=…
# apt-get` (sudo resets the environment), so that one sudoers rule allows the update and the
# install alike; the install waits up to ten minutes for another apt to let go of dpkg's lock
# rather than failing at once (the update does not wait).
as_root() {
    if [ "$(id -u)" -ne 0 ]; then sudo "$@"; else "$@"; fi
}
apt_update() {
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
}
apt_get_install() {
    as_root env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq "$@" >/dev/null
}
apt_install() {
    apt_update
    apt_get_install "$@"
}

has_vulkan_driver() {
    # An ICD manifest in either standard place, and the Vulkan loader.
    { ls /usr/share/vulkan/icd.d/*.json || ls /etc/vulkan/icd.d/*.json; } >/dev/null 2>&1 \
        && ldconfig -p | grep libvulkan.so.1 >/dev/null
}
# Waits for the background job whose number the variable named `$1` holds, then forgets it
# (a signal during the wait leaves it known to the exit's cleanup); where it failed, shows its
# log and ends the run saying what failed.
wait_for() {
    local job="${!1}" log="$2" what="$3" status=0
    wait "$job" || status=$?
    printf -v "$1" '%s' ""
    if [ "$status" -ne 0 ]; then
        cat "$log" >&2
        echo "$what failed (above)" >&2
        exit 1
    fi
}

# What the tests need of the system is installed while the release build runs (apt mostly waits
# on the network and the disk, the build on the cores), and waited for before the first test.
SYSTEM_PACKAGES=()
if ! has_vulkan_driver; then
    echo "installing Mesa lavapipe (mesa-vulkan-drivers, libvulkan1)..."
    SYSTEM_PACKAGES+=(mesa-vulkan-drivers libvulkan1)
fi
if ! { command -v chromium && command -v chromedriver; } >/dev/null 2>&1; then
    echo "installing Chromium and its WebDriver (chromium, chromium-driver)..."
    SYSTEM_PACKAGES+=(chromium chromium-driver)
fi
if [ ${#SYSTEM_PACKAGES[@]} -gt 0 ]; then
    SYSTEM_LOG="$(mktemp)"
    if [ "$(id -u)" -ne 0 ]; then
        # In the foreground, where sudo can ask for its password.
        apt_update
        apt_get_install "${SYSTEM_PACKAGES[@]}" > "$SYSTEM_LOG" 2>&1 &
    else
        apt_install "${SYSTEM_PACKAGES[@]}" > "$SYSTEM_LOG" 2>&1 &
    fi
    SYSTEM_JOB=$!
fi
# A second install (Python's venv, below) waits for this one first.
wait_for_system_packages() {
    if [ -n "$SYSTEM_JOB" ]; then
        wait_for SYSTEM_JOB "$SYSTEM_LOG" "installing ${SYSTEM_PACKAGES[*]}"
    fi
}
# Silences a harmless warning of Mesa's device-select layer.
export NODEVICE_SELECT=1
# The GPU scoring shapes are measured once per test run, into a cache of its own: the tests
# neither read nor change the user's.
BITROCK_CACHE_DIR="$(mktemp -d)"
export BITROCK_CACHE_DIR

# The Python tests' virtual environment.
mkdir -p "${CARGO_TARGET_DIR:-target}"
TARGET="$(cd "${CARGO_TARGET_DIR:-target}" && pwd)"
VENV="$TARGET/python-venv"
if [ ! -x "$VENV/bin/python" ] && ! python3 -m venv "$VENV" >/dev/null 2>&1; then
    rm -rf "$VENV"
    echo "installing Python's venv (python3, python3-venv)..."
    wait_for_system_packages
    apt_install python3 python3-venv
    python3 -m venv "$VENV"
fi
# The Python tests' dependencies (the package's, its test extra's, the browser test's) are
# installed while the Rust tests build: pip mostly unpacks, on one core, while the build keeps
# both busy. Read from pyproject.toml where the environment's Python reads TOML (3.11 on);
# elsewhere the package's install below fetches them.
python_dependencies() {
    "$VENV/bin/python" - <<'PY' > "$TARGET/python-dependencies.txt"
try:
    import tomllib
except ImportError:
    raise SystemExit(0)
with open("bindings/python/pyproject.toml", "rb") as f:
    project = tomllib.load(f)["project"]
print("\n".join(project["dependencies"] + project["optional-dependencies"]["test"]))
PY
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check \
        -r "$TARGET/python-dependencies.txt" -r tests/browser/requirements.txt
}
python_dependencies > "$TARGET/python-dependencies.log" 2>&1 &
DEPENDENCIES=$!

# ArviZ 1.x (it needs Python ≥ 3.12) reads the runs' and the evidence's DataTrees as the 0.2x
# line does: the package's abi3 wheel in a second environment, made beside the build too.
newer_python() {
    local p
    for p in python3.14 python3.13 python3.12; do
        if command -v "$p" >/dev/null && "$p" -c 'import sys; assert sys.version_info >= (3, 12)' 2>/dev/null; then
            command -v "$p"
            return
        fi
    done
    if command -v pyenv >/dev/null; then
        for p in $(pyenv versions --bare 2>/dev/null | sort -rV); do
            case "$p" in 3.1[2-9]*) echo "$(pyenv root)/versions/$p/bin/python3"; return ;; esac
        done
    fi
}
PYTHON_NEW="$(newer_python || true)"
VENV_NEW="$TARGET/python-venv-arviz1"
arviz1_environment() {
    [ -x "$VENV_NEW/bin/python" ] || "$PYTHON_NEW" -m venv "$VENV_NEW"
    "$VENV_NEW/bin/python" -m pip install -q --disable-pip-version-check "arviz>=1,<2" "xarray>=2024.10" "pandas>=2.0" pytest
}
if [ -n "$PYTHON_NEW" ]; then
    arviz1_environment > "$TARGET/python-arviz1.log" 2>&1 &
    ARVIZ1=$!
fi
WHEELS="$(mktemp -d)"

# Slow tests (fits, simulations, ABC runs, GPU parity) run in release. The library's unit
# tests are built first and run while the binary and the integration tests build (rustc's
# front end keeps one core busy there, not two); everything is built before the other tests
# run, so that the Python package's wheel (pip builds it with maturin, linking the very build
# of the library made here) is made while they run.
# Cargo's messages as JSON (the compiler's diagnostics still rendered, on stderr): the unit
# tests' executable is the one artifact with one.
UNIT_TEST_BINARY="$(cargo test --release --lib --no-run --message-format=json-render-diagnostics | "$VENV/bin/python" -c '
import json, sys
for line in sys.stdin:
    message = json.loads(line)
    if message.get("reason") == "compiler-artifact" and message.get("executable"):
        print(message["executable"])
')"
if [ ! -x "$UNIT_TEST_BINARY" ]; then
    echo "cargo named no single executable for the library's unit tests: '$UNIT_TEST_BINARY'" >&2
    exit 1
fi
wait_for_system_packages
"$UNIT_TEST_BINARY" > "$TARGET/unit-tests.log" 2>&1 &
UNIT_TESTS=$!
cargo test --release --all-targets --no-run
"$VENV/bin/python" -m pip wheel -q --disable-pip-version-check --no-deps -w "$WHEELS" ./bindings/python \
    > "$TARGET/python-wheel.log" 2>&1 &
WHEEL_JOB=$!
wait_for UNIT_TESTS "$TARGET/unit-tests.log" "the library's unit tests"
cat "$TARGET/unit-tests.log"
# Every target but the library's unit tests, run above.
cargo test --release --bins --test '*' --bench '*' --examples
# --all-targets leaves out the doctests (the crate documentation's example of the library API).
cargo test --release --doc

wait_for DEPENDENCIES "$TARGET/python-dependencies.log" "installing the Python tests' dependencies"
wait_for WHEEL_JOB "$TARGET/python-wheel.log" "building the Python package's wheel"
WHEEL="$(ls "$WHEELS"/bitrock-*.whl)"
# The Python package, installed as its users install it (from its wheel), then its tests
# against the binary built above.
"$VENV/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "$WHEEL"
"$VENV/bin/python" -m pip install -q --disable-pip-version-check "$WHEEL[test]"
# The extension's type stubs are generated from its Rust signatures and doc comments (PyO3's
# introspection), never written by hand: the committed ones must be what the code gives.
STUBS="$(mktemp -d)"
(cd bindings/python && "$VENV/bin/maturin" generate-stubs --profile release --out "$STUBS" -q)
if ! diff -u bindings/python/python/bitrock/_bitrock.pyi "$STUBS/bitrock/_bitrock.pyi"; then
    echo "bindings/python/python/bitrock/_bitrock.pyi differs from the Rust code's: in bindings/python run" >&2
    echo "  maturin generate-stubs --profile release --out python" >&2
    exit 1
fi
rm -rf "$STUBS"
# On two workers, each test file on one (its module fixtures made once), the ten slowest
# listed at the end. pytest exits 5 when it collects no test (on xdist's workers too): set -e
# fails the run then.
BITROCK_BIN="$TARGET/release/bitrock" "$VENV/bin/python" -m pytest -q -n 2 --dist loadfile --durations=10 \
    bindings/python/tests

# ArviZ 1.x's tests beside the browser's (they share no files), reported after it.
if [ -n "$ARVIZ1" ]; then
    wait_for ARVIZ1 "$TARGET/python-arviz1.log" "making the ArviZ 1.x environment"
    "$VENV_NEW/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "$WHEEL"
    BITROCK_BIN="$TARGET/release/bitrock" "$VENV_NEW/bin/python" -m pytest -q -k arviz \
        bindings/python/tests/test_abc.py bindings/python/tests/test_evidence.py \
        > "$TARGET/python-arviz1-tests.log" 2>&1 &
    ARVIZ1_TESTS=$!
else
    echo "ArviZ 1.x tests not run: it needs Python 3.12 or newer, and none was found here" >&2
fi

# The live page of `bitrock watch --serve` in a real browser: headless Chromium driven through
# its WebDriver (selenium), against the binary built above.
"$VENV/bin/python" -m pip install -q --disable-pip-version-check -r tests/browser/requirements.txt
BITROCK_BIN="$TARGET/release/bitrock" "$VENV/bin/python" -m pytest -q tests/browser

if [ -n "$ARVIZ1_TESTS" ]; then
    echo "ArviZ 1.x:"
    wait_for ARVIZ1_TESTS "$TARGET/python-arviz1-tests.log" "the ArviZ 1.x tests"
    cat "$TARGET/python-arviz1-tests.log"
fi
