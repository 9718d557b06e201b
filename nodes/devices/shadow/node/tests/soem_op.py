#!/usr/bin/env python3
"""An independent EtherCAT master (SOEM, through pysoem) brings the emulated Shadow Hand's two
SubDevices to OP and exchanges with the palm.

Usage: soem_op.py INTERFACE [CYCLES]

Opens INTERFACE (needs CAP_NET_RAW), scans the bus, checks for the bridge (product 0) then the
palm (product 6). The palm's SII announces no sync managers, so SOEM maps nothing: as the
shipped Shadow driver does, this script programs the palm's four one-buffer sync managers
(command 0x1000/58, bridge command 0x103A/12, status 0x1046/220, bridge status 0x1122/12) with
FPWR in PRE-OP, requests SAFE-OP and OP, then runs CYCLES (default 200) exchanges of a
SENSOR_DATA command (FPWR into the command buffer) and the palm's status (FPRD of the status
buffer), checking that the palm answers (EDC command 1, the requested data type, the motors
of the requested parity). Returns to INIT and prints OK; exits non-zero with a message on the
first thing that is wrong. Used by nodes/devices/shadow/node/tests/veth.rs.
"""

import struct
import sys
import time

import pysoem

PRODUCT_BRIDGE = 0
PRODUCT_PALM = 6
TIMEOUT_US = 2_000_000
SMS = [  # start, length, control
    (0x1000, 58, 0x26),
    (0x103A, 12, 0x26),
    (0x1046, 220, 0x02),
    (0x1122, 12, 0x02),
]
FLAGS = 4  # FROM_MOTOR: FLAGS


def fail(message):
    print(f"FAIL: {message}", flush=True)
    sys.exit(1)


def command(which):
    # EDC_command, from_motor_data_type, which_motors, to_motor_data_type, 20 demands, tactile.
    return struct.pack("<IIhI20hI", 1, FLAGS, which, 2, *([0] * 20), 1)


def wait_state(master, state, what):
    if master.state_check(state, TIMEOUT_US) != state:
        master.read_state()
        states = ", ".join(f"{s.name}: {s.state:#x} code {s.al_status:#06x}" for s in master.slaves)
        fail(f"not in {what}: {states}")


def main():
    if len(sys.argv) < 2:
        fail("usage: soem_op.py INTERFACE [CYCLES]")
    interface = sys.argv[1]
    cycles = int(sys.argv[2]) if len(sys.argv) > 2 else 200

    master = pysoem.Master()
    master.open(interface)
    try:
        found = master.config_init()
        if found != 2:
            fail(f"expected 2 SubDevices (bridge, palm) on {interface}, found {found}")
        bridge, palm = master.slaves
        for sd in master.slaves:
            print(f"found {sd.name!r} vendor {sd.man:#010x} product {sd.id:#x}", flush=True)
        if bridge.id != PRODUCT_BRIDGE or palm.id != PRODUCT_PALM:
            fail(f"not a Shadow Hand: products {bridge.id:#x}, {palm.id:#x}")
        wait_state(master, pysoem.PREOP_STATE, "PRE-OP")

        # Without the palm's sync managers, SAFE-OP is refused (0x0017).
        master.config_map()
        master.state = pysoem.SAFEOP_STATE
        master.write_state()
        time.sleep(0.05)
        master.read_state()
        print(f"SAFE-OP without sync managers: palm state {palm.state:#x} "
              f"code {palm.al_status:#06x}", flush=True)
        if palm.al_status != 0x0017:
            fail(f"the palm did not refuse SAFE-OP with 0x0017: {palm.al_status:#06x}")
        # Acknowledge the error, back in PRE-OP. The firmware reads AL control once per loop:
        # wait until it has taken the acknowledge before asking for anything else.
        palm.state = pysoem.PREOP_STATE | 0x10
        palm.write_state()
        deadline = time.monotonic() + TIMEOUT_US / 1e6
        while True:
            master.read_state()
            if palm.state == pysoem.PREOP_STATE:
                break
            if time.monotonic() > deadline:
                fail(f"the error was not acknowledged: state {palm.state:#x} "
                     f"code {palm.al_status:#06x}")
            time.sleep(0.002)

        for n, (start, length, control) in enumerate(SMS):
            palm._fpwr(0x0806 + 8 * n, bytes([0]))  # disabled while programmed
            palm._fpwr(0x0800 + 8 * n, struct.pack("<HHBBBB", start, length, control, 0, 1, 0))
        master.state = pysoem.SAFEOP_STATE
        master.write_state()
        wait_state(master, pysoem.SAFEOP_STATE, "SAFE-OP")
        master.state = pysoem.OP_STATE
        master.write_state()
        wait_state(master, pysoem.OP_STATE, "OP")
        print("both in OP", flush=True)

        answered = 0
        for k in range(cycles):
            which = k % 2
            palm._fpwr(0x1000, command(which))
            time.sleep(0.001)
            try:
                status = palm._fprd(0x1046, 220)
            except Exception:  # not refilled yet: an empty buffer does not answer
                continue
            edc, data_type, parity = struct.unpack_from("<I", status, 0)[0], \
                struct.unpack_from("<I", status, 78)[0], struct.unpack_from("<h", status, 82)[0]
            arrived = struct.unpack_from("<I", status, 84)[0]
            expected = 0xAAAAA if parity else 0x55555
            if edc == 1 and data_type == FLAGS and arrived == expected:
                answered += 1
        master.read_state()
        print(f"{answered}/{cycles} statuses answered; palm state {palm.state:#x}", flush=True)
        if answered < cycles * 0.8:
            fail(f"only {answered} of {cycles} commands were answered")

        master.state = pysoem.INIT_STATE
        master.write_state()
        master.state_check(pysoem.INIT_STATE, TIMEOUT_US)
        print("OK", flush=True)
    finally:
        master.close()


if __name__ == "__main__":
    main()
