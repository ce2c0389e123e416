#!/bin/sh
# What every CARLOS image needs from Debian/Ubuntu, installed only when missing (on the project's own base
# image, tools/images/python.Dockerfile, everything is there and this installs nothing):
# - the libraries SUMO and open3d load (the Makefile's SYSTEM_PACKAGES, plus libatomic1 and libudev1 that a
#   desktop system has anyway), in every image: the images share one dependency layer that holds both;
# - python3-venv when python3 cannot create a virtual environment (Debian's and Ubuntu's python3 without it;
#   the official python images have ensurepip built in);
# - the packages named as arguments.
# Used by images/*/Dockerfile (RUN --mount=type=bind,source=images/system-packages.sh,…) and the base image.
set -eu
LIBS="libusb-1.0-0 libgl1 libegl1 libx11-6 libxext6 libxrender1 libatomic1 libudev1"
missing=""
for package in $LIBS "$@"; do
  dpkg-query -W -f='${Status}\n' "$package" 2>/dev/null | grep -q '^install ok installed$' \
    || missing="$missing $package"
done
if command -v python3 >/dev/null && ! python3 -c 'import ensurepip' 2>/dev/null; then
  missing="$missing python3-venv"
fi
[ -n "$missing" ] || exit 0
echo "system-packages: installing$missing"
apt-get update -qq
# shellcheck disable=SC2086
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing
apt-get clean
rm -rf /var/lib/apt/lists/* /var/cache/apt/*.bin /var/log/apt /var/log/dpkg.log /var/cache/ldconfig/aux-cache
