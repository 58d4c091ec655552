#!/usr/bin/env bash
# Build the swarmpose daemon's image (docker/Dockerfile) with podman, from the repository root.
#
#   scripts/build-image.sh [TAG]          # TAG defaults to swarmpose:latest
#
# The Dockerfile starts FROM debian:bookworm-slim. When podman has no such image and cannot pull
# docker.io/library/debian:bookworm-slim (no registry reachable), this makes the same kind of image
# the official one is, a minimal debootstrap of bookworm (--variant=minbase) from Debian's own
# archive ($DEBIAN_MIRROR, default http://deb.debian.org/debian), trimmed of documentation and
# apt lists, and imports it under both localhost/debian:bookworm-slim (what it is) and
# docker.io/library/debian:bookworm-slim (the name the FROM resolves to, so podman finds it
# locally and never asks a registry). Debootstrapping needs root and the debootstrap package.
#
# The build runs with --format docker (OCI images cannot hold the HEALTHCHECK) and --network host
# (RUN steps reach Debian's archive and PyPI without a container network). Layers are cached: a
# rebuild after a change to service/ reinstalls only the package, not its dependencies.
# Prints the build time and the image size at the end. Variables: PODMAN (default podman),
# DEBIAN_MIRROR, PULL_TIMEOUT_S (default 30), PIP_CERT (a CA bundle for pip in the build).
set -euo pipefail

if [[ ${1:-} == -* ]]; then
  sed -n '2,18s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"
  [[ $1 == -h || $1 == --help ]] && exit 0
  exit 2
fi
tag=${1:-swarmpose:latest}
podman=${PODMAN:-podman}
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
pull_timeout=${PULL_TIMEOUT_S:-30}
base=docker.io/library/debian:bookworm-slim
local_base=localhost/debian:bookworm-slim
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

fail() {
  echo "build-image.sh: $*" >&2
  exit 1
}

command -v "$podman" >/dev/null || fail "podman not found: install it (as root: apt-get install podman," \
  "or run scripts/install-system-deps.sh as root), or set PODMAN"
"$podman" info >/dev/null 2>&1 || fail "podman cannot run a container here: '$podman info' fails:" \
  "$("$podman" info 2>&1 | tail -n 1)"

# Dirs the cleanup trap removes; set before the trap is installed.
rootfs=""
cleanup() {
  if [[ -n $rootfs && -d $rootfs ]]; then
    rm -rf --one-file-system "$rootfs"
  fi
}
trap cleanup EXIT

debootstrap_base() {
  [[ $(id -u) -eq 0 ]] || fail "$base is not here and cannot be pulled; making it with debootstrap needs root"
  command -v debootstrap >/dev/null || fail "$base is not here and cannot be pulled; install debootstrap" \
    "(apt-get install debootstrap) to make it from $mirror"
  rootfs=$(mktemp -d /var/tmp/swarmpose-bookworm.XXXXXX)
  echo "build-image.sh: debootstrap --variant=minbase bookworm from $mirror into $rootfs"
  debootstrap --variant=minbase bookworm "$rootfs" "$mirror" >"$rootfs.log" 2>&1 \
    || fail "debootstrap failed; its log: $rootfs.log"
  rm -f "$rootfs.log"
  # The suites the official image lists (debootstrap writes only the main suite to sources.list).
  rm -f "$rootfs/etc/apt/sources.list"
  cat >"$rootfs/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $mirror
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: ${mirror%/debian}/debian-security
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
  # Slim: no manuals, documentation (copyright files stay) or translations, now or from later installs.
  cat >"$rootfs/etc/dpkg/dpkg.cfg.d/swarmpose-slim" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
path-exclude /usr/share/lintian/*
EOF
  find "$rootfs/usr/share/doc" -mindepth 1 -not -name copyright -not -type d -delete
  find "$rootfs/usr/share/doc" -mindepth 1 -type d -empty -delete
  rm -rf "$rootfs"/usr/share/{man,info,lintian}/* "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/*.bin \
    "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/log/*.log
  find "$rootfs/usr/share/locale" -mindepth 1 -maxdepth 1 -not -name locale.alias -exec rm -rf {} +
  echo "build-image.sh: importing it as $local_base and $base"
  tar -C "$rootfs" --numeric-owner -c . \
    | "$podman" import --change 'CMD ["bash"]' \
        --message "debootstrap --variant=minbase bookworm $mirror (scripts/build-image.sh)" - "$local_base" \
        >/dev/null || fail "podman import of the debootstrapped root failed"
  "$podman" tag "$local_base" "$base"
  rm -rf --one-file-system "$rootfs"
  rootfs=""
  echo "build-image.sh: made the base image in $(($(date +%s) - started)) s"
}

started=$(date +%s)
if "$podman" image exists "$base"; then
  echo "build-image.sh: base image $base is here"
elif timeout "$pull_timeout" "$podman" pull --quiet "$base" >/dev/null 2>&1; then
  echo "build-image.sh: pulled $base"
else
  echo "build-image.sh: $base is not here, and pulling it failed (no registry reachable within ${pull_timeout} s)"
  debootstrap_base
fi

# Whether podman runs containers here as it is, or needs the options of a VM with hybrid cgroups
# (crun refuses them; runc does not) and without CAP_SYS_RESOURCE (podman's default rlimits, nofile
# 1048576 and nproc above conmon's 32768, cannot be set).
run_options=()
if ! probe=$("$podman" run --rm --network host --pull=never "$base" true 2>&1); then
  hard_nofile=$(ulimit -Hn)
  hard_nproc=$(ulimit -Hu)
  [[ $hard_nofile == unlimited ]] && hard_nofile=1048576
  [[ $hard_nproc == unlimited || $hard_nproc -gt 32768 ]] && hard_nproc=32768
  compat=(--runtime runc --ulimit "nofile=$hard_nofile:$hard_nofile" --ulimit "nproc=$hard_nproc:$hard_nproc")
  if command -v runc >/dev/null && "$podman" run "${compat[@]}" --rm --network host --pull=never "$base" true \
      >/dev/null 2>&1; then
    run_options=("${compat[@]}")
    echo "build-image.sh: podman cannot run containers here as it is ($probe); it can with: ${run_options[*]}"
  else
    fail "podman cannot run a container here: $probe (tried also: ${compat[*]}; is runc installed?)"
  fi
fi

# pip in the build trusts what the host's pip trusts: $PIP_CERT, else the host's CA bundle (needed
# behind a TLS-intercepting proxy; a superset of pip's own bundle elsewhere).
build_options=()
cert=${PIP_CERT:-/etc/ssl/certs/ca-certificates.crt}
if [[ -f $cert ]]; then
  build_options=(--volume "$(realpath "$cert"):/run/build-ca.crt:ro" --build-arg PIP_CERT=/run/build-ca.crt)
fi

echo "build-image.sh: podman build -f docker/Dockerfile -t $tag"
"$podman" build --format docker --network host --pull=never --layers "${run_options[@]}" "${build_options[@]}" \
  -f "$repo/docker/Dockerfile" -t "$tag" "$repo" || fail "podman build failed (its output is above)"
finished=$(date +%s)

size=$("$podman" image inspect --format '{{.Size}}' "$tag")
echo "build-image.sh: built $tag in $((finished - started)) s; image size $((size / 1000000)) MB ($size bytes)"
# The last line: the options `podman run` needs here (none on most machines); tests/docker reads it.
echo "podman-run-options: ${run_options[*]}"
