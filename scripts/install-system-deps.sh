#!/usr/bin/env bash
# Installs the headless OpenGL libraries MuJoCo renders with (EGL + Mesa's software rasteriser),
# from Debian's packages, when they are missing. As root it installs them; otherwise it prints the
# exact command to run and fails.
set -euo pipefail

packages=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libglx-mesa0)
libs=(libEGL.so.1 libEGL_mesa.so.0 libGL.so.1)

known=$(ldconfig -p 2>/dev/null || true)
missing_lib=""
for lib in "${libs[@]}"; do
  case "$known" in *"$lib"*) ;; *) missing_lib="$lib"; break ;; esac
done
if [ -z "$missing_lib" ] && compgen -G "/usr/lib/*/dri/swrast_dri.so" >/dev/null; then
  exit 0
fi
[ -n "$missing_lib" ] || missing_lib="swrast_dri.so (Mesa software renderer)"

cmd="apt-get update && apt-get install -y --no-install-recommends ${packages[*]}"
if ! command -v apt-get >/dev/null 2>&1; then
  echo "error: $missing_lib is missing and this is not a Debian/Ubuntu machine; install the EGL and Mesa libraries (packages like: ${packages[*]})" >&2
  exit 1
fi
if [ "$(id -u)" != "0" ]; then
  echo "error: $missing_lib is missing. Install the headless OpenGL libraries with:" >&2
  echo "  sudo sh -c '$cmd'" >&2
  exit 1
fi
echo "installing headless OpenGL libraries: ${packages[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
