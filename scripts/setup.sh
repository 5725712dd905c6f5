#!/usr/bin/env bash
# Create .venv beside this repo and install warpcut into it, with the right torch build:
#   - a torch already importable in .venv is kept;
#   - a machine with an NVIDIA GPU gets PyPI's default (CUDA) torch;
#   - any other machine gets the CPU build of torch (a few hundred MB instead of several GB).
# Override with TORCH_SPEC (e.g. TORCH_SPEC="torch==2.13.0") and PYTHON (the interpreter to use).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
TORCH_CPU_VERSION=${TORCH_CPU_VERSION:-2.13.0}

if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
# shellcheck disable=SC1091
. .venv/bin/activate
python -m pip install -q --upgrade pip

if python -c "import torch" 2>/dev/null; then
  echo "setup: keeping installed torch $(python -c 'import torch; print(torch.__version__)')"
elif [ -n "${TORCH_SPEC:-}" ]; then
  python -m pip install -q "$TORCH_SPEC"
elif command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
  python -m pip install -q "torch>=2.4"
else
  # If pip's configured find-links already hold the CPU wheel, the plain pin takes it (its local
  # version 2.13.0+cpu sorts above PyPI's 2.13.0); otherwise add PyTorch's CPU index, since PyPI's
  # default Linux build bundles CUDA (several GB).
  if python -m pip download -q --no-deps --no-index -d "$(mktemp -d)" "torch==${TORCH_CPU_VERSION}" 2>/dev/null; then
    python -m pip install -q "torch==${TORCH_CPU_VERSION}"
  else
    python -m pip install -q "torch==${TORCH_CPU_VERSION}" --extra-index-url https://download.pytorch.org/whl/cpu
  fi
fi
python -m pip install -q -e ".[test]"
echo "setup: ready ($(python -c 'import torch, warp; print("torch", torch.__version__, "/ warp", warp.__version__)'))"
