"""The independent check of the simulated LEAP Hand: ROBOTIS's own Python SDK (PyPI
`dynamixel-sdk` 4.1.0) on the simulator's pty at 4 Mbit/s. Run by dynamixel_sdk.rs as
`python3 dynamixel_sdk_check.py PORT`; prints one line per check and exits 1 at the first failure.

- every servo (IDs 0..15) answers Ping with model number 1240 (XC330-M288-T);
- goal positions written by GroupSyncWrite read back by Read (read4ByteTxRx);
- present positions by GroupSyncRead, both txRxPacket (Sync Read) and fastSyncRead (Fast Sync
  Read), equal to the ones Read gives;
- with the torque on, a write to Operating Mode (EEPROM) is refused with Access Error (7);
  with it off, accepted.
"""

import sys

import dynamixel_sdk as sdk

IDS = range(16)
BAUD = 4_000_000
MODEL_XC330_M288 = 1240
GOAL_POSITION, PRESENT_POSITION = 116, 132
OPERATING_MODE, TORQUE_ENABLE = 11, 64
ACCESS_ERROR = 7


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what, flush=True)
    if not ok:
        sys.exit(1)


def main(path):
    port = sdk.PortHandler(path)
    packets = sdk.PacketHandler(2.0)
    check(port.openPort(), "open " + path)
    check(port.setBaudRate(BAUD), "baud rate %d" % BAUD)

    for i in IDS:
        model, result, error = packets.ping(port, i)
        check(
            result == sdk.COMM_SUCCESS and error == 0 and model == MODEL_XC330_M288,
            "ping %d: model %d (%s)" % (i, model, packets.getTxRxResult(result)),
        )

    writer = sdk.GroupSyncWrite(port, packets, GOAL_POSITION, 4)
    goals = {i: 1500 + 37 * i for i in IDS}
    for i, goal in goals.items():
        check(writer.addParam(i, list(goal.to_bytes(4, "little"))), "sync write param %d" % i)
    check(writer.txPacket() == sdk.COMM_SUCCESS, "GroupSyncWrite of 16 goal positions")
    for i, goal in goals.items():
        value, result, error = packets.read4ByteTxRx(port, i, GOAL_POSITION)
        check(
            result == sdk.COMM_SUCCESS and error == 0 and value == goals[i],
            "read back goal %d: %d (want %d)" % (i, value, goal),
        )

    present = {}
    for i in IDS:
        value, result, error = packets.read4ByteTxRx(port, i, PRESENT_POSITION)
        check(result == sdk.COMM_SUCCESS and error == 0, "read present position %d" % i)
        present[i] = value
    reader = sdk.GroupSyncRead(port, packets, PRESENT_POSITION, 4)
    for i in IDS:
        check(reader.addParam(i), "sync read param %d" % i)
    for name, call in (("txRxPacket", reader.txRxPacket), ("fastSyncRead", reader.fastSyncRead)):
        result = call()
        check(result == sdk.COMM_SUCCESS, "GroupSyncRead.%s: %s" % (name, packets.getTxRxResult(result)))
        got = {i: reader.getData(i, PRESENT_POSITION, 4) for i in IDS}
        check(
            all(reader.isAvailable(i, PRESENT_POSITION, 4) for i in IDS) and got == present,
            "GroupSyncRead.%s present positions %s" % (name, sorted(got.values())),
        )

    result, error = packets.write1ByteTxRx(port, 0, TORQUE_ENABLE, 1)
    check(result == sdk.COMM_SUCCESS and error == 0, "torque on (ID 0)")
    result, error = packets.write1ByteTxRx(port, 0, OPERATING_MODE, 5)
    check(
        result == sdk.COMM_SUCCESS and error == ACCESS_ERROR,
        "EEPROM write under torque refused: error %d (%s)" % (error, packets.getRxPacketError(error)),
    )
    result, error = packets.write1ByteTxRx(port, 0, TORQUE_ENABLE, 0)
    check(result == sdk.COMM_SUCCESS and error == 0, "torque off (ID 0)")
    result, error = packets.write1ByteTxRx(port, 0, OPERATING_MODE, 5)
    check(result == sdk.COMM_SUCCESS and error == 0, "EEPROM write with the torque off accepted")
    value, result, error = packets.read1ByteTxRx(port, 0, OPERATING_MODE)
    check(value == 5, "operating mode now %d" % value)
    port.closePort()


if __name__ == "__main__":
    main(sys.argv[1])
