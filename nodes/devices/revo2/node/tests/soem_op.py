#!/usr/bin/env python3
"""An independent EtherCAT master (SOEM, through pysoem) brings the emulated Revo2 to OP.

Usage: soem_op.py INTERFACE [CYCLES]

Opens INTERFACE (needs CAP_NET_RAW), scans the bus, checks that the first SubDevice is a Revo2
(vendor 0x00BC0000, product 0x00009252), maps the process data, requests OP, exchanges CYCLES
(default 200) process-data cycles checking the working counter, returns to INIT and prints OK.
Exits non-zero with a message on the first thing that is wrong. Used by nodes/devices/revo2/node/tests/veth.rs.
"""

import sys
import time

import pysoem

VENDOR_ID = 0x00BC0000
PRODUCT_CODE = 0x00009252
TIMEOUT_US = 2_000_000  # state changes
RECV_TIMEOUT_US = 20_000  # one process-data cycle


def fail(message):
    print(f"FAIL: {message}", flush=True)
    sys.exit(1)


def main():
    if len(sys.argv) < 2:
        fail("usage: soem_op.py INTERFACE [CYCLES]")
    interface = sys.argv[1]
    cycles = int(sys.argv[2]) if len(sys.argv) > 2 else 200

    master = pysoem.Master()
    master.open(interface)
    try:
        found = master.config_init()
        if found < 1:
            fail(f"no SubDevice found on {interface}")
        sd = master.slaves[0]
        print(f"found {found} SubDevice(s); first: {sd.name!r} vendor {sd.man:#010x} "
              f"product {sd.id:#010x} revision {sd.rev:#x}", flush=True)
        if sd.man != VENDOR_ID or sd.id != PRODUCT_CODE:
            fail(f"not a Revo2: vendor {sd.man:#010x} product {sd.id:#010x}")
        # config_init requests PRE-OP without waiting; a firmware takes its next loop to enter
        # it (and to open its mailbox).
        if master.state_check(pysoem.PREOP_STATE, TIMEOUT_US) != pysoem.PREOP_STATE:
            master.read_state()
            fail(f"not in PRE-OP: state {sd.state:#x}, AL status code {sd.al_status:#06x}")
        # The identity object over CoE as well (SDO upload through the mailbox).
        vendor_sdo = int.from_bytes(sd.sdo_read(0x1018, 1), "little")
        if vendor_sdo != VENDOR_ID:
            fail(f"0x1018:01 reads {vendor_sdo:#010x}")

        io_size = master.config_map()
        print(f"process image {io_size} bytes: {len(sd.output)} out, {len(sd.input)} in; "
              f"expected WKC {master.expected_wkc}", flush=True)
        if master.state_check(pysoem.SAFEOP_STATE, TIMEOUT_US) != pysoem.SAFEOP_STATE:
            master.read_state()
            fail(f"not in SAFE-OP: state {sd.state:#x}, AL status code {sd.al_status:#06x}")

        # Outputs must be valid before OP: send a few cycles, then request OP.
        for _ in range(3):
            master.send_processdata()
            master.receive_processdata(RECV_TIMEOUT_US)
        master.state = pysoem.OP_STATE
        master.write_state()
        deadline = time.monotonic() + TIMEOUT_US / 1e6
        while True:
            master.send_processdata()
            master.receive_processdata(RECV_TIMEOUT_US)
            if master.state_check(pysoem.OP_STATE, 5_000) == pysoem.OP_STATE:
                break
            if time.monotonic() > deadline:
                master.read_state()
                fail(f"not in OP: state {sd.state:#x}, AL status code {sd.al_status:#06x}")
        print("in OP", flush=True)

        good = 0
        for _ in range(cycles):
            master.send_processdata()
            wkc = master.receive_processdata(RECV_TIMEOUT_US)
            if wkc == master.expected_wkc:
                good += 1
            time.sleep(0.001)
        master.read_state()
        print(f"{good}/{cycles} cycles with WKC {master.expected_wkc}; state {sd.state:#x}",
              flush=True)
        if good < cycles * 0.95:
            fail(f"only {good} of {cycles} cycles had the expected working counter")
        if sd.state != pysoem.OP_STATE:
            fail(f"left OP during the exchange: state {sd.state:#x}, "
                 f"AL status code {sd.al_status:#06x}")

        master.state = pysoem.INIT_STATE
        master.write_state()
        master.state_check(pysoem.INIT_STATE, TIMEOUT_US)
        print("OK", flush=True)
    finally:
        master.close()


if __name__ == "__main__":
    main()
