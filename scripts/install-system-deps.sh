#!/usr/bin/env bash
# Install the system libraries swarmpose needs on Debian/Ubuntu, when they are missing.
# Open3D's wheel links libusb-1.0, libGL, libEGL and libgomp; a fresh Debian may also lack python3-venv.
# openni2: sources need OpenNI2: libopenni2-0 (libOpenNI2.so.0 and its drivers) and libopenni2-dev
# (libOpenNI2.so, the name the `openni` Python bindings load).
# As root this runs apt-get; otherwise it names the packages to install and fails.
# As root it also installs what the container test (tests/docker/test_container.py) and
# scripts/build-image.sh use: podman, runc (podman's runtime where crun refuses hybrid cgroups) and
# debootstrap (to make debian:bookworm-slim when no registry is reachable). They are optional:
# without root a missing one is only reported (that test is then skipped), never a failure.
set -euo pipefail

python=${PYTHON:-python3}
declare -A lib_package=(
  [libusb-1.0.so.0]=libusb-1.0-0
  [libGL.so.1]=libgl1
  [libEGL.so.1]=libegl1
  [libgomp.so.1]=libgomp1
  [libOpenNI2.so.0]=libopenni2-0
  [libOpenNI2.so]=libopenni2-dev
)
# ldconfig lives in /sbin on Debian, off a normal user's PATH; read its cache once.
ldconfig_bin=$(command -v ldconfig || echo /sbin/ldconfig)
cache=$("$ldconfig_bin" -p 2>/dev/null || true)
missing=()
for lib in "${!lib_package[@]}"; do
  if [[ $cache != *"$lib ("* ]]; then  # ldconfig -p lines read "<name> (libc6,...) => <path>"
    missing+=("${lib_package[$lib]}")
  fi
done
if ! "$python" -m venv --help >/dev/null 2>&1 || ! "$python" -c "import ensurepip" >/dev/null 2>&1; then
  missing+=(python3-venv)
fi
# Optional: the container tools (command -> package); debootstrap lives in /usr/sbin.
declare -A tool_package=([podman]=podman [runc]=runc [debootstrap]=debootstrap)
optional=()
for tool in "${!tool_package[@]}"; do
  if ! command -v "$tool" >/dev/null && [[ ! -x /usr/sbin/$tool ]]; then
    optional+=("${tool_package[$tool]}")
  fi
done
if ((${#missing[@]} == 0 && ${#optional[@]} == 0)); then
  exit 0
fi
if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  if ((${#missing[@]} > 0)); then
    echo "installing system packages: ${missing[*]}"
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
  if ((${#optional[@]} > 0)); then
    echo "installing the container tools: ${optional[*]}"
    if ! apt-get install -y -qq --no-install-recommends "${optional[@]}" debian-archive-keyring >/dev/null; then
      echo "could not install ${optional[*]}: tests/docker/test_container.py will be skipped" >&2
    fi
  fi
elif ((${#missing[@]} > 0)); then
  echo "swarmpose needs these system packages: ${missing[*]}" >&2
  echo "install them (e.g. 'sudo apt-get install ${missing[*]}') and run make again" >&2
  exit 1
else
  echo "note: ${optional[*]} not installed: tests/docker/test_container.py (the image built and run)" \
    "is skipped without them (and without root)" >&2
fi
