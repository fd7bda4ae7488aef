#!/usr/bin/env bash
# A real browser for the test of `python -m continuum_statics view`: Debian's
# chromium-headless-shell (renders WebGL with SwiftShader). Installed with apt-get when missing
# and possible (root); otherwise the browser test says why it cannot run (and fails under CI=true).
set -u
command -v chromium-headless-shell >/dev/null 2>&1 && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium-headless-shell >/dev/null 2>&1 \
    || { apt-get update -q >/dev/null 2>&1 && \
         DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium-headless-shell >/dev/null 2>&1; } \
    || echo "install_browser: apt-get install chromium-headless-shell failed" >&2
else
  echo "install_browser: chromium-headless-shell missing (apt-get install chromium-headless-shell as root)" >&2
fi
exit 0
