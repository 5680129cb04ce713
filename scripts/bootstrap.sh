#!/usr/bin/env bash
# Create .venv (Python >= 3.11) and install cnt-env with its dev extras.
#
# torch is installed FIRST, alone, pinned to the CPU build: once torch==2.13.0
# is present, the package install that follows finds it satisfied and no
# resolver can pull a CUDA build (several GB of nvidia-* packages). Before
# installing torch we ask pip, in a dry run, what it would fetch, and stop if
# that is a CUDA build. Set ALLOW_CUDA=1 to skip that guard.
#
# Called by the Makefile through the stamp file .venv/.installed, which is
# rebuilt only when pyproject.toml or this script changes.
#
# Environment: PYTHON (interpreter to create the venv with), VENV (default
# .venv), TORCH_REQ (default torch==2.13.0), EXTRAS (default dev,rerun,video: the demo writes
# a rerun recording and a video, and the replay tests read both back).
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${VENV:-.venv}
TORCH_REQ=${TORCH_REQ:-torch==2.13.0}
EXTRAS=${EXTRAS:-dev,rerun,video}
STAMP="$VENV/.installed"
CUDA_PATTERN='^(nvidia|cuda)[-_]'

log() { printf '[bootstrap] %s\n' "$*" >&2; }
die() { printf '[bootstrap] error: %s\n' "$*" >&2; exit 1; }

if [[ -z "${PYTHON:-}" ]]; then
    if command -v python3.11 >/dev/null 2>&1; then PYTHON=python3.11; else PYTHON=python3; fi
fi

if [[ ! -x "$VENV/bin/python" ]]; then
    command -v "$PYTHON" >/dev/null 2>&1 || die "no '$PYTHON' on PATH; set PYTHON=/path/to/python3.11"
    "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
        || die "$PYTHON is $("$PYTHON" -V 2>&1); cnt-env needs Python >= 3.11 (set PYTHON=...)"
    log "creating $VENV with $("$PYTHON" -V 2>&1)"
    "$PYTHON" -m venv "$VENV"
fi

VPY="$VENV/bin/python"
pip_() { "$VPY" -m pip "$@"; }
rm -f "$STAMP"

# 1. torch, alone, CPU build.
torch_installed=$("$VPY" -c 'import importlib.metadata as m; print(m.version("torch"))' 2>/dev/null || true)
if [[ -n "$torch_installed" ]]; then
    log "torch $torch_installed already installed"
    pip_ install --quiet "$TORCH_REQ"  # no-op when it satisfies TORCH_REQ
else
    if [[ "${ALLOW_CUDA:-0}" != 1 ]]; then
        log "checking which torch build pip would install for '$TORCH_REQ'"
        report=$(mktemp)
        errlog=$(mktemp)
        trap 'rm -f "$report" "$errlog"' EXIT
        pip_ install --dry-run --quiet --report "$report" "$TORCH_REQ" 2>"$errlog" \
            || { cat "$errlog" >&2; die "pip could not resolve '$TORCH_REQ'"; }
        cuda=$("$VPY" - "$report" "$CUDA_PATTERN" <<'EOF'
import json, re, sys
names = [i["metadata"]["name"] for i in json.load(open(sys.argv[1]))["install"]]
print(" ".join(n for n in names if re.match(sys.argv[2], n, re.IGNORECASE)))
EOF
)
        [[ -z "$cuda" ]] || die "pip would install a CUDA build of torch (with: $cuda).
  Provide a CPU wheel (e.g. PIP_FIND_LINKS=/dir/with/torch-2.13.0+cpu wheel) or set
  TORCH_REQ to one; set ALLOW_CUDA=1 to install the CUDA build anyway."
    fi
    log "installing $TORCH_REQ (first, on its own)"
    pip_ install "$TORCH_REQ"
fi

# 2. The package itself, editable, with its extras; torch is already satisfied.
log "installing cnt-env[$EXTRAS] (editable)"
pip_ install -e ".[$EXTRAS]"

# 3. Guard: no CUDA packages crept in.
if [[ "${ALLOW_CUDA:-0}" != 1 ]]; then
    cuda=$(pip_ list --format=freeze 2>/dev/null | grep -iE "$CUDA_PATTERN" || true)
    [[ -z "$cuda" ]] || die "CUDA packages were installed into $VENV: $cuda"
fi

log "torch $("$VPY" -c 'import importlib.metadata as m; print(m.version("torch"))')"
touch "$STAMP"
