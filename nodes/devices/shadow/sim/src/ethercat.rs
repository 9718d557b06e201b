//! The hand on an EtherCAT bus, as a real Hand E is: two SubDevices of `teleop-ecat-sim` in
//! ring order, the bridge (product 0: no process data, no mailbox) and the palm (product 6,
//! protocol 0220). Neither SII announces sync managers, FMMUs or a mailbox (the real ones are
//! not public): the MainDevice must program the palm's four one-buffer sync managers as the
//! shipped driver does, or the palm refuses SAFE-OP (0x0017).
//!
//! The palm's firmware ([`PalmFirmware`]) polls for the command sync manager being written
//! (E11's AL event 0x220 bit 8) and reads the command out of its sync manager right away,
//! before its CAN round (E11 `this_node.c`, `Service_EtherCAT_Packet`:
//! `Read_Commands_From_ET1200` follows the SM0 event), so SM0 is free again for the next
//! command during the round. The bridge command (SM1) is read only in CAN direct mode, before
//! the wait, when SM1 was written: in other modes a bridge message stays in SM1 (and a later
//! one is refused) until the first CAN-direct cycle takes it. It writes the status [`PROCESS_TIME`] later (the bridge status
//! [`CAN_DIRECT_ROUND`] later), so a status read in a cycle answers the previous cycle's
//! command. A command written during a round waits in SM0 until the round ends (the firmware
//! is busy on its CAN buses); a third one meanwhile is refused by the full SM0. A status the
//! MainDevice has not read yet is not overwritten (one-buffer): counted in
//! [`PalmStats::unread_status`].

use std::time::Duration;

use teleop_ecat_sim::{
    AlState, Application, EscConfig, Identity, Pdi, SmSetting, SubDevice, SyncManagers,
};
use teleop_shadow_protocol::data::{EdcCommand, EdcNumbering};
use teleop_shadow_protocol::layout::{CanBridge, Command, Protocol, PRODUCT_BRIDGE, PRODUCT_SR06};

use crate::palm::{Palm, CAN_DIRECT_ROUND, SENSOR_DATA_ROUND};

/// Vendor ID both SubDevices carry: Shadow's entry in the ETG vendor list (ethercrab's
/// `vendors.rs`); no Shadow source names it (docs/devices/shadow.md, "Open").
pub const VENDOR_ID: u32 = 0x0000_0530;
/// From the command being seen to the status being written in SENSOR_DATA mode: the
/// firmware's CAN round ([`SENSOR_DATA_ROUND`]).
pub const PROCESS_TIME: Duration = SENSOR_DATA_ROUND;
/// Sync managers in the order the palm expects them: command, bridge command, status, bridge
/// status.
pub const SM_COMMAND: usize = 0;
/// The bridge command's sync manager.
pub const SM_BRIDGE_COMMAND: usize = 1;
/// The status's sync manager.
pub const SM_STATUS: usize = 2;
/// The bridge status's sync manager.
pub const SM_BRIDGE_STATUS: usize = 3;

/// The palm's four sync managers for `protocol` (docs/devices/shadow.md, "Sync managers and
/// FMMUs"): one buffer each, AL event enabled on the two the MainDevice writes.
pub fn palm_sync_managers(protocol: Protocol) -> Vec<SmSetting> {
    let a = protocol.area();
    let bridge = CanBridge::SIZE as u16;
    vec![
        SmSetting {
            start: a.command,
            len: a.command_len,
            control: 0x26,
        },
        SmSetting {
            start: a.bridge_command,
            len: bridge,
            control: 0x26,
        },
        SmSetting {
            start: a.status,
            len: a.status_len,
            control: 0x02,
        },
        SmSetting {
            start: a.bridge_status,
            len: bridge,
            control: 0x02,
        },
    ]
}

/// The bridge SubDevice: nothing behind its ESC.
#[derive(Debug, Default)]
pub struct Bridge;

impl Application for Bridge {
    teleop_ecat_sim::no_objects!();
}

/// What the palm's firmware counted.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct PalmStats {
    /// Commands taken (cycles run).
    pub cycles: u64,
    /// Statuses not written because the MainDevice had not read the previous one.
    pub unread_status: u64,
    /// Bridge messages taken that were not idle.
    pub bridged: u64,
}

/// A command the firmware has read and is serving (its CAN round).
#[derive(Debug, Clone, Copy)]
struct Round {
    command: Command,
    bridge: Option<CanBridge>,
    /// When the firmware saw the command (its frame time 0).
    start: Duration,
    /// When it writes what it answers.
    end: Duration,
}

/// The palm's firmware behind its ESC.
#[derive(Debug)]
pub struct PalmFirmware {
    /// The palm and its motor boards and hand.
    pub palm: Palm,
    /// Counters.
    pub stats: PalmStats,
    round: Option<Round>,
    /// When the firmware is back in its loop, polling for the next command.
    free_at: Duration,
}

impl PalmFirmware {
    /// Firmware around `palm`.
    pub fn new(palm: Palm) -> Self {
        Self {
            palm,
            stats: PalmStats::default(),
            round: None,
            free_at: Duration::ZERO,
        }
    }

    /// The end of a round: the palm's cycle for its command, and the status and bridge status
    /// it writes.
    fn finish(&mut self, round: Round, pdi: &mut Pdi<'_>) {
        let start_us = round.start.as_micros() as u64;
        let direct = EdcCommand::from_value(round.command.edc_command, self.palm.numbering)
            == Some(EdcCommand::CanDirectMode);
        let (status, reply) = self
            .palm
            .cycle_us(&round.command, round.bridge.as_ref(), start_us);
        // In CAN direct mode a reply that came later (an ERASE's echo) goes out with the next
        // cycle.
        let reply = match reply {
            Some(r) => Some(r),
            None if direct => {
                let late = self.palm.pending_reply(start_us / 1000);
                if late.is_some() {
                    self.palm
                        .bridge_status_written(round.end.as_micros() as u64);
                }
                late
            }
            None => None,
        };
        if let Some(status) = status {
            if !pdi.put(SM_STATUS, &status.pack()) {
                self.stats.unread_status += 1;
            }
        }
        if let Some(reply) = reply {
            pdi.put(SM_BRIDGE_STATUS, &reply.pack());
        }
    }
}

impl Application for PalmFirmware {
    teleop_ecat_sim::no_objects!();

    fn pdi(&mut self, now: Duration, _: AlState, pdi: &mut Pdi<'_>) {
        loop {
            if let Some(round) = self.round {
                if now < round.end {
                    return; // still on the CAN buses
                }
                self.round = None;
                self.finish(round, pdi);
            }
            let Some(written) = pdi.written(SM_COMMAND) else {
                return;
            };
            // The firmware polls its AL event register in its main loop: it sees a command as
            // soon as the command is complete, or when it is back from the previous round.
            let start = written.max(self.free_at);
            let Some(command) = pdi.take(SM_COMMAND).and_then(|b| Command::unpack(b).ok()) else {
                return;
            };
            let command_kind = EdcCommand::from_value(command.edc_command, self.palm.numbering);
            // E11: the bridge command is read only in CAN direct mode, when the AL event read
            // with the command says SM1 was written (`ROS_Wants_me_to_send_CAN`). Otherwise SM1
            // stays full: a message written then waits there, and one written while it waits
            // is refused by the ESC.
            let bridge = (command_kind == Some(EdcCommand::CanDirectMode))
                .then(|| {
                    pdi.written(SM_BRIDGE_COMMAND)
                        .and_then(|_| pdi.take(SM_BRIDGE_COMMAND))
                        .and_then(|b| CanBridge::unpack(b).ok())
                })
                .flatten();
            self.stats.cycles += 1;
            if bridge.is_some_and(|b| !b.is_idle()) {
                self.stats.bridged += 1;
            }
            let took = match command_kind {
                Some(EdcCommand::CanDirectMode) => CAN_DIRECT_ROUND,
                Some(EdcCommand::SensorData | EdcCommand::SensorChannelNumbers) => PROCESS_TIME,
                // Any other command: the error LED, nothing else.
                _ => Duration::ZERO,
            };
            let end = start + took;
            self.free_at = end;
            self.round = Some(Round {
                command,
                bridge,
                start,
                end,
            });
        }
    }
}

/// The two SubDevices in ring order, answering frames as the hand's bus does.
#[derive(Debug)]
pub struct ShadowBus {
    /// The first SubDevice (product 0).
    pub bridge: SubDevice<Bridge>,
    /// The second (product 6).
    pub palm: SubDevice<PalmFirmware>,
    between: Vec<u8>,
}

impl ShadowBus {
    /// A hand whose palm has `serial` (it names the hand's namespace on a real system) and
    /// reads AL control once per `firmware_loop`.
    pub fn new(palm: Palm, serial: u32, firmware_loop: Duration) -> Self {
        let bridge = EscConfig {
            identity: Identity {
                vendor_id: VENDOR_ID,
                product_code: PRODUCT_BRIDGE,
                revision: 0,
                serial,
            },
            name: "Shadow EtherCAT bridge (emulated)".into(),
            mac: [0x02, 0x00, 0x00, 0x00, 0x5a, 0x01],
            port1_linked: true,
            sync_managers: SyncManagers::Programmed(Vec::new()),
            firmware_loop,
            ..EscConfig::default()
        };
        let palm_config = EscConfig {
            identity: Identity {
                vendor_id: VENDOR_ID,
                product_code: PRODUCT_SR06,
                revision: 0,
                serial,
            },
            name: "Shadow SR06 palm (emulated)".into(),
            mac: [0x02, 0x00, 0x00, 0x00, 0x5a, 0x02],
            sync_managers: SyncManagers::Programmed(palm_sync_managers(Protocol::P0220)),
            firmware_loop,
            ..EscConfig::default()
        };
        Self {
            bridge: SubDevice::new(bridge, Bridge),
            palm: SubDevice::new(palm_config, PalmFirmware::new(palm)),
            between: vec![0; teleop_ecat_link::MAX_FRAME],
        }
    }

    /// The palm.
    pub fn palm(&self) -> &Palm {
        &self.palm.app().palm
    }

    /// The palm, to change (faults, objects).
    pub fn palm_mut(&mut self) -> &mut Palm {
        &mut self.palm.app_mut().palm
    }

    /// The EDC numbering the palm's firmware uses.
    pub fn numbering(&self) -> EdcNumbering {
        self.palm().numbering
    }
}

impl teleop_ecat_link::Responder for ShadowBus {
    fn respond(&mut self, frame: &[u8], out: &mut [u8], now: Duration) -> Option<usize> {
        let n = self
            .bridge
            .process_frame_into(frame, &mut self.between, now)?;
        self.palm.process_frame_into(&self.between[..n], out, now)
    }

    fn idle(&mut self, now: Duration) {
        self.bridge.tick(now);
        self.palm.tick(now);
    }
}
