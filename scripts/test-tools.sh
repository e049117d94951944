#!/usr/bin/env bash
# The external tools the test suite talks to (real receivers, not mocks).
# Installs the missing ones when run as root on Debian/Ubuntu; otherwise says
# what to install and fails: the suite never skips a test for a missing tool.
set -euo pipefail

# tool  debian-package
tools=(
  "oscdump liblo-tools"
  "oscsend liblo-tools"
  "pd puredata-core"
  "sclang supercollider-language"
  "jackd jackd2"
  "ip iproute2"
  "sysctl procps"
  "openssl openssl"
  "chromium chromium"
  "chromedriver chromium-driver"
  "systemd-analyze systemd"
  "node nodejs"
  "npm npm"
  "dot graphviz"
)

# the official Foxglove client (tests/foxglove/test_official_client.py), from the npm registry
install_js() {
  local dir="$(dirname "$0")/../tests/foxglove/js"
  [ -d "$dir/node_modules/@foxglove/ws-protocol" ] || npm ci --prefix "$dir" --no-audit --no-fund --loglevel=error
}

missing=()
for entry in "${tools[@]}"; do
  read -r tool package <<<"$entry"
  command -v "$tool" >/dev/null 2>&1 || missing+=("$package")
done
if [ ${#missing[@]} -eq 0 ]; then install_js; exit 0; fi
mapfile -t missing < <(printf '%s\n' "${missing[@]}" | sort -u)

if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing test tools: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "the tests need: ${missing[*]} — install with: sudo apt-get install ${missing[*]}" >&2
  exit 1
fi
install_js
