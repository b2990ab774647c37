#!/usr/bin/env bash
# Installs what Sandpatch needs to build, test and benchmark on Debian 12.
# Idempotent and non-interactive: packages already present are skipped.
# Every package comes from Debian's own archive; nothing is downloaded otherwise.
set -euo pipefail

# Build tools and the libraries Sandpatch links (see docs/dependencies.md for why each).
PACKAGES=(
  build-essential cmake pkg-config ca-certificates
  libeigen3-dev        # small linear algebra (granule inertia, quaternions)
  libbullet-dev        # rigid bodies outside patches, heightfield collision
  libfcl-dev           # distance / continuous collision queries (shells, prediction)
  libegl-dev libgl-dev libgl1-mesa-dri libegl-mesa0   # headless EGL + OpenGL 4.3; llvmpipe without a GPU
  libomp-dev           # OpenMP runtime headers (GCC's libgomp comes with g++)
  nlohmann-json3-dev   # scene files and reports
  libpng-dev           # 16-bit heightmaps and image outputs
  libcli11-dev         # command-line parsing
  libtinyobjloader-dev # OBJ triangle meshes for bodies
  libgtest-dev         # unit and physics tests (GoogleTest + CTest)
  libbenchmark-dev     # micro-benchmarks of hot kernels
  python3              # peer set-up scripts and plots
  python3-matplotlib   # frame-time plots of `sandpatch stress` (scripts/plot_frames.py)
  ffmpeg               # `sandpatch run --video`: frames piped to it and encoded
  libglfw3-dev         # `sandpatch view`: its window, keys and mouse (built without a window if missing)
  xvfb xauth           # xvfb-run: the viewer's test runs it on a virtual X display (CI has no screen)
  clang libclang-rt-14-dev  # the sanitizer and libFuzzer build of .ci/run (scripts/fuzz.sh)
)
# The peer DEM is only needed for `sandpatch bench` comparisons; pass --peers to install it.
if [[ "${1:-}" == "--peers" ]]; then
  PACKAGES+=(lammps openmpi-bin)
fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
