#!/usr/bin/env bash
# Installs the Debian packages sbptt needs, only those that are missing, and any package named
# on the command line (the check scripts add clang, its sanitizer runtimes and clang-tidy).
# Run as root, or as a user with sudo.
# libqhull-dev: Debian's CMake package of MuJoCo names /usr/include/libqhull_r/ as an include
# directory of mujoco::mujoco without depending on the package that creates it, and CMake
# refuses a downstream target that links it while the directory is missing.
# locales: the sources of the German locale that test_train_locale makes with localedef.
set -euo pipefail
packages=(cmake make g++ libeigen3-dev catch2 libcli11-dev libmujoco-dev libqhull-dev python3
          python3-matplotlib locales "$@")
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
as_root=()
[ "$(id -u)" -eq 0 ] || as_root=(sudo)
echo "sbptt: installing ${missing[*]}" >&2
# Through env, because sudo's env_reset would drop a variable set in front of it, and tzdata
# (pulled in by matplotlib) would then wait for an answer on a hidden prompt.
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  "${missing[@]}" >/dev/null
