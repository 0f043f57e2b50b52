#!/usr/bin/env bash
# Installs the Debian packages raysim needs beyond Python: EGL with Mesa for headless
# rendering (pyvista/VTK off-screen) and Debian's chromium for the browser tests of the HTML
# pages. Does nothing when they are present already.
set -euo pipefail
# chromium: the headless browser the tests open the HTML pages in (report, check, the site)
packages=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libxrender1 chromium)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "raysim: no apt-get here; install EGL/Mesa (${missing[*]}) by hand for headless rendering" >&2
    exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "raysim: installing ${missing[*]} with apt-get"
$sudo apt-get update -q
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
