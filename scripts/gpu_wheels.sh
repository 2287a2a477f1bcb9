#!/bin/bash
# Run on the workstation before a device call: elevens' pure-Python dependencies that the GPU
# machine's image lacks, as wheels in .whl/ (ignored by git; carry it with the call). The image
# has JAX with CUDA, Flax, Optax, Orbax, NumPy, matplotlib, rich and pillow already
# (/work/.library/device/KINDS.md). imageio-ffmpeg (68 MB) is left out: no GIFs there.
set -eu
cd "$(dirname "$0")/.."
grep -qx "/.whl/" .git/info/exclude 2>/dev/null || echo "/.whl/" >> .git/info/exclude
mkdir -p .whl
for package in tyro==1.0.17 docstring_parser==0.18.0 typeguard==4.6.1 shtab==1.13.0 tensorboardX==2.6.5; do
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp --platform manylinux_2_28_x86_64 --platform any -d .whl "$package"
done
ls .whl
# On the device, first:  python3 -m pip install -q --no-index --no-deps --no-compile \
#   --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site:$PWD/src
