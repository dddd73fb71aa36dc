#!/usr/bin/env bash
# Third-party conformance: start `gyrobench sim serve`, point pymodbus, two
# independent Espec clients and PyVISA (the supply, over its socket and a
# pty) at it, stop it with SIGTERM (must exit 0); then PyVISA again against
# a second `sim serve` whose supply speaks the Rigol DP800's commands.
# Usage: tests/conformance/run.sh PATH/TO/gyrobench PATH/TO/python
set -euo pipefail
bin=$1
py=$2
here=$(cd "$(dirname "$0")" && pwd)
out=$(mktemp)
"$bin" sim serve >"$out" 2>/dev/null &
pid=$!
trap 'kill "$pid" 2>/dev/null || true; rm -f "$out"' EXIT
for _ in $(seq 1 100); do
  [ "$(wc -l <"$out")" -ge 9 ] && break
  sleep 0.1
done
echo "sim serve endpoints:"
sed 's/^/  /' "$out"
grep -Eq '^chamber espec-ascii tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^chamber watlow-f4t-modbus tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^table acl tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^gyro rlg-frame pty:///dev/' "$out"
grep -Eq '^supply keysight-e36300 tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^supply keysight-e36300 pty:///dev/' "$out"
addr() { grep "^$1 $2 tcp://" "$out" | sed 's#.*tcp://##'; }
pty() { grep "^$1 $2 pty://" "$out" | sed 's#.*pty://##'; }
espec=$(addr chamber espec-ascii)
watlow=$(addr chamber watlow-f4t-modbus)
"$py" "$here/check_f4t_pymodbus.py" "${watlow%:*}" "${watlow##*:}"
"$py" "$here/check_espec_clients.py" "${espec%:*}" "${espec##*:}"
supply=$(addr supply keysight-e36300)
"$py" "$here/check_supply_pyvisa.py" keysight-e36300 "${supply%:*}" "${supply##*:}" "$(pty supply keysight-e36300)"
kill -TERM "$pid"
wait "$pid"
echo "sim serve stopped on SIGTERM with exit 0"

config=$(mktemp --suffix=.toml)
echo 'supply = "rigol-dp800"' >"$config"
: >"$out"
"$bin" sim serve --config "$config" >"$out" 2>/dev/null &
pid=$!
trap 'kill "$pid" 2>/dev/null || true; rm -f "$out" "$config"' EXIT
for _ in $(seq 1 100); do
  [ "$(wc -l <"$out")" -ge 9 ] && break
  sleep 0.1
done
supply=$(addr supply rigol-dp800)
"$py" "$here/check_supply_pyvisa.py" rigol-dp800 "${supply%:*}" "${supply##*:}" "$(pty supply rigol-dp800)"
kill -TERM "$pid"
wait "$pid"
trap - EXIT
rm -f "$out" "$config"
