"""The shipped LEAP API's way of driving the hand, for bench_leap.rs: ROBOTIS's Python SDK
(PyPI `dynamixel-sdk` 4.1.0) on the bus at 4 Mbit/s, as LEAP_Hand_API's `main.py` does it
(see docs/devices/leap.md, "The shipped API"):

- bring-up: Operating Mode 5 by Sync Write, Torque Enable per servo, Position P/I/D 600/0/200
  (the side joints 0, 4, 8 at 0.75) and Goal Current 350 mA by Sync Write, goals at the flat pose;
- then a loop without sleep: `write_desired_pos` (one GroupSyncWrite of Goal Position for the
  16 servos) and `read_pos_vel_cur` (one `GroupSyncRead(126, 10).fastSyncRead()`, current,
  velocity and position taken out and sign-extended; a failed read tried once more, as the
  API's `read(retries=1)` does);
- torque off per servo at the end, as the API's `disconnect`.

Usage: python3 bench_leap_sdk.py PORT WARM_UP_S SECONDS
Prints `window FROM_NS TO_NS loops N failed_reads F` (CLOCK_MONOTONIC, the loops after the
warm-up); exits 1 when the bus cannot be opened.
"""

import sys
import time

import dynamixel_sdk as sdk

IDS = list(range(16))
SIDE = (0, 4, 8)
BAUD = 4_000_000
OPERATING_MODE, TORQUE_ENABLE = 11, 64
POSITION_D, POSITION_I, POSITION_P = 80, 82, 84
GOAL_CURRENT, GOAL_POSITION = 102, 116
PRESENT_CURRENT, PRESENT_VELOCITY, PRESENT_POSITION = 126, 128, 132
KP, KI, KD, CURRENT_MA = 600, 0, 200, 350
# The API's flat pose: pi rad, int(pi / (2 pi / 4096)) counts.
FLAT = 2047


def signed(value, bits):
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def sync_write(port, packets, addr, size, values):
    group = sdk.GroupSyncWrite(port, packets, addr, size)
    for i, value in zip(IDS, values):
        group.addParam(i, list((value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")))
    group.txPacket()
    group.clearParam()


def main(path, warm_up, seconds):
    port = sdk.PortHandler(path)
    packets = sdk.PacketHandler(2.0)
    if not (port.openPort() and port.setBaudRate(BAUD)):
        print("cannot open %s at %d" % (path, BAUD))
        sys.exit(1)

    sync_write(port, packets, OPERATING_MODE, 1, [5] * 16)
    for i in IDS:
        while packets.write1ByteTxRx(port, i, TORQUE_ENABLE, 1)[0] != sdk.COMM_SUCCESS:
            time.sleep(0.25)
    side = lambda full: [int(full * 0.75) if i in SIDE else full for i in IDS]
    sync_write(port, packets, POSITION_P, 2, side(KP))
    sync_write(port, packets, POSITION_I, 2, [KI] * 16)
    sync_write(port, packets, POSITION_D, 2, side(KD))
    sync_write(port, packets, GOAL_CURRENT, 2, [CURRENT_MA] * 16)

    writer = sdk.GroupSyncWrite(port, packets, GOAL_POSITION, 4)
    reader = sdk.GroupSyncRead(port, packets, PRESENT_CURRENT, 10)
    for i in IDS:
        reader.addParam(i)
    goals = [FLAT] * 16
    state = ([0] * 16, [0] * 16, [0] * 16)
    loops = failed = 0
    start = time.monotonic_ns()
    warm_until = start + int(warm_up * 1e9)
    end = warm_until + int(seconds * 1e9)
    window = None
    now = start
    while now < end:
        # write_desired_pos
        for i, goal in zip(IDS, goals):
            writer.addParam(i, list(goal.to_bytes(4, "little")))
        writer.txPacket()
        writer.clearParam()
        # read_pos_vel_cur
        for _ in range(2):
            if reader.fastSyncRead() == sdk.COMM_SUCCESS:
                state = (
                    [signed(reader.getData(i, PRESENT_CURRENT, 2), 16) for i in IDS],
                    [signed(reader.getData(i, PRESENT_VELOCITY, 4), 32) for i in IDS],
                    [signed(reader.getData(i, PRESENT_POSITION, 4), 32) for i in IDS],
                )
                break
            if window is not None:
                failed += 1
        now = time.monotonic_ns()
        if window is None and now >= warm_until:
            window = now
        elif window is not None:
            loops += 1

    for i in IDS:
        packets.write1ByteTxRx(port, i, TORQUE_ENABLE, 0)
    port.closePort()
    print(
        "window %d %d loops %d failed_reads %d (last positions %d..%d)"
        % (window, now, loops, failed, min(state[2]), max(state[2]))
    )


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), float(sys.argv[3]))
