# The project's own Python base image (carlos.local/python:3.11-<suite>-<date>), for when no registry is
# reachable: Debian's python3 (3.11 in bookworm) and python3-venv on the minimal Debian root filesystem that
# tools/images/build makes with debootstrap and `docker import`s (DEBIAN_IMAGE), plus the libraries SUMO and
# open3d load (images/system-packages.sh, the same list the images check). images/*/Dockerfile take it as
# their PYTHON_IMAGE build argument in place of python:3.11.x-slim-bookworm. Built from the repository root:
#   docker build -f tools/images/python.Dockerfile --build-arg DEBIAN_IMAGE=carlos.local/debian:bookworm-… .
ARG DEBIAN_IMAGE
FROM ${DEBIAN_IMAGE}
RUN --mount=type=bind,source=images/system-packages.sh,target=/tmp/system-packages.sh \
    sh /tmp/system-packages.sh python3 python3-venv ca-certificates
ENV LANG=C.UTF-8
CMD ["python3"]
