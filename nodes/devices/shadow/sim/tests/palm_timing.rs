//! The palm's firmware timing as the 2011 palm firmware has it (shadow-robot/
//! sr-ros-interface-ethercat at f478de52, `sr_external_dependencies/hosted/external/
//! 0220_palm_edc/this_node.c`, `Service_EtherCAT_Packet`): the command is read out of its sync
//! manager right after the SM0 event, before the CAN round, so a command the MainDevice writes
//! during the round is taken, not refused; `idle_time_us` is the time from the last status
//! write to the next command. Driven frame by frame on the palm's SubDevice with explicit
//! times, as a MainDevice programs it (SMs, FMMUs, INIT -> OP).
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_ecat_sim::registers as reg;
use teleop_shadow_protocol::data::{FromMotor, ToMotor};
use teleop_shadow_protocol::layout::{CanBridge, Command, Protocol, Status};
use teleop_sim_shadow::ethercat::{palm_sync_managers, ShadowBus, PROCESS_TIME};
use teleop_sim_shadow::palm::Palm;

const STATION: u16 = 0x1002;
const APWR: u8 = 0x02;
const FPRD: u8 = 0x04;
const FPWR: u8 = 0x05;
const LRW: u8 = 0x0C;
const LOGICAL: u32 = 0x0001_0000;
const OUT_LEN: usize = Command::SIZE + CanBridge::SIZE;
const IN_LEN: usize = Status::SIZE + CanBridge::SIZE;

fn frame(cmd: u8, address: u32, data: &[u8]) -> Vec<u8> {
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&[0x10; 6]);
    f.extend_from_slice(&[0x88, 0xA4]);
    let len = 10 + data.len() + 2;
    f.extend_from_slice(&(len as u16 | 0x1000).to_le_bytes());
    f.push(cmd);
    f.push(0);
    f.extend_from_slice(&address.to_le_bytes());
    f.extend_from_slice(&(data.len() as u16).to_le_bytes());
    f.extend_from_slice(&[0, 0]);
    f.extend_from_slice(data);
    f.extend_from_slice(&[0, 0]);
    f
}

/// The palm SubDevice of an emulated hand, in OP, with its clock.
struct Rig {
    bus: ShadowBus,
    now: Duration,
}

impl Rig {
    fn one(&mut self, cmd: u8, address: u32, data: &[u8]) -> (Vec<u8>, u16) {
        let reply = self
            .bus
            .palm
            .process_frame(&frame(cmd, address, data), self.now)
            .expect("a reply");
        let n = data.len();
        let wkc = u16::from_le_bytes([reply[26 + n], reply[27 + n]]);
        (reply[26..26 + n].to_vec(), wkc)
    }

    fn fpwr(&mut self, register: u16, data: &[u8]) {
        let address = u32::from(STATION) | u32::from(register) << 16;
        assert_eq!(self.one(FPWR, address, data).1, 1, "FPWR {register:#06x}");
    }

    fn al_status(&mut self) -> u16 {
        let address = u32::from(STATION) | u32::from(reg::AL_STATUS) << 16;
        let (d, wkc) = self.one(FPRD, address, &[0, 0]);
        assert_eq!(wkc, 1);
        u16::from_le_bytes([d[0], d[1]])
    }

    fn request(&mut self, state: u16) {
        self.fpwr(reg::AL_CONTROL, &state.to_le_bytes());
        assert_eq!(self.al_status(), state, "AL state {state:#x}");
    }

    fn new() -> Self {
        let mut rig = Self {
            bus: ShadowBus::new(Palm::new(), 1178, Duration::ZERO),
            now: Duration::from_millis(1),
        };
        let address = u32::from(reg::STATION_ADDRESS) << 16;
        assert_eq!(rig.one(APWR, address, &STATION.to_le_bytes()).1, 1);
        rig.request(0x02);
        for (n, sm) in palm_sync_managers(Protocol::P0220).iter().enumerate() {
            rig.fpwr(reg::SM0 + 8 * n as u16 + 6, &[0]);
            let mut b = sm.start.to_le_bytes().to_vec();
            b.extend_from_slice(&sm.len.to_le_bytes());
            b.extend_from_slice(&[sm.control, 0, 1, 0]);
            rig.fpwr(reg::SM0 + 8 * n as u16, &b);
        }
        let a = Protocol::P0220.area();
        for (n, (logical, len, physical, kind)) in [
            (LOGICAL, OUT_LEN, a.command, 2u8),
            (LOGICAL + OUT_LEN as u32, IN_LEN, a.status, 1u8),
        ]
        .into_iter()
        .enumerate()
        {
            let mut b = logical.to_le_bytes().to_vec();
            b.extend_from_slice(&(len as u16).to_le_bytes());
            b.extend_from_slice(&[0, 7]);
            b.extend_from_slice(&physical.to_le_bytes());
            b.extend_from_slice(&[0, kind, 1, 0, 0, 0]);
            rig.fpwr(reg::FMMU0 + 16 * n as u16, &b);
        }
        rig.request(0x04);
        rig.request(0x08);
        // Past the palm's boot.
        rig.now = Duration::from_millis(Palm::BOOT_MS + 50);
        rig
    }

    /// One LRW at the current time with `command`: the status part read and the working counter.
    fn lrw(&mut self, command: &Command) -> (Option<Status>, u16) {
        let mut data = vec![0u8; OUT_LEN + IN_LEN];
        data[..Command::SIZE].copy_from_slice(&command.pack());
        let (back, wkc) = self.one(LRW, LOGICAL, &data);
        let status = Status::unpack(&back[OUT_LEN..OUT_LEN + Status::SIZE])
            .ok()
            .filter(|s| s.edc_command != 0);
        (status, wkc)
    }

    fn after_us(&mut self, us: u64) {
        self.now += Duration::from_micros(us);
    }
}

fn sensor_data(which: i16) -> Command {
    Command {
        edc_command: 1,
        from_motor_data_type: FromMotor::Flags as u32,
        which_motors: which,
        to_motor_data_type: ToMotor::TorqueDemand as u32,
        ..Command::default()
    }
}

/// A MainDevice cycle that comes early (a late cycle caught up) writes its command while the
/// palm is still on its CAN buses with the previous one: the firmware has already read that one
/// out of SM0, so the new command goes in (LRW write: +2) and is answered after the round.
#[test]
fn a_command_written_during_the_can_round_is_taken_not_refused() {
    let mut rig = Rig::new();
    let (_, wkc) = rig.lrw(&sensor_data(0));
    assert_eq!(wkc & 2, 2, "the first command is written");
    // 300 us later, well inside the palm's CAN round (> 600 us).
    rig.after_us(300);
    let (_, wkc) = rig.lrw(&sensor_data(1));
    assert_eq!(
        wkc & 2,
        2,
        "a command written during the CAN round is taken (working counter {wkc})"
    );
    // Both rounds run; the MainDevice reads the first answer, then the second.
    rig.after_us(1700);
    let (first, _) = rig.lrw(&sensor_data(0));
    assert_eq!(first.unwrap().which_motors, 0);
    assert_eq!(rig.bus.palm.app().stats.cycles, 2, "both commands ran");
    assert_eq!(
        rig.bus.palm().motors[1].replies,
        1,
        "the odd motors answered"
    );
}

/// `idle_time_us` counts from the status write (the end of the CAN round) to the next command
/// (`calculate_idle_time`), not from command to command.
#[test]
fn idle_time_is_from_the_status_write_to_the_next_command() {
    let mut rig = Rig::new();
    rig.lrw(&sensor_data(0));
    rig.after_us(1000);
    rig.lrw(&sensor_data(1));
    rig.after_us(1000);
    let (status, wkc) = rig.lrw(&sensor_data(0));
    assert_eq!(wkc, 3);
    let status = status.unwrap();
    assert_eq!(status.which_motors, 1, "the second command's answer");
    let round = PROCESS_TIME.as_micros() as u16;
    assert_eq!(
        status.idle_time_us,
        1000 - round,
        "1 ms period less the {round} us round"
    );
}

/// While the palm boots its status is what `Platform_Init_Callback` writes: EDC_command 0xCC,
/// then every 16-bit word from the second on 0xDEAD, the upper half of EDC_command included
/// (the loop starts at word 1 of the struct), so EDC_command reads 0xDEAD00CC.
#[test]
fn the_boot_status_is_the_firmwares_init_words() {
    let mut palm = Palm::new();
    let (status, _) = palm.cycle(&sensor_data(0), None, 0);
    let s = status.unwrap();
    assert_eq!(s.edc_command, 0xDEAD_00CC, "{:#x}", s.edc_command);
    assert!(s.sensors.iter().all(|w| *w == 0xDEAD));
    assert_eq!(s.motor_data_type, 0xDEAD_DEAD);
    assert_eq!(s.which_motors as u16, 0xDEAD);
    assert_eq!(s.which_motor_data_arrived, 0xDEAD_DEAD);
    assert_eq!(s.which_motor_data_had_errors, 0xDEAD_DEAD);
    assert!(s
        .packets
        .iter()
        .all(|p| p.torque as u16 == 0xDEAD && p.misc == 0xDEAD));
    assert_eq!(s.tactile_data_type, 0xDEAD_DEAD);
    assert_eq!(s.tactile_data_valid, 0xDEAD);
    assert!(s.tactile.iter().flatten().all(|w| *w == 0xDEAD));
    assert_eq!(s.idle_time_us, 0xDEAD);
}

/// The firmware reads the bridge command (SM1) only in CAN direct mode, when its AL event says
/// it was written (`ROS_Wants_me_to_send_CAN`); in SENSOR_DATA mode SM1 stays full. So the
/// first CAN-direct cycle takes the bridge message written long before (it goes on the bus),
/// the one written with it is refused by the full SM1, and the next cycle's goes through: why
/// the shipped flasher sends a dummy message (id 0) before MAGIC.
#[test]
fn the_bridge_command_is_read_in_can_direct_mode_only() {
    use teleop_shadow_protocol::can::BootMessage;
    use teleop_shadow_protocol::data::{EdcCommand, EdcNumbering};
    use teleop_sim_shadow::bootloader::Mode;

    let magic = |bus: u8, id: u8| {
        let m = BootMessage::magic(id);
        CanBridge {
            can_bus: bus,
            length: m.len,
            id: m.id,
            data: m.data,
        }
    };
    let lrw = |rig: &mut Rig, command: &Command, bridge: &CanBridge| {
        let mut data = vec![0u8; OUT_LEN + IN_LEN];
        data[..Command::SIZE].copy_from_slice(&command.pack());
        data[Command::SIZE..OUT_LEN].copy_from_slice(&bridge.pack());
        rig.one(LRW, LOGICAL, &data).1
    };
    let direct = Command {
        edc_command: EdcCommand::CanDirectMode
            .value(EdcNumbering::Shipped)
            .unwrap(),
        ..Command::default()
    };
    let mut rig = Rig::new();
    // Normal mode, with a bridge message for motor 3 (bus 1, id 3): not sent.
    lrw(&mut rig, &sensor_data(0), &magic(1, 3));
    rig.after_us(1000);
    lrw(&mut rig, &sensor_data(1), &magic(1, 3));
    rig.after_us(1000);
    assert_eq!(rig.bus.palm().boards[3].mode(), Mode::Application);
    // The first CAN-direct cycle, with MAGIC for motor 13 (bus 2, id 3).
    lrw(&mut rig, &direct, &magic(2, 3));
    rig.after_us(1000);
    lrw(&mut rig, &direct, &CanBridge::default());
    rig.after_us(1000);
    let palm = rig.bus.palm();
    assert_eq!(
        (palm.boards[3].mode(), palm.boards[13].mode()),
        (Mode::Bootloader, Mode::Application),
        "the stale message went out, the new one was refused"
    );
    // Now SM1 is free: the next message goes through.
    lrw(&mut rig, &direct, &magic(2, 3));
    rig.after_us(1000);
    lrw(&mut rig, &direct, &CanBridge::default());
    rig.after_us(1000);
    assert_eq!(rig.bus.palm().boards[13].mode(), Mode::Bootloader);
}
