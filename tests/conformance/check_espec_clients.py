"""Independent Espec ASCII clients read and drive the simulated chamber.

Usage: check_espec_clients.py HOST PORT

1. espec-pr3j (pyvisa-py, TCP socket): written for the PR-3J, it expects
   non-negative temperatures and a humidity field, so it is used for what
   it covers: TEMP?, set point, MODE? and MODE set, alarm limits.
2. A plain socket client speaking only the commands of docs/protocols.md:
   MON? without humidity, negative set points, ALARM?, refusals.
"""
import re
import socket
import sys

import pyvisa
from espec_pr3j import EspecPr3j
from espec_pr3j.data_classes import OperationMode

failed = 0
passed = 0


def check(name, ok, detail=""):
    global failed, passed
    print(("ok   " if ok else "FAIL ") + name + (f": {detail}" if detail else ""))
    if ok:
        passed += 1
    else:
        failed += 1


def with_espec_pr3j(host, port):
    rm = pyvisa.ResourceManager("@py")
    c = EspecPr3j(resource_path=f"TCPIP0::{host}::{port}::SOCKET", resource_manager=rm)
    # Its TEMP? pattern is unsigned: set non-negative alarm limits first.
    c.set_temperature_limits(90.0, 5.0)
    t = c.get_temperature_status()
    check("espec-pr3j sets alarm limits", (t.upper_limit, t.lower_limit) == (90.0, 5.0), str(t))
    check("espec-pr3j reads TEMP?", abs(t.current_temperature - 20.0) < 0.5, str(t))
    c.set_target_temperature(25.0)
    t = c.get_temperature_status()
    check("espec-pr3j set point reads back", t.target_temperature == 25.0, str(t))
    check("espec-pr3j reads MODE?", c.get_mode() == OperationMode.CONSTANT)
    c.set_mode(OperationMode.STANDBY)
    check("espec-pr3j sets MODE", c.get_mode() == OperationMode.STANDBY)
    c.set_mode(OperationMode.CONSTANT)
    c.close()


def with_plain_socket(host, port):
    s = socket.create_connection((host, port), timeout=3)
    f = s.makefile("rwb")

    def ask(line):
        f.write(line.encode() + b"\r\n")
        f.flush()
        reply = f.readline()
        check(f"{line!r} reply ends in CR LF", reply.endswith(b"\r\n"), repr(reply))
        return reply.decode().strip()

    num = r"-?\d+\.\d"
    check("TEMP? = pv,sp,upper,lower", re.fullmatch(f"{num},{num},{num},{num}", ask("TEMP?")) is not None)
    check("MON? = temp,,mode,alarms", re.fullmatch(f"{num},,(OFF|STANDBY|CONSTANT|RUN),\\d+", ask("MON?")) is not None)
    check("negative set point accepted", ask("TEMP, S-40.0") == "OK:TEMP, S-40.0")
    check("set point reads back", ask("TEMP?").split(",")[1] == "-40.0")
    check("ALARM? = count[,codes]", re.fullmatch(r"\d+(,\d+)*", ask("ALARM?")) is not None)
    check("set point beyond range refused", ask("TEMP, S500.0") == "NA:DATA OUT OF RANGE")
    check("unknown command refused", ask("FOO?") == "NA:CMD ERR")
    check("RS-485 address prefix accepted", ask("1,MODE?") in ("CONSTANT", "STANDBY", "OFF"))
    ask("TEMP, S20.0")
    s.close()


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    with_espec_pr3j(host, port)
    with_plain_socket(host, port)
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
