#!/usr/bin/env bash
# Idempotent set-up: system package for open3d, a virtualenv, pinned CPU torch, the project.
set -euo pipefail
VENV="${1:-.venv}"
PYTHON="${PYTHON:-python3}"

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "[setup] installing libusb-1.0-0 (needed by open3d)"
        apt-get update -qq >/dev/null 2>&1 || true
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
    else
        echo "[setup] warning: libusb-1.0-0 missing and cannot apt-get install it; open3d features will be unavailable" >&2
    fi
fi

if [ ! -x "$VENV/bin/python" ]; then
    echo "[setup] creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
PIP="$VENV/bin/python -m pip"
# Pinned CPU torch first: an unpinned torch would pull several GB of CUDA wheels.
if ! "$VENV/bin/python" -c "import torch" >/dev/null 2>&1; then
    echo "[setup] installing torch==2.13.0 (CPU)"
    $PIP install -q torch==2.13.0
fi
echo "[setup] installing sgbelief and its dependencies"
$PIP install -q -e ".[all,dev]"
# Ray (the optional extra sgbelief[ray], for --executor ray): best effort, so that the tests run
# the executor in Ray's local mode wherever it installs; they skip where it does not.
if ! "$VENV/bin/python" -c "import ray" >/dev/null 2>&1; then
    echo "[setup] installing ray (optional: --executor ray)"
    $PIP install -q "ray>=2.9" || echo "[setup] warning: ray did not install; --executor ray and its tests are unavailable" >&2
fi
# rerun-sdk (the optional extra sgbelief[rerun], for sgbelief record): best effort as well; the
# recording tests skip where it does not install.
if ! "$VENV/bin/python" -c "import rerun" >/dev/null 2>&1; then
    echo "[setup] installing rerun-sdk (optional: sgbelief record)"
    $PIP install -q "rerun-sdk>=0.41,<0.42" || echo "[setup] warning: rerun-sdk did not install; sgbelief record and its tests are unavailable" >&2
fi
# crowd-kit: the field's reference Dawid-Skene, which tests/test_dawid_skene.py checks sgbelief's
# against (a test dependency only). Its declared dependencies include transformers and pyarrow,
# which its aggregation module never imports: install it without them, plus what that module needs.
if ! "$VENV/bin/python" -c "import crowdkit.aggregation" >/dev/null 2>&1; then
    echo "[setup] installing crowd-kit (test reference for Dawid-Skene)"
    ($PIP install -q --no-deps "crowd-kit==1.4.2" && $PIP install -q attrs nltk "pandas>=2") \
        || echo "[setup] warning: crowd-kit did not install; its comparison test will be skipped" >&2
fi
"$VENV/bin/python" -c "import sgbelief, sys; print('[setup] sgbelief', sgbelief.__version__, 'ready on Python', sys.version.split()[0])"
