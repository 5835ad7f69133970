#!/usr/bin/env bash
# Installs the system packages VLN-Pilot needs from Debian's packages, only when they are missing:
#   gl       the headless OpenGL libraries MuJoCo renders with (EGL + Mesa's software rasteriser)
#   browser  Chromium, for the report tests (driven by Playwright's Python package)
# As root it installs them; otherwise it prints the exact command to run and fails.
set -euo pipefail

wants=("$@")
[ ${#wants[@]} -gt 0 ] || wants=(gl)

packages=()
reasons=()
for want in "${wants[@]}"; do
  case "$want" in
    gl)
      known=$(ldconfig -p 2>/dev/null || true)
      for lib in libEGL.so.1 libEGL_mesa.so.0 libGL.so.1; do
        case "$known" in *"$lib"*) ;; *) reasons+=("$lib"); ;; esac
      done
      compgen -G "/usr/lib/*/dri/swrast_dri.so" >/dev/null || reasons+=("swrast_dri.so (Mesa software renderer)")
      [ ${#reasons[@]} -eq 0 ] || packages+=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libglx-mesa0)
      ;;
    browser)
      if [ ! -x /usr/bin/chromium ]; then reasons+=("/usr/bin/chromium"); packages+=(chromium fonts-dejavu-core); fi
      ;;
    *) echo "error: unknown dependency group '$want'; valid groups: gl, browser" >&2; exit 2 ;;
  esac
done
[ ${#packages[@]} -gt 0 ] || exit 0

cmd="apt-get update && apt-get install -y --no-install-recommends ${packages[*]}"
if ! command -v apt-get >/dev/null 2>&1; then
  echo "error: missing ${reasons[*]} and this is not a Debian/Ubuntu machine; install: ${packages[*]}" >&2
  exit 1
fi
if [ "$(id -u)" != "0" ]; then
  echo "error: missing ${reasons[*]}. Install the system packages with:" >&2
  echo "  sudo sh -c '$cmd'" >&2
  exit 1
fi
echo "installing system packages (missing ${reasons[*]}): ${packages[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
