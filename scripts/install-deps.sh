#!/usr/bin/env bash
# Installs the Debian packages the twin builds and tests with. Idempotent:
# does nothing when every package is already installed.
set -euo pipefail
packages=(
  cmake g++ make ccache pkg-config
  libeigen3-dev libsundials-dev libcgal-dev libsimbody-dev
  libyaml-cpp-dev libcli11-dev nlohmann-json3-dev libfmt-dev zlib1g-dev
  libzip-dev zipcmp zipmerge ziptool zip unzip
  libgtest-dev libgmock-dev libbenchmark-dev
  libnlopt-cxx-dev libnlopt-dev
  openmpi-bin libopenmpi-dev
  gnuplot-nox libxml2-utils python3
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "installing: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi
