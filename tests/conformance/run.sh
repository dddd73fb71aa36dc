#!/usr/bin/env bash
# Third-party conformance: start `gyrobench sim serve`, point pymodbus and two
# independent Espec clients at it, stop it with SIGTERM (must exit 0).
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
  [ "$(wc -l <"$out")" -ge 7 ] && break
  sleep 0.1
done
echo "sim serve endpoints:"
sed 's/^/  /' "$out"
grep -Eq '^chamber espec-ascii tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^chamber watlow-f4t-modbus tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^table acl tcp://127\.0\.0\.1:[0-9]+$' "$out"
grep -Eq '^gyro rlg-frame pty:///dev/' "$out"
addr() { grep "^$1 $2 tcp://" "$out" | sed 's#.*tcp://##'; }
espec=$(addr chamber espec-ascii)
watlow=$(addr chamber watlow-f4t-modbus)
"$py" "$here/check_f4t_pymodbus.py" "${watlow%:*}" "${watlow##*:}"
"$py" "$here/check_espec_clients.py" "${espec%:*}" "${espec##*:}"
kill -TERM "$pid"
wait "$pid"
echo "sim serve stopped on SIGTERM with exit 0"
trap - EXIT
rm -f "$out"
