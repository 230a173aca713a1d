#!/usr/bin/env bash
# Installs what icrender builds and tests against: the Debian packages, and Intel Open Image
# Denoise (OIDN), which Debian 12 does not package, into third_party/oidn/lib (git-ignored).
# Idempotent and cheap when everything is there: packages already present are skipped (one
# dpkg query), and the denoiser is not fetched again while its libraries and the stamp naming
# the pinned wheel's hash are in place.
set -euo pipefail

project="$(cd "$(dirname "$0")/.." && pwd)"

packages=(
  build-essential pkg-config
  libembree-dev
  libopenimageio-dev openimageio-tools
  # OpenEXR's own API: a streamed EXR's tiles are copied into the final file as compressed.
  libopenexr-dev
  libtinygltf-dev nlohmann-json3-dev libstb-dev
  libopenmpi-dev openmpi-bin
  libclang-dev clang
  iproute2
  # For the denoiser's wheel below: fetched over HTTPS, unpacked with unzip.
  curl ca-certificates unzip
)

install_packages() {
  local missing=()
  for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
      missing+=("$p")
    fi
  done

  if [ ${#missing[@]} -eq 0 ]; then
    echo "install-deps: all ${#packages[@]} packages present"
    return
  fi

  local sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    sudo_cmd=(sudo)
  fi

  echo "install-deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# --- Intel Open Image Denoise -------------------------------------------------------------
# The pyoidn wheel ships the OIDN 2.5.1 shared libraries and the TBB they were built with (no
# headers: icrender binds the few C functions it calls by hand, src/sys/oidn.rs). The wheel is
# pinned by version and sha256; it is located through PyPI's simple index (the API pip uses).
oidn_version=2.5.1
wheel=pyoidn-2.5.1.0-py3-none-manylinux2014_x86_64.whl
wheel_sha256=32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e
oidn_dir="$project/third_party/oidn"
oidn_lib="$oidn_dir/lib"
stamp="$oidn_lib/.installed-from"
# Only the CPU device is unpacked: the wheel's CUDA, HIP and SYCL devices (with SYCL's runtime,
# about 100 MB) need GPU drivers the renderer does not use, and OIDN loads whichever device
# modules it finds beside its core, so leaving them out only leaves out those devices.
oidn_files=(
  libOpenImageDenoise.so.2.5.1
  libOpenImageDenoise_core.so.2.5.1
  libOpenImageDenoise_device_cpu.so.2.5.1
  libtbb.so.12.19
)

oidn_present() {
  [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$wheel $wheel_sha256" ] || return 1
  local f
  for f in "${oidn_files[@]}" libOpenImageDenoise.so.2 libtbb.so.12; do
    [ -e "$oidn_lib/$f" ] || return 1
  done
}

wheel_url() {
  # The simple index lists each file as <a href="URL#sha256=HASH">NAME</a>; the pinned hash is
  # checked again on the downloaded bytes.
  local index
  index="$(curl -fsSL --retry 3 "https://pypi.org/simple/pyoidn/")" ||
    { echo "install-deps: cannot read PyPI's index of pyoidn (https://pypi.org/simple/pyoidn/)" >&2; exit 1; }
  printf '%s\n' "$index" | grep -o "href=\"[^\"]*/$wheel#sha256=$wheel_sha256\"" |
    head -n 1 | sed -e 's/^href="//' -e 's/#.*//' || true
}

install_oidn() {
  if oidn_present; then
    echo "install-deps: Open Image Denoise $oidn_version present in ${oidn_lib#"$project"/}"
    return
  fi
  echo "install-deps: fetching Open Image Denoise $oidn_version ($wheel) from PyPI"
  mkdir -p "$oidn_dir"
  local work
  work="$(mktemp -d "$oidn_dir/.fetch.XXXXXX")"
  # shellcheck disable=SC2064  # expand now: the trap must remove this run's folder
  trap "rm -rf '$work'" EXIT
  local url
  url="$(wheel_url)"
  [ -n "$url" ] || { echo "install-deps: $wheel with sha256 $wheel_sha256 is not listed on PyPI" >&2; exit 1; }
  curl -fsSL --retry 3 -o "$work/$wheel" "$url" ||
    { echo "install-deps: downloading $url failed" >&2; exit 1; }
  echo "$wheel_sha256  $work/$wheel" | sha256sum --check --quiet - ||
    { echo "install-deps: $wheel does not have the pinned sha256 $wheel_sha256; not installed" >&2; exit 1; }
  local inside=()
  for f in "${oidn_files[@]}"; do inside+=("pyoidn/oidn/lib/$f"); done
  unzip -q -j "$work/$wheel" "${inside[@]}" -d "$work/lib"
  # The wheel holds copies under every soname; one file each and links under the names the
  # loader asks for are enough.
  ln -s libOpenImageDenoise.so.2.5.1 "$work/lib/libOpenImageDenoise.so.2"
  ln -s libtbb.so.12.19 "$work/lib/libtbb.so.12"
  echo "$wheel $wheel_sha256" >"$work/lib/.installed-from"
  # The folder must be called lib: the libraries' RPATH is $ORIGIN/../lib.
  rm -rf "$oidn_lib"
  mv "$work/lib" "$oidn_lib"
  echo "install-deps: Open Image Denoise $oidn_version unpacked into ${oidn_lib#"$project"/}"
}

install_packages
install_oidn
