#!/usr/bin/env bash
# Installs the Debian packages icrender builds and tests against. Idempotent: packages already
# present are skipped, so running it twice costs one dpkg query.
set -euo pipefail

packages=(
  build-essential pkg-config
  libembree-dev
  libopenimageio-dev openimageio-tools
  libtinygltf-dev nlohmann-json3-dev libstb-dev
  libopenmpi-dev openmpi-bin
  libclang-dev clang
  iproute2
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo_cmd=(sudo)
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
