"""PyVISA (pure-Python backend, pyvisa-py) drives the simulated supply.

Usage: check_supply_pyvisa.py DIALECT HOST PORT [PTY]

DIALECT is keysight-e36300 or rigol-dp800. Over the raw socket
(TCPIP::HOST::PORT::SOCKET) it powers the unit on channel 2, reads the
steady draw, checks the error queue's numbers for bad commands and
out-of-range values, trips the over-current protection, clears it and
switches off. Over PTY (ASRL<path>::INSTR, the serial path) it asks the
identity and a measurement. Channel-named queries: `MEAS:VOLT? (@2)`,
`(@1:3)`, `OUTP? (@1,2)` on the Keysight, `MEAS:VOLT? CH2`, `OUTP? CH2`
on the Rigol.
"""
import sys
import time

import pyvisa

failed = 0
passed = 0


def check(name, ok, detail=""):
    global failed, passed
    print(("ok   " if ok else "FAIL ") + name + (f": {detail}" if detail else ""))
    if ok:
        passed += 1
    else:
        failed += 1


def until(inst, query, done, timeout_s=3.0):
    """Ask `query` until `done(answer)` holds; the last answer."""
    end = time.monotonic() + timeout_s
    while True:
        a = inst.query(query).strip()
        if done(a) or time.monotonic() > end:
            return a
        time.sleep(0.02)


def errors(inst):
    """Empty the error queue; its entries, oldest first."""
    out = []
    for _ in range(30):
        e = inst.query("SYST:ERR?").strip()
        code = int(e.split(",", 1)[0])
        if code == 0:
            return out
        out.append(e)
    return out


def socket_session(dialect, host, port):
    rm = pyvisa.ResourceManager("@py")
    inst = rm.open_resource(
        f"TCPIP::{host}::{port}::SOCKET", read_termination="\n", write_termination="\n"
    )
    inst.timeout = 2000
    keysight = dialect == "keysight-e36300"
    model = "E36312A" if keysight else "DP832"
    idn = inst.query("*IDN?").strip()
    check("*IDN? names the model", idn.split(",")[1].startswith(model), idn)

    inst.write("*RST")
    inst.write("*CLS")
    limit = 1.0 if keysight else 1.5
    inst.write("INSTrument:NSELect 2")
    inst.write("SOURce:VOLTage:LEVel:IMMediate:AMPLitude 15")
    inst.write(f"CURR {limit}")
    if not keysight:
        inst.write(f"CURR:PROT {limit}")
    inst.write("CURR:PROT:STAT ON")
    inst.write("OUTP ON")
    check("settings leave no error", errors(inst) == [])
    check("INST:NSEL? is 2", inst.query("INST:NSEL?").strip() == "2")
    v = inst.query("VOLT?").strip()
    want = "+1.50000000E+01" if keysight else "15.0000"
    check("VOLT? in the maker's number form", v == want, v)
    a = until(inst, "MEAS:CURR?", lambda a: abs(float(a) - 0.55) < 0.001)
    check("the unit draws its steady current", abs(float(a) - 0.55) < 0.001, a)
    v = float(inst.query("MEAS:VOLT?"))
    check("the output holds 15 V", abs(v - 15.0) < 0.01, str(v))
    on = inst.query("OUTP?").strip()
    check("OUTP? says on", on == ("1" if keysight else "ON"), on)

    # A channel named in the command itself: the E36300's channel list,
    # the DP832's CH<n> argument.
    inst.write("INST:NSEL 1")
    if keysight:
        v = inst.query("MEAS:VOLT? (@2)").strip()
        check("MEAS:VOLT? (@2) answers channel 2", abs(float(v) - 15.0) < 0.01, v)
        vs = inst.query("MEAS:VOLT? (@1:3)").strip().split(",")
        check(
            "MEAS:VOLT? (@1:3) answers each channel in order",
            len(vs) == 3 and abs(float(vs[1]) - 15.0) < 0.01 and float(vs[0]) == 0.0,
            str(vs),
        )
        o = inst.query("OUTP? (@1,2)").strip()
        check("OUTP? (@1,2) is 0,1", o == "0,1", o)
    else:
        v = inst.query("MEAS:VOLT? CH2").strip()
        check("MEAS:VOLT? CH2 answers channel 2", abs(float(v) - 15.0) < 0.01, v)
        o = inst.query("OUTP? CH2").strip()
        check("OUTP? CH2 is ON", o == "ON", o)
    check("channel-named queries leave no error", errors(inst) == [])
    check("... and the selection as it was", inst.query("INST:NSEL?").strip() == "1")
    inst.write("INST:NSEL 2")

    inst.write("VOLT:FOO 3")
    inst.write("VOLT 99")
    inst.write("OUTP MAYBE")
    inst.write("CURR")
    got = [e.split(",", 1)[0] for e in errors(inst)]
    check(
        "bad commands queue -113, -222, -224, -109 in order",
        got == ["-113", "-222", "-224", "-109"],
        str(got),
    )
    check("the setting refused kept the old one", float(inst.query("VOLT?")) == 15.0)

    # SCPI's path rule: after `;` a header continues from the branch before.
    inst.write(f"SOUR:VOLT 15;CURR {limit}")
    check("SOUR:VOLT 15;CURR ... sets SOUR:CURR", errors(inst) == [])
    inst.write("INST:NSEL 2;VOLT 16")
    got = [e.split(",", 1)[0] for e in errors(inst)]
    check("INST:NSEL 2;VOLT 16 is INST:VOLT, -113", got == ["-113"], str(got))
    check("... and left the voltage alone", float(inst.query("VOLT?")) == 15.0)

    inst.write("CURR 0.5")
    if not keysight:
        inst.write("CURR:PROT 0.5")
    t = until(inst, "CURR:PROT:TRIP?", lambda a: a in ("1", "YES"))
    check("a limit under the draw trips the protection", t in ("1", "YES"), t)
    off = inst.query("OUTP?").strip()
    check("the tripped output is off", off in ("0", "OFF"), off)
    a = float(inst.query("MEAS:CURR?"))
    check("no current after the trip", a == 0.0, str(a))
    inst.write("OUTP ON")
    got = [e.split(",", 1)[0] for e in errors(inst)]
    check("switching a tripped output on is -221", got == ["-221"], str(got))
    inst.write(f"CURR {limit}")
    if not keysight:
        inst.write(f"CURR:PROT {limit}")
    inst.write("OUTP:PROT:CLE" if keysight else "CURR:PROT:CLE")
    inst.write("OUTP ON")
    check("cleared and on again without error", errors(inst) == [])
    a = until(inst, "MEAS:CURR?", lambda a: abs(float(a) - 0.55) < 0.001)
    check("the unit draws again", abs(float(a) - 0.55) < 0.001, a)
    inst.write("OUTP OFF")
    v = until(inst, "MEAS:VOLT?", lambda a: float(a) == 0.0)
    check("off: the output falls to 0 V", float(v) == 0.0, v)
    inst.close()


def serial_session(dialect, path):
    rm = pyvisa.ResourceManager("@py")
    inst = rm.open_resource(f"ASRL{path}::INSTR", read_termination="\n", write_termination="\n")
    inst.timeout = 2000
    idn = inst.query("*IDN?").strip()
    model = "E36312A" if dialect == "keysight-e36300" else "DP832"
    check("over serial: *IDN? names the model", model in idn, idn)
    inst.write("SYST:REM")
    v = inst.query("INST:NSEL 2;:MEAS:VOLT?").strip()
    check("over serial: MEAS:VOLT? answers a number", float(v) >= 0.0, v)
    inst.close()


def main():
    dialect, host, port = sys.argv[1], sys.argv[2], int(sys.argv[3])
    socket_session(dialect, host, port)
    if len(sys.argv) > 4:
        serial_session(dialect, sys.argv[4])
    print(f"{dialect}: {passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
