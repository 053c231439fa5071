#!/usr/bin/env bash
# System packages some tests need: chromium (the HTML reports rendered in a real browser, layout checked)
# and mosquitto (the MQTT broker the edge-service tests start on a loopback port).
# As root with apt-get (CI, a fresh VM), installs what is missing; otherwise says which tests will skip.
set -euo pipefail
missing=()
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
[[ -x /usr/sbin/mosquitto ]] || command -v mosquitto >/dev/null 2>&1 || missing+=(mosquitto)
[[ ${#missing[@]} -eq 0 ]] && exit 0
if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null 2>&1; then
  echo "installing system packages for the tests: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "note: ${missing[*]} not installed: the browser / MQTT tests will be skipped" \
       "(install with: sudo apt-get install ${missing[*]})" >&2
fi
