"""pymodbus reads the simulated Watlow F4T's temperature and writes its set point.

Usage: check_f4t_pymodbus.py HOST PORT
Registers and encoding as in docs/protocols.md: float32 in two holding
registers, low word first; PV at 2820, set point at 2782.
"""
import struct
import sys

from pymodbus.client import ModbusTcpClient

PV, SET_POINT, CONTROL_MODE = 2820, 2782, 2730


def to_float(regs):
    return struct.unpack("<f", struct.pack("<HH", regs[0], regs[1]))[0]


def to_regs(value):
    return list(struct.unpack("<HH", struct.pack("<f", value)))


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    client = ModbusTcpClient(host, port=port, timeout=3)
    assert client.connect(), "cannot connect to the simulated F4T"
    counts = {"passed": 0, "failed": 0}

    def check(name, ok, detail=""):
        print(("ok   " if ok else "FAIL ") + name + (f": {detail}" if detail else ""))
        counts["passed" if ok else "failed"] += 1

    rr = client.read_holding_registers(PV, count=2, device_id=1)
    check("read PV", not rr.isError(), str(rr))
    pv = to_float(rr.registers)
    check("PV is the +20 degC the chamber starts at", abs(pv - 20.0) < 0.5, f"{pv}")

    wr = client.write_registers(SET_POINT, to_regs(-35.5), device_id=1)
    check("write set point", not wr.isError(), str(wr))
    rr = client.read_holding_registers(SET_POINT, count=2, device_id=1)
    sp = to_float(rr.registers)
    check("set point reads back", sp == -35.5, f"{sp}")

    rr = client.read_holding_registers(CONTROL_MODE, count=1, device_id=1)
    check("control mode is auto (10)", rr.registers == [10], str(rr.registers))

    rr = client.read_holding_registers(1000, count=2, device_id=1)
    check("unknown register gives an exception", rr.isError(), str(rr))
    wr = client.write_registers(SET_POINT, to_regs(900.0), device_id=1)
    check("set point beyond the chamber gives an exception", wr.isError(), str(wr))

    client.write_registers(SET_POINT, to_regs(20.0), device_id=1)
    client.close()
    print(f"{counts['passed']} passed, {counts['failed']} failed")
    return 1 if counts["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
